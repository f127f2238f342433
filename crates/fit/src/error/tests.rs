//! The typed errors of settings and views print the one line they printed as text before
//! (the CLI and the docs quote them): each checked against the line written out by hand.

use ndarray::Array3;

use crate::dataset::{Dataset, View};
use crate::dense::DenseGrid;
use crate::settings::{Budget, FitSettings, SceneBox};
use crate::space::SpaceChoice;
use crate::splats::model::SplatModel;
use crate::splats::settings::SplatSettings;
use crate::testing::view;
use crate::FitError;
use fogray_ops::{Intrinsics, PinholeCamera};

/// The error of `settings`' check, with its line.
fn refusal(settings: FitSettings) -> (FitError, String) {
    let e = settings.check().unwrap_err();
    let line = e.to_string();
    (e, line)
}

#[test]
fn a_flag_out_of_range_names_the_flag_and_the_rule() {
    let (e, line) = refusal(FitSettings {
        grid: 1,
        ..FitSettings::DEFAULT
    });
    assert_eq!(
        e,
        FitError::Setting {
            flag: "--grid",
            value: None,
            rule: "must be at least 2".into()
        }
    );
    assert_eq!(line, "--grid must be at least 2");
    let (e, line) = refusal(FitSettings {
        evaluations: 10_001,
        ..FitSettings::DEFAULT
    });
    assert!(matches!(e, FitError::Setting { flag: "--evaluations", value: Some(ref v), .. } if v == "10001"));
    assert_eq!(
        line,
        "--evaluations 10001: at most 10000 (each renders every held-out view)"
    );
    let (_, line) = refusal(FitSettings::DEFAULT.with_budget(Budget::Steps(0)));
    assert_eq!(line, "--steps must be at least 1");
    let (_, line) = refusal(FitSettings::DEFAULT.with_budget(Budget::Seconds(1e308)));
    assert_eq!(
        line,
        "--seconds 1e308: at most 604800 (one week; a budget that can end)"
    );
    let contracted = FitSettings {
        space: SpaceChoice::Contracted,
        framing: None,
        ..FitSettings::DEFAULT
    };
    assert_eq!(
        contracted.field_space().unwrap_err().to_string(),
        "--space contracted needs an inner region (framed from the cameras by fogray fit)"
    );
}

#[test]
fn a_box_names_its_axis_and_bounds() {
    let with_box = |min, max| FitSettings {
        scene_box: Some(SceneBox { min, max }),
        ..FitSettings::DEFAULT
    };
    let (e, line) = refusal(with_box([0.0, f64::NAN, 0.0], [1.0; 3]));
    assert!(matches!(e, FitError::BoxAxis { axis: 1, .. }), "{e:?}");
    assert_eq!(line, "--box: axis 1 runs from NaN to 1 (must be finite and increasing)");
    let (_, line) = refusal(with_box([0.0, 2.0, 0.0], [1.0, 0.5, 1.0]));
    assert_eq!(line, "--box: axis 1 runs from 2 to 0.5 (must be finite and increasing)");
    let (e, line) = refusal(with_box([-2e6, 0.0, 0.0], [1.0; 3]));
    assert!(matches!(e, FitError::BoxBeyondRange { axis: 0, .. }), "{e:?}");
    assert_eq!(line, "--box: axis 0 runs from -2e6 to 1e0, beyond 1e6 from the origin");
}

#[test]
fn a_splat_setting_out_of_range_reads_as_before() {
    let degree = SplatSettings {
        degree: 4,
        ..SplatSettings::default()
    };
    assert_eq!(
        degree.check().unwrap_err().to_string(),
        "a splat colour degree of 4 (0 to 3)"
    );
    let cap = SplatSettings {
        max_splats: 0,
        ..SplatSettings::default()
    };
    assert_eq!(
        cap.check().unwrap_err().to_string(),
        "a splat fit's budget, densification period, initial count and cap must be positive"
    );
}

