//! The tape's positional order of the composite's inputs (sigma, delta, color, then the
//! background unless [`Background::None`], then t with depth) and outputs (colour, opacity,
//! then depth, weights and transmittance as configured), and its translation to and from the
//! named structs that everything else uses: the only place that knows the order.

use fogray_tape::Float;
use ndarray::{ArrayD, ArrayViewD};

use super::arrays::{CompositeArrays, CompositeOutputs};
use super::config::{Background, Composite};
use super::gradients::{CompositeGradients, CompositeUpstream, CompositeWanted};
use crate::error::{Op, OpsError};

/// One value per input of the op, by name (`background` and `t` present exactly when the op
/// has them).
pub(super) struct ByInput<T> {
    pub sigma: T,
    pub delta: T,
    pub color: T,
    pub background: Option<T>,
    pub t: Option<T>,
}

/// One value per output of the op, by name (the optional ones present exactly when
/// configured).
pub(super) struct ByOutput<T> {
    pub color: T,
    pub opacity: T,
    pub depth: Option<T>,
    pub weights: Option<T>,
    pub transmittance: Option<T>,
}

fn count_error(what: &'static str, expected: usize, got: usize) -> OpsError {
    OpsError::Shape {
        op: Op::Composite,
        what,
        expected: format!("{expected} {what}"),
        got: format!("{got}"),
    }
}

/// The next item if the slot is `on`; an error if it is on and the items have run out.
fn next_if<T>(
    items: &mut impl Iterator<Item = T>,
    on: bool,
    out_of_items: impl Fn() -> OpsError,
) -> Result<Option<T>, OpsError> {
    if on {
        items.next().map(Some).ok_or_else(out_of_items)
    } else {
        Ok(None)
    }
}

impl<T> ByInput<T> {
    /// Names `items`, given in the tape's order for `op`; an error if there are not exactly as
    /// many as the op has inputs.
    pub(super) fn from_tape(op: &Composite, items: Vec<T>) -> Result<Self, OpsError> {
        let has_background = op.background != Background::None;
        let expected = [true, true, true, has_background, op.depth]
            .iter()
            .filter(|&&on| on)
            .count();
        let got = items.len();
        let wrong = || count_error("inputs", expected, got);
        let mut items = items.into_iter();
        let (Some(sigma), Some(delta), Some(color)) = (items.next(), items.next(), items.next()) else {
            return Err(wrong());
        };
        let background = next_if(&mut items, has_background, wrong)?;
        let t = next_if(&mut items, op.depth, wrong)?;
        if items.next().is_some() {
            return Err(wrong());
        }
        Ok(ByInput {
            sigma,
            delta,
            color,
            background,
            t,
        })
    }

    /// The values in the tape's order.
    pub(super) fn into_tape(self) -> Vec<T> {
        [
            Some(self.sigma),
            Some(self.delta),
            Some(self.color),
            self.background,
            self.t,
        ]
        .into_iter()
        .flatten()
        .collect()
    }
}

impl<T> ByOutput<T> {
    /// Names `items`, given in the tape's order for `op`; an error if there are not exactly as
    /// many as the op has outputs.
    pub(super) fn from_tape(op: &Composite, items: Vec<T>) -> Result<Self, OpsError> {
        let optional = [op.depth, op.weights, op.transmittance];
        let expected = 2 + optional.iter().filter(|&&on| on).count();
        let got = items.len();
        let wrong = || count_error("outputs", expected, got);
        let mut items = items.into_iter();
        let (Some(color), Some(opacity)) = (items.next(), items.next()) else {
            return Err(wrong());
        };
        let depth = next_if(&mut items, op.depth, wrong)?;
        let weights = next_if(&mut items, op.weights, wrong)?;
        let transmittance = next_if(&mut items, op.transmittance, wrong)?;
        if items.next().is_some() {
            return Err(wrong());
        }
        Ok(ByOutput {
            color,
            opacity,
            depth,
            weights,
            transmittance,
        })
    }

    /// The values in the tape's order.
    pub(super) fn into_tape(self) -> Vec<T> {
        [
            Some(self.color),
            Some(self.opacity),
            self.depth,
            self.weights,
            self.transmittance,
        ]
        .into_iter()
        .flatten()
        .collect()
    }
}

/// The tape's input arrays, by name.
pub(super) fn arrays<'a, F: Float>(
    op: &Composite,
    inputs: &[ArrayViewD<'a, F>],
) -> Result<CompositeArrays<'a, F>, OpsError> {
    let x = ByInput::from_tape(op, inputs.to_vec())?;
    Ok(CompositeArrays {
        sigma: x.sigma,
        delta: x.delta,
        color: x.color,
        background: x.background,
        t: x.t,
    })
}

