//! View-dependent colour from spherical harmonics, fused: for `n` samples, coefficients
//! `[n, 3 B]` and unit view directions `[n, 3]` to a colour `[n, 3]`,
//!
//! ```text
//! color[i, c] = sigmoid( sum_{b < B} coeffs[i, c B + b] Y_b(d_i) ),   B = (degree + 1)^2
//! ```
//!
//! for degree 0 to 3 (1, 4, 9 or 16 basis functions a channel), as one op ([`ShColor`]) with a
//! hand-written backward, with a tape ([`ShColor::apply`]) or without ([`ShColor::evaluate`],
//! [`ShColor::vjp`]), and its taped twin ([`twin::sh_color`]). The coefficients are laid out
//! channel-major: channel `c`'s `B` coefficients are columns `c B .. (c + 1) B` of a row.
//! The directions are constants of the op: they get no gradient.
//!
//! # The basis
//!
//! The real spherical harmonics, orthonormal on the unit sphere (`integral Y_a Y_b = delta_ab`),
//! in the order, normalisation and signs that Plenoxels (svox2) and 3D Gaussian splatting use,
//! so that their coefficients can be read as they are. With `d = (x, y, z)` ([`basis`] holds the
//! constants):
//!
//! ```text
//! degree 0   Y_0  = C0                                  C0 = 0.28209479177387814
//! degree 1   Y_1  = -C1 y   Y_2 = C1 z   Y_3 = -C1 x    C1 = 0.4886025119029199
//! degree 2   Y_4  = C2[0] xy                            C2 = [ 1.0925484305920792,
//!            Y_5  = C2[1] yz                                  -1.0925484305920792,
//!            Y_6  = C2[2] (2z^2 - x^2 - y^2)                   0.31539156525252005,
//!            Y_7  = C2[3] xz                                  -1.0925484305920792,
//!            Y_8  = C2[4] (x^2 - y^2)                          0.5462742152960396 ]
//! degree 3   Y_9  = C3[0] y (3x^2 - y^2)                C3 = [-0.5900435899266435,
//!            Y_10 = C3[1] xyz                                  2.890611442640554,
//!            Y_11 = C3[2] y (4z^2 - x^2 - y^2)                -0.4570457994644658,
//!            Y_12 = C3[3] z (2z^2 - 3x^2 - 3y^2)               0.3731763325901154,
//!            Y_13 = C3[4] x (4z^2 - x^2 - y^2)                -0.4570457994644658,
//!            Y_14 = C3[5] z (x^2 - y^2)                        1.445305721320277,
//!            Y_15 = C3[6] x (x^2 - 3y^2)                      -0.5900435899266435 ]
//! ```
//!
//! A lower degree's basis is a prefix of a higher one's. The activation is the sigmoid itself,
//! as in Plenoxels (3D Gaussian splatting instead adds 0.5 and clamps: fold that into the
//! coefficients' meaning, not into this op). Degree 0 is view independent:
//! `sigmoid(C0 k_c)`.
//!
//! # Computation
//!
//! The sigmoid and its slope are the stable forms of [`activation`](crate::activation)
//! (`sigmoid(x) = exp(min(x, 0)) / (1 + e)`, `sigmoid'(x) = e / (1 + e)^2` with
//! `e = exp(-|x|)`): exactly 0 or 1 where saturated, and a slope that is never `y (1 - y)`.
//! Every row is computed in f64 (basis, sums, sigmoid) and rounded once to the data's
//! precision (f32 or f64). The backward is in closed form,
//! `dL/dcoeffs[i, c B + b] = dL/dcolor[i, c] sigmoid'(x_ic) Y_b(d_i)`, recomputing `x_ic`
//! from the inputs (nothing is kept on the tape), so the tape's gradients are bitwise those of
//! [`ShColor::vjp`]. Rows run in parallel in fixed chunks, each row on its own, so the
//! results are bitwise the same for any number of threads.
//!
//! Input is checked: the degree (at most 3), the shapes, finite values, and directions of
//! length 1 within `1e-3` (they are used as given, not normalised); the first row at fault is
//! named ([`OpsError`](crate::OpsError)).
//!
//! ```
//! use fogray_ops::sh::{basis::{C0, C1}, ShColor};
//! use fogray_tape::Tape;
//! use ndarray::arr2;
//!
//! let op = ShColor::new(1)?; // 4 basis functions a channel: C0, -C1 y, C1 z, -C1 x
//! let mut tape = Tape::<f64>::new();
//! let coeffs = tape.param(arr2(&[[1.0, 0.0, 2.0, 0.0, /**/ 0.0, 0.0, 0.0, 0.0, /**/ 0.0, 5.0, 0.0, 5.0]]));
//! let up = tape.constant(arr2(&[[0.0, 0.0, 1.0]]));
//! let color = op.apply(&mut tape, coeffs, up)?;
//! let sigmoid = |x: f64| 1.0 / (1.0 + (-x).exp());
//! let x = C0 + 2.0 * C1; // looking along +z: Y = (C0, 0, C1, 0)
//! assert!((tape.value(color)?[[0, 0]] - sigmoid(x)).abs() < 1e-15);
//! assert_eq!(tape.value(color)?[[0, 1]], 0.5);
//! assert_eq!(tape.value(color)?[[0, 2]], 0.5); // the x and y terms vanish along z
//! let loss = tape.sum(color)?;
//! let grads = tape.backward(loss)?;
//! let g = grads.get(coeffs).unwrap();
//! let slope = sigmoid(x) * (1.0 - sigmoid(x));
//! assert!((g[[0, 2]] - slope * C1).abs() < 1e-15); // dcolor_0 / dk_z = sigmoid'(x) C1
//! assert_eq!(g[[0, 4]], 0.25 * C0); // sigmoid'(0) = 1/4
//! assert_eq!(g[[0, 1]], 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod basis;
mod check;
mod config;
mod kernel;
mod op;
pub mod twin;

pub use config::ShColor;
