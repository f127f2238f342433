//! Whether photographs without alpha show an object over a plain backdrop: a render over white
//! written without alpha, a studio sweep, a turntable against a sheet. There the border of
//! every picture is one colour, and the object is fitted in its box as a picture with alpha
//! would be. A capture's border shows its surroundings (a room, a field, a sky with a horizon),
//! which vary from picture to picture and along each border, so few of its border pixels share
//! one colour.

use crate::dataset::View;

/// The width of the border looked at, as a share of the picture's short side (at least one
/// pixel): wide enough that one stray row of an edge does not decide, narrow enough that the
/// object itself (which a capture may frame tightly) rarely reaches into it.
const BORDER_SHARE: f64 = 0.03;

/// The largest channel difference from the common colour at which a border pixel still counts
/// as that colour: above JPEG's and a sensor's noise on a flat sheet, below the steps of a
/// room's shading.
const SAME_COLOUR: f64 = 0.08;

/// The share of all border pixels that must be the common colour for the backdrop to be plain:
/// an object that touches the border here and there leaves a plain backdrop plain.
const PLAIN_SHARE: f64 = 0.95;

/// The colour of the plain backdrop behind `views`, if their borders show one: the per-channel
/// median of every border pixel of every view, when at least [`PLAIN_SHARE`] of them lie within
/// [`SAME_COLOUR`] of it in every channel. `None` for no views, or borders that vary.
pub(crate) fn plain_backdrop(views: &[View]) -> Option<[f64; 3]> {
    let mut border: Vec<[f64; 3]> = Vec::new();
    for view in views {
        let (h, w, _) = view.image.dim();
        let width = ((h.min(w) as f64 * BORDER_SHARE).ceil() as usize).clamp(1, h.min(w).div_ceil(2));
        for y in 0..h {
            for x in 0..w {
                let inside = (width..h - width).contains(&y) && (width..w - width).contains(&x);
                if !inside {
                    border.push([0, 1, 2].map(|c| view.image[[y, x, c]]));
                }
            }
        }
    }
    if border.is_empty() {
        return None;
    }
    let colour = [0, 1, 2].map(|c| median(border.iter().map(|p| p[c]).collect()));
    let same = border
        .iter()
        .filter(|p| (0..3).all(|c| (p[c] - colour[c]).abs() <= SAME_COLOUR))
        .count();
    (same as f64 >= PLAIN_SHARE * border.len() as f64).then_some(colour)
}

/// The median of `values` (the upper one of an even count); NaN sorts last.
fn median(mut values: Vec<f64>) -> f64 {
    let middle = values.len() / 2;
    *values.select_nth_unstable_by(middle, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::view;
    use ndarray::Array3;

    /// View `i` of 8 x 8 pixels: `backdrop` everywhere but a centre square of `object`.
    fn picture(i: usize, backdrop: [f64; 3], object: [f64; 3]) -> View {
        let mut v = view(i, [3.0, 0.0, 0.5]);
        v.image = Array3::from_shape_fn((8, 8, 3), |(y, x, c)| {
            if (2..6).contains(&y) && (2..6).contains(&x) {
                object[c]
            } else {
                backdrop[c]
            }
        });
        v
    }

    #[test]
    fn an_object_over_one_colour_has_a_plain_backdrop_of_that_colour() {
        let views: Vec<View> = (0..3).map(|i| picture(i, [0.9, 0.8, 0.7], [0.1, 0.5, 0.2])).collect();
        assert_eq!(plain_backdrop(&views), Some([0.9, 0.8, 0.7]));
    }

    #[test]
    fn noise_below_the_tolerance_keeps_the_backdrop_plain() {
        let mut views: Vec<View> = (0..3).map(|i| picture(i, [1.0; 3], [0.0; 3])).collect();
        // Every other border pixel dimmed by 0.05: still within SAME_COLOUR of the median.
        for (i, v) in views.iter_mut().enumerate() {
            for x in 0..8 {
                if (x + i) % 2 == 0 {
                    v.image[[0, x, 1]] = 0.95;
                }
            }
        }
        assert!(plain_backdrop(&views).is_some());
    }

    #[test]
    fn a_capture_whose_borders_vary_has_no_plain_backdrop() {
        // The ramp pictures of the unit tests: every pixel a different colour, as a room's.
        let views: Vec<View> = (0..3).map(|i| view(i, [3.0, 0.0, 0.5])).collect();
        assert_eq!(plain_backdrop(&views), None);
        // One colour per picture, but a different one in each: the borders do not agree.
        let views: Vec<View> = (0..4)
            .map(|i| picture(i, [0.2 * i as f64, 0.5, 0.5], [0.0; 3]))
            .collect();
        assert_eq!(plain_backdrop(&views), None);
    }

    #[test]
    fn an_object_across_a_seventh_of_the_border_leaves_it_not_plain() {
        // 28 border pixels of 8 x 8; the object colours 4 of them in every view (14 %).
        let mut views: Vec<View> = (0..3).map(|i| picture(i, [1.0; 3], [0.0; 3])).collect();
        for v in &mut views {
            for x in 2..6 {
                v.image[[7, x, 0]] = 0.0;
            }
        }
        assert_eq!(plain_backdrop(&views), None);
        assert_eq!(plain_backdrop(&[]), None);
    }
}
