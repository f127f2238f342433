//! How far a COLMAP step has got, read from the lines it prints: feature extraction's
//! `Processed file [12/80]`, exhaustive matching's `Matching block [2/3, 1/3]`, sequential
//! matching's `Matching image [12/80]`, the mapper's `Registering image #7 (5)` (the number in
//! brackets: the photograph's place in the model, counting those registered before it; the
//! mapper tries some several times). Lines it does not recognise say nothing.

/// A count read from a line of COLMAP's output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// `done` of `total` (photographs, or blocks of pairs).
    Of {
        /// Done so far.
        done: usize,
        /// In all.
        total: usize,
    },
    /// The mapper is registering its `n`-th photograph.
    Registering(usize),
}

/// `a/b` as two numbers.
fn fraction(text: &str) -> Option<(usize, usize)> {
    let (a, b) = text.trim().split_once('/')?;
    Some((a.trim().parse().ok()?, b.trim().parse().ok()?))
}

/// What `line` says of the step's progress, if anything.
pub fn parse(line: &str) -> Option<Progress> {
    let bracket = |after: &str| -> Option<&str> {
        let rest = &line[line.find(after)? + after.len()..];
        let rest = rest.trim_start().strip_prefix('[')?;
        Some(&rest[..rest.find(']')?])
    };
    if let Some(inside) = bracket("Processed file").or_else(|| bracket("Matching image")) {
        let (done, total) = fraction(inside)?;
        return Some(Progress::Of { done, total });
    }
    if let Some(inside) = bracket("Matching block") {
        // Blocks of rows by blocks of columns: [row/rows, column/columns], row-major.
        let (row, column) = inside.split_once(',')?;
        let ((row, rows), (column, columns)) = (fraction(row)?, fraction(column)?);
        let done = row.checked_sub(1)?.checked_mul(columns)?.checked_add(column)?;
        return Some(Progress::Of {
            done,
            total: rows.checked_mul(columns)?,
        });
    }
    let rest = &line[line.find("Registering image #")?..];
    let count = &rest[rest.find('(')? + 1..rest.find(')')?];
    Some(Progress::Registering(count.trim().parse().ok()?))
}

/// `progress` in words; `blocks` when the count is of blocks of pairs (exhaustive matching).
pub fn describe(progress: Progress, blocks: bool) -> String {
    match progress {
        Progress::Of { done, total } if blocks => format!("block {done} of {total}"),
        Progress::Of { done, total } => format!("{done} of {total} photographs"),
        Progress::Registering(n) => format!("registering photograph {n}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_read_from_each_steps_lines() {
        assert_eq!(
            parse("Processed file [12/80]"),
            Some(Progress::Of { done: 12, total: 80 })
        );
        // glog's prefix, as COLMAP 3.9 and later print it.
        assert_eq!(
            parse("I0512 10:01:02.123 feature_extraction.cc:254] Processed file [3/9]"),
            Some(Progress::Of { done: 3, total: 9 })
        );
        assert_eq!(
            parse("Matching image [7/80] in 0.250s"),
            Some(Progress::Of { done: 7, total: 80 })
        );
        // Block (2, 3) of 3 x 4 blocks, row-major: 1 * 4 + 3 = 7 of 12.
        assert_eq!(
            parse("Matching block [2/3, 3/4] in 1.2s"),
            Some(Progress::Of { done: 7, total: 12 })
        );
        assert_eq!(parse("Registering image #14 (9)"), Some(Progress::Registering(9)));
    }

    #[test]
    fn other_lines_say_nothing() {
        for line in [
            "",
            "  Name:            view_00.png",
            "Processed file [12/]",
            "Matching block [0/3, 1/3]",
            "Registering image #14",
            "Processed file [99999999999999999999999/2]",
            "==============================================================================",
        ] {
            assert_eq!(parse(line), None, "{line:?}");
        }
    }
}