/// The tape's "needs this input's gradient" flags, by name.
pub(super) fn wanted(op: &Composite, needs: Vec<bool>) -> Result<CompositeWanted, OpsError> {
    let n = ByInput::from_tape(op, needs)?;
    Ok(CompositeWanted {
        sigma: n.sigma,
        delta: n.delta,
        color: n.color,
        background: n.background.unwrap_or(false),
        t: n.t.unwrap_or(false),
    })
}

/// The tape's upstream gradients (one per output), by name.
pub(super) fn upstream<'a, F: Float>(
    op: &Composite,
    grads: &[Option<ArrayViewD<'a, F>>],
) -> Result<CompositeUpstream<'a, F>, OpsError> {
    let g = ByOutput::from_tape(op, grads.to_vec())?;
    Ok(CompositeUpstream {
        color: g.color,
        opacity: g.opacity,
        depth: g.depth.flatten(),
        weights: g.weights.flatten(),
        transmittance: g.transmittance.flatten(),
    })
}

/// The outputs in the tape's order (`outputs` as [`Composite::evaluate`] returns them: the
/// optional ones present exactly when configured).
pub(super) fn outputs_in_order<F>(outputs: CompositeOutputs<F>) -> Vec<ArrayD<F>> {
    ByOutput {
        color: outputs.color,
        opacity: outputs.opacity,
        depth: outputs.depth,
        weights: outputs.weights,
        transmittance: outputs.transmittance,
    }
    .into_tape()
}

/// The input gradients in the tape's order, one entry per input of `op`.
pub(super) fn gradients_in_order<F>(op: &Composite, g: CompositeGradients<F>) -> Vec<Option<ArrayD<F>>> {
    ByInput {
        sigma: g.sigma,
        delta: g.delta,
        color: g.color,
        background: (op.background != Background::None).then_some(g.background),
        t: op.depth.then_some(g.t),
    }
    .into_tape()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn op(background: Background, depth: bool) -> Composite {
        let op = Composite::new(&[0, 2]).unwrap().background(background);
        if depth {
            op.with_depth()
        } else {
            op
        }
    }

    #[test]
    fn inputs_are_named_in_the_tapes_order_and_back() {
        let cases = [
            (Background::None, false, vec!["sigma", "delta", "color"]),
            (Background::Shared, false, vec!["sigma", "delta", "color", "background"]),
            (Background::None, true, vec!["sigma", "delta", "color", "t"]),
            (
                Background::PerRay,
                true,
                vec!["sigma", "delta", "color", "background", "t"],
            ),
        ];
        for (background, depth, order) in cases {
            let op = op(background, depth);
            let named = ByInput::from_tape(&op, order.clone()).unwrap();
            assert_eq!(
                (named.sigma, named.delta, named.color, named.background, named.t),
                (
                    "sigma",
                    "delta",
                    "color",
                    (background != Background::None).then_some("background"),
                    depth.then_some("t")
                )
            );
            assert_eq!(named.into_tape(), order);
            // One too few or one too many is refused.
            let mut short = order.clone();
            short.pop();
            let mut long = order.clone();
            long.push("extra");
            for wrong in [short, long] {
                let len = wrong.len();
                match ByInput::from_tape(&op, wrong) {
                    Err(OpsError::Shape {
                        op: Op::Composite,
                        what: "inputs",
                        got,
                        ..
                    }) => assert_eq!(got, len.to_string()),
                    other => panic!("{:?}", other.map(|_| ())),
                }
            }
        }
    }

    #[test]
    fn outputs_are_named_in_the_tapes_order_and_back() {
        let op = Composite::new(&[0, 2]).unwrap().with_depth().with_transmittance();
        let order = vec!["color", "opacity", "depth", "transmittance"];
        let named = ByOutput::from_tape(&op, order.clone()).unwrap();
        assert_eq!(
            (
                named.color,
                named.opacity,
                named.depth,
                named.weights,
                named.transmittance
            ),
            ("color", "opacity", Some("depth"), None, Some("transmittance"))
        );
        assert_eq!(named.into_tape(), order);
        assert!(ByOutput::from_tape(&op, vec!["color", "opacity", "depth"]).is_err());
        // The wanted flags of the tape map to the named inputs (here: the t gradient only).
        let op = op.background(Background::PerRay);
        let w = wanted(&op, vec![false, false, false, false, true]).unwrap();
        assert_eq!(
            w,
            CompositeWanted {
                t: true,
                ..Default::default()
            }
        );
    }
}
