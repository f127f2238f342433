//! The train / test split of datasets that do not store one: every eighth frame (index
//! `i % 8 == 0`, counting from 0 in file order) is held out for testing, the convention of
//! the NeRF papers' LLFF scenes, so that results compare with theirs.

/// Every how many frames one is held out for testing.
pub const HOLDOUT_EVERY: usize = 8;

/// Splits `items` into (train, test): test takes indices `i % 8 == 0`, train the rest, each
/// in the original order.
pub fn holdout<T>(items: Vec<T>) -> (Vec<T>, Vec<T>) {
    let mut train = Vec::with_capacity(items.len());
    let mut test = Vec::with_capacity(items.len() / HOLDOUT_EVERY + 1);
    for (i, item) in items.into_iter().enumerate() {
        if i % HOLDOUT_EVERY == 0 {
            test.push(item);
        } else {
            train.push(item);
        }
    }
    (train, test)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_eighth_from_zero_is_test() {
        let (train, test) = holdout((0..17).collect());
        assert_eq!(test, vec![0, 8, 16]);
        assert_eq!(train.len(), 14);
        assert_eq!(train[..3], [1, 2, 3]);
        assert_eq!(train[7], 9);
    }
}
