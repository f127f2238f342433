// The references are quoted to the 17 digits they were computed to; f64 rounds them.
#![allow(clippy::excessive_precision)]

use super::super::test_util::{assert_gradcheck, values_close};
use crate::{Float, Tape, Var};
use ndarray::{arr1, ArrayD};

const NAMES: [&str; 5] = ["sigmoid", "softplus", "tanh", "sin", "cos"];

fn apply<F: Float>(t: &mut Tape<F>, name: &str, x: Var) -> crate::Result<Var> {
    match name {
        "sigmoid" => t.sigmoid(x),
        "softplus" => t.softplus(x),
        "tanh" => t.tanh(x),
        "sin" => t.sin(x),
        _ => t.cos(x),
    }
}

/// Values and derivatives of `name` at `xs` in precision `F`, widened to f64.
fn value_and_slope<F: Float>(name: &str, xs: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut t = Tape::<F>::new();
    let x = t.param(arr1(&xs.iter().map(|&v| F::lit(v)).collect::<Vec<_>>()));
    let y = apply(&mut t, name, x).unwrap();
    let s = t.sum(y).unwrap();
    let g = t.backward(s).unwrap();
    let wide = |a: ndarray::ArrayViewD<'_, F>| a.iter().map(|v| v.as_f64()).collect();
    (wide(t.value(y).unwrap()), wide(g.get(x).unwrap()))
}

/// References at x = (-1, 0, 0.5, 2), from the formulas in the module docs evaluated with
/// 30-digit arithmetic (mpmath), rounded to 17 digits:
/// sigmoid = 1/(1 + e^-x), its slope sigmoid(x) sigmoid(-x); softplus = ln(1 + e^x), slope
/// sigmoid; tanh, slope 1/cosh^2; sin, slope cos; cos, slope -sin.
fn references(name: &str) -> ([f64; 4], [f64; 4]) {
    match name {
        "sigmoid" => (
            [
                0.268_941_421_369_995_12,
                0.5,
                0.622_459_331_201_854_56,
                0.880_797_077_977_882_44,
            ],
            [
                0.196_611_933_241_481_85,
                0.25,
                0.235_003_712_201_594_49,
                0.104_993_585_403_506_52,
            ],
        ),
        "softplus" => (
            [
                0.313_261_687_518_222_83,
                std::f64::consts::LN_2,
                0.974_076_984_180_106_68,
                2.126_928_011_042_972_5,
            ],
            [
                0.268_941_421_369_995_12,
                0.5,
                0.622_459_331_201_854_56,
                0.880_797_077_977_882_44,
            ],
        ),
        "tanh" => (
            [
                -0.761_594_155_955_764_89,
                0.0,
                0.462_117_157_260_009_76,
                0.964_027_580_075_816_88,
            ],
            [
                0.419_974_341_614_026_07,
                1.0,
                0.786_447_732_965_927_41,
                0.070_650_824_853_164_466,
            ],
        ),
        "sin" => (
            [
                -0.841_470_984_807_896_51,
                0.0,
                0.479_425_538_604_203_0,
                0.909_297_426_825_681_7,
            ],
            [
                0.540_302_305_868_139_72,
                1.0,
                0.877_582_561_890_372_72,
                -0.416_146_836_547_142_39,
            ],
        ),
        _ => (
            [
                0.540_302_305_868_139_72,
                1.0,
                0.877_582_561_890_372_72,
                -0.416_146_836_547_142_39,
            ],
            [
                0.841_470_984_807_896_51,
                0.0,
                -0.479_425_538_604_203_0,
                -0.909_297_426_825_681_7,
            ],
        ),
    }
}

#[test]
fn values_and_slopes_match_high_precision_references_in_f64_and_f32() {
    let xs = [-1.0, 0.0, 0.5, 2.0];
    for name in NAMES {
        let (want_y, want_dy) = references(name);
        let (y, dy) = value_and_slope::<f64>(name, &xs);
        values_close(name, arr1(&y).into_dyn().view(), &want_y, 4e-16);
        values_close(name, arr1(&dy).into_dyn().view(), &want_dy, 4e-16);
        let (y, dy) = value_and_slope::<f32>(name, &xs);
        values_close(name, arr1(&y).into_dyn().view(), &want_y, 3e-7);
        values_close(name, arr1(&dy).into_dyn().view(), &want_dy, 3e-7);
    }
}