#[test]
fn views_that_do_not_fit_together_are_named() {
    let k = Intrinsics::from_vertical_fov(8, 8, 40f64.to_radians()).unwrap();
    let camera = PinholeCamera::look_at(k, [3.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let e = View::new("left", &camera, Array3::zeros((8, 7, 3))).unwrap_err();
    assert_eq!(
        e,
        FitError::ViewSize {
            view: "left".into(),
            what: "picture",
            got: vec![8, 7, 3],
            expected: vec![8, 8, 3]
        }
    );
    assert_eq!(
        e.to_string(),
        "view left: picture [8, 7, 3], but the camera's image is [8, 8, 3]"
    );
    let one = || vec![view(0, [3.0, 0.0, 0.5])];
    let e = Dataset::new(one(), Vec::new(), [1.0; 3]).unwrap_err();
    assert_eq!(
        (e.clone(), e.to_string().as_str()),
        (FitError::NoTestView, "the fit needs at least one test view")
    );
    let e = Dataset::new(Vec::new(), one(), [1.0; 3]).unwrap_err();
    assert_eq!(
        (e.clone(), e.to_string().as_str()),
        (FitError::NoTrainingPixel, "the fit needs at least one training pixel")
    );
    let mut changed = one();
    changed[0].image = Array3::zeros((4, 8, 3));
    let e = Dataset::new(changed, one(), [1.0; 3]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "view 000: picture [4, 8, 3], but the camera's image is [8, 8, 3]"
    );
}

#[test]
fn ctrl_c_refused_says_so() {
    let e = FitError::CtrlC {
        reason: "a handler is already set".into(),
    };
    assert_eq!(e.to_string(), "cannot catch Ctrl-C: a handler is already set");
}

#[test]
fn each_typed_refusal_reads_as_written_by_hand() {
    use crate::environment::Environment;
    use crate::shading::Shading;
    use crate::splats::model::SplatArraysOwned;
    use fogray_ops::OpsError;
    use ndarray::{arr1, arr2, Array2};

    let picture = || view(0, [3.0, 0.5, 0.0]);
    let mut changed_alpha = picture().with_alpha(Array2::from_elem((8, 8), 0.5)).unwrap();
    changed_alpha.alpha = Some(Array2::zeros((8, 2)));
    let splats = SplatModel::<f64>::new(
        SplatArraysOwned {
            means: arr2(&[[0.0; 3]]),
            log_scales: arr2(&[[-2.0; 3]]),
            quats: arr2(&[[1.0, 0.0, 0.0, 0.0]]),
            opacity_logits: arr1(&[0.0]),
            sh: Array2::zeros((1, 3)),
        },
        0,
    )
    .unwrap();
    let folder = std::env::temp_dir().join(format!("fogray-no-such-folder-{}", std::process::id()));
    let ply = folder.join("m.ply");
    let cases: [(FitError, String); 7] = [
        (
            Environment::new(4).unwrap_err(),
            "--background-degree: sh_color: degree is 4 (must be 0, 1, 2 or 3)".into(),
        ),
        (
            Shading::new(0.0, 5).unwrap_err(),
            "--sh-degree: sh_color: degree is 5 (must be 0, 1, 2 or 3)".into(),
        ),
        (
            picture().with_alpha(Array2::zeros((8, 7))).unwrap_err(),
            "view 000: alpha [8, 7], but the camera's image is [8, 8]".into(),
        ),
        (
            Dataset::new(vec![changed_alpha], vec![picture()], [1.0; 3]).unwrap_err(),
            "view 000: alpha [8, 2], but the camera's image is [8, 8]".into(),
        ),
        (
            crate::splats::ply::write_ply(&ply, &splats).unwrap_err(),
            format!(
                "{}: the splats cannot be written: No such file or directory (os error 2)",
                ply.display()
            ),
        ),
        (
            DenseGrid::<f64>::new(SceneBox::UNIT, 2, 0.0, -1.0).err().unwrap(),
            "--tv: total_variation: weight is -1 (must be finite and non-negative)".into(),
        ),
        (
            DenseGrid::<f64>::new(SceneBox::UNIT, 2, 0.0, 0.0)
                .and_then(|g| g.with_distortion(-0.5))
                .err()
                .unwrap(),
            "--distortion -0.5: must be finite and non-negative".into(),
        ),
    ];
    for (e, line) in cases {
        assert_eq!(e.to_string(), line, "{e:?}");
    }
    // The op's refusal stays the error's source, typed.
    let e = Environment::new(4).unwrap_err();
    let source = std::error::Error::source(&e).and_then(|s| s.downcast_ref::<OpsError>());
    assert_eq!(
        source.map(ToString::to_string).as_deref(),
        Some("sh_color: degree is 4 (must be 0, 1, 2 or 3)")
    );
    assert!(!folder.exists());
}
