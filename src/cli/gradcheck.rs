//! `fogray gradcheck`: the input's gradients from the fused op, the stable taped twin and
//! central finite differences (f64), and the worst disagreements between them.

use fogray_ops::{Background, Composite, CompositeInputs};
use fogray_tape::{gradcheck, GradcheckOptions, Tape, TapeError, Var};
use ndarray::{Array1, Array2, ArrayD};

use super::evaluate::{evaluate, Method};
use super::input::Packed;

/// `L = sum(g * C)` of the fused op as a function of (sigma, delta, color, background).
fn loss(tape: &mut Tape<f64>, v: &[Var], p: &Packed, seed: &ArrayD<f64>) -> Result<Var, TapeError> {
    let op = Composite::new(&p.offsets)
        .map_err(|e| TapeError::InvalidArgument {
            op: "gradcheck",
            reason: e.to_string(),
        })?
        .background(Background::PerRay);
    let out = op.apply(
        tape,
        &CompositeInputs {
            sigma: v[0],
            delta: v[1],
            color: v[2],
            background: Some(v[3]),
            t: None,
        },
    )?;
    let g = tape.constant(seed.clone());
    let weighted = tape.mul(out.color, g)?;
    tape.sum(weighted)
}

fn worst(a: &[f64], b: &[f64]) -> (f64, usize) {
    a.iter()
        .zip(b)
        .enumerate()
        .map(|(i, (x, y))| ((x - y).abs(), i))
        .fold((0.0, 0), |m, e| if e.0 > m.0 { e } else { m })
}

/// A text report: worst absolute difference per input, fused vs taped and fused vs FD.
pub fn run(p: &Packed) -> Result<String, String> {
    let rays = p.offsets.len() - 1;
    let eps = GradcheckOptions::default().eps;
    if let Some(i) = p.sigma.iter().zip(&p.delta).position(|(&s, &d)| s <= eps || d <= eps) {
        return Err(format!(
            "sample {i} (packed index) has sigma or delta <= {eps}: central differences would step to a negative value, which the op rejects"
        ));
    }
    let seed: Vec<f64> = p.grad_color.clone().unwrap_or_else(|| vec![1.0; rays * p.ch]);
    let fused = evaluate::<f64>(p, Method::Fused, Some(&seed))?
        .grads
        .ok_or("no gradient")?;
    let taped = evaluate::<f64>(p, Method::Taped, Some(&seed))?
        .grads
        .ok_or("no gradient")?;
    let shape_err = |e: ndarray::ShapeError| e.to_string();
    let inputs = [
        Array1::from(p.sigma.clone()).into_dyn(),
        Array1::from(p.delta.clone()).into_dyn(),
        Array2::from_shape_vec((p.sigma.len(), p.ch), p.color.clone())
            .map_err(shape_err)?
            .into_dyn(),
        Array2::from_shape_vec((rays, p.ch), p.background.clone())
            .map_err(shape_err)?
            .into_dyn(),
    ];
    let seed_arr = ArrayD::from_shape_vec(vec![rays, p.ch], seed).map_err(shape_err)?;
    let report =
        gradcheck(|t, v| loss(t, v, p, &seed_arr), &inputs, &GradcheckOptions::default()).map_err(|e| e.to_string())?;
    let mut numeric: [Vec<f64>; 4] = Default::default();
    for e in &report.entries {
        if let Some(i) = e.input {
            numeric[i].push(e.numeric);
        }
    }
    let mut out = String::from("input        |fused-taped| (at)   |fused-FD|    (at)\n");
    let names = ["sigma", "delta", "color", "background"];
    let analytic = [&fused.sigma, &fused.delta, &fused.color, &fused.background];
    let twin = [&taped.sigma, &taped.delta, &taped.color, &taped.background];
    for i in 0..4 {
        let (dt, at_t) = worst(analytic[i], twin[i]);
        let (dn, at_n) = worst(analytic[i], &numeric[i]);
        out += &format!("{:<12} {dt:<12.3e} {at_t:>5}   {dn:<12.3e} {at_n:>5}\n", names[i]);
    }
    out += &format!(
        "(absolute differences; central finite differences in f64, step 1e-6, over {} elements)",
        report.checked
    );
    Ok(out)
}