#[test]
fn slopes_at_zero_are_exact() {
    // sigmoid'(0) = 1/4, softplus'(0) = sigmoid(0) = 1/2, tanh'(0) = 1, sin'(0) = 1, cos'(0) = 0:
    // all representable, so exact. A softplus built from relu has relu'(0) = 0 there instead.
    let want = [0.25, 0.5, 1.0, 1.0, 0.0];
    for (name, want) in NAMES.into_iter().zip(want) {
        assert_eq!(value_and_slope::<f64>(name, &[0.0]).1, [want], "{name} f64");
        assert_eq!(value_and_slope::<f32>(name, &[0.0]).1, [want], "{name} f32");
    }
}

fn saturates<F: Float>() {
    let xs = [-1e4, 1e4];
    let (y, dy) = value_and_slope::<F>("sigmoid", &xs);
    assert_eq!((y, dy), (vec![0.0, 1.0], vec![0.0, 0.0]), "sigmoid {}", F::NAME);
    let (y, dy) = value_and_slope::<F>("softplus", &xs);
    assert_eq!((y, dy), (vec![0.0, 1e4], vec![0.0, 1.0]), "softplus {}", F::NAME);
    let (y, dy) = value_and_slope::<F>("tanh", &xs);
    assert_eq!((y, dy), (vec![-1.0, 1.0], vec![0.0, 0.0]), "tanh {}", F::NAME);
    for name in ["sin", "cos"] {
        let (y, dy) = value_and_slope::<F>(name, &xs);
        assert!(
            y.iter().chain(&dy).all(|v| v.is_finite() && v.abs() <= 1.0),
            "{name} {}",
            F::NAME
        );
    }
}

#[test]
fn saturate_exactly_with_finite_slopes_at_plus_minus_1e4() {
    saturates::<f32>();
    saturates::<f64>();
}

#[test]
fn softplus_is_x_to_the_last_bit_for_large_x() {
    // ln_1p(e^-x) < e^-x is below half an ulp of x from x = 17 in f32 (e^-17 = 4.1e-8, half an
    // ulp of 16 is 9.5e-7) and from x = 37 in f64 (e^-37 = 8.5e-17, half an ulp of 32 is 3.6e-15).
    let grid = |from: f64| -> Vec<f64> {
        (0..400)
            .map(|k| from * 1.02f64.powi(k))
            .filter(|&x| x <= 1e4)
            .chain([1e4])
            .collect()
    };
    for (from, name) in [(17.0, "f32"), (37.0, "f64")] {
        let xs = grid(from);
        let y = if name == "f32" {
            value_and_slope::<f32>("softplus", &xs).0
        } else {
            value_and_slope::<f64>("softplus", &xs).0
        };
        for (x, y) in xs.iter().zip(&y) {
            let x = if name == "f32" { f64::from(*x as f32) } else { *x };
            assert_eq!(y.to_bits(), x.to_bits(), "softplus({x}) in {name}");
        }
    }
}

#[test]
fn the_tails_keep_digits_where_the_textbook_forms_lose_them() {
    // References from 30-digit arithmetic: sigmoid'(40) = 4.2483542552915611e-18,
    // tanh'(20) = 1/cosh^2(20) = 1.6993417021166356e-17, softplus(-40) = 4.2483542552915611e-18.
    let (_, ds) = value_and_slope::<f64>("sigmoid", &[40.0]);
    let (_, dt) = value_and_slope::<f64>("tanh", &[20.0]);
    let (sp, _) = value_and_slope::<f64>("softplus", &[-40.0]);
    let cases = [
        ("sigmoid'(40)", ds[0], 4.248_354_255_291_561_1e-18),
        ("tanh'(20)", dt[0], 1.699_341_702_116_635_6e-17),
        ("softplus(-40)", sp[0], 4.248_354_255_291_561_1e-18),
    ];
    for (what, got, want) in cases {
        assert!(((got - want) / want).abs() < 1e-14, "{what}: got {got}, want {want}");
    }
    // The textbook forms: y (1 - y), 1 - tanh^2 and ln(1 + e^x) all give 0 here, and e^x
    // overflows at 1e4.
    let y = 1.0 / (1.0 + (-40.0f64).exp());
    let t = 20.0f64.tanh();
    assert_eq!(
        (y * (1.0 - y), 1.0 - t * t, (1.0 + (-40.0f64).exp()).ln()),
        (0.0, 0.0, 0.0)
    );
    assert_eq!(1e4f64.exp(), f64::INFINITY);
}

#[test]
fn every_activation_passes_gradcheck_in_f64() {
    let x = ArrayD::from_shape_vec(vec![2, 3], vec![-2.1, -0.3, 0.0, 0.7, 1.3, 3.0]).unwrap();
    for name in NAMES {
        assert_gradcheck(name, std::slice::from_ref(&x), move |t, v| apply(t, name, v[0]));
    }
}
