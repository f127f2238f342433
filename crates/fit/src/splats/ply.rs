//! Splats as the PLY file that 3D Gaussian splatting's viewers open (the Inria viewer,
//! SuperSplat, brush, gsplat's exporters): binary little-endian, one `vertex` element per
//! splat with float properties `x y z`, `nx ny nz` (zero), `f_dc_0..2`, `f_rest_*`
//! (channel-major, `3 ((degree + 1)^2 - 1)` of them), `opacity` (a logit), `scale_0..2`
//! (log standard deviations) and `rot_0..3` (a quaternion `w x y z`).
//!
//! Those viewers take a colour as `0.5 + sum_b Y_b f_b` (clamped), fogray as
//! `sigmoid(sum_b Y_b k_b)`. The view-independent colour `c = sigmoid(C0 k_0)` is written
//! exactly (`f_dc = (c - 0.5) / C0`); the view-dependent terms are the sigmoid's first order
//! about it (`f_b = c (1 - c) k_b`), exact as they vanish.
//!
//! Written by hand for the same reason as the mesh's PLY ([`crate::mesh::ply`]): a header and
//! one packed array.

use std::path::Path;

use fogray_ops::sh::basis::C0;
use fogray_tape::Float;

use super::model::SplatModel;
use crate::error::FitError;

/// The property names of a file of colour degree `degree`, in the file's order.
pub(crate) fn property_names(degree: usize) -> Vec<String> {
    let rest = 3 * ((degree + 1) * (degree + 1) - 1);
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    names.extend((0..rest).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    names
}

fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

/// The PLY header of `count` splats of colour degree `degree`: what a file holds before its
/// splats' floats.
pub(crate) fn header(degree: usize, count: usize) -> String {
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment fogray splats, colour degree {degree}\nelement vertex {count}\n"
    );
    for name in property_names(degree) {
        header += &format!("property float {name}\n");
    }
    header + "end_header\n"
}

/// `model` in the 3DGS PLY layout (see the [module docs](self)), as the file's bytes.
///
/// Errors: a parameter lent to a tape ([`FitError::Param`]).
pub(crate) fn splats_ply<F: Float>(model: &SplatModel<F>) -> Result<Vec<u8>, FitError> {
    let a = model.arrays()?;
    let basis = (model.degree() + 1) * (model.degree() + 1);
    let names = property_names(model.degree());
    let mut out = Vec::with_capacity(64 * 1024 + 4 * names.len() * model.len());
    out.extend_from_slice(header(model.degree(), model.len()).as_bytes());
    for i in 0..model.len() {
        let mut push = |v: f64| out.extend_from_slice(&(v as f32).to_le_bytes());
        for k in 0..3 {
            push(a.means[[i, k]].as_f64());
        }
        for _ in 0..3 {
            push(0.0);
        }
        let dc: [f64; 3] = [0, 1, 2].map(|c| sigmoid(C0 * a.sh[[i, c * basis]].as_f64()));
        for c in dc {
            push((c - 0.5) / C0);
        }
        for (c, colour) in dc.iter().enumerate() {
            for b in 1..basis {
                push(colour * (1.0 - colour) * a.sh[[i, c * basis + b]].as_f64());
            }
        }
        push(a.opacity_logits[i].as_f64());
        for k in 0..3 {
            push(a.log_scales[[i, k]].as_f64());
        }
        for k in 0..4 {
            push(a.quats[[i, k]].as_f64());
        }
    }
    Ok(out)
}

/// Writes `model` to the file `path` whole or not at all ([`fogray_data::write_atomic`]).
///
/// Errors: the file cannot be written (naming it), a parameter lent to a tape.
pub(crate) fn write_ply<F: Float>(path: &Path, model: &SplatModel<F>) -> Result<(), FitError> {
    let bytes = splats_ply(model)?;
    fogray_data::write_atomic(path, |out| out.write_all(&bytes)).map_err(|e| FitError::Write {
        path: path.to_path_buf(),
        what: "the splats",
        reason: match e {
            // Its message names the file again.
            fogray_data::DataError::Io { message, .. } => message,
            other => other.to_string(),
        },
    })
}
