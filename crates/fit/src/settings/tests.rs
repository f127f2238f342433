use super::*;

#[test]
fn a_long_budget_of_seconds_grows_to_the_finer_lattice() {
    let long = FitSettings::LONG_FIT_SECONDS;
    assert_eq!(FitSettings::recommended_grid(Budget::Seconds(60.0)), 128);
    assert_eq!(FitSettings::recommended_grid(Budget::Seconds(long - 1e-9)), 128);
    assert_eq!(FitSettings::recommended_grid(Budget::Seconds(long)), 192);
    assert_eq!(FitSettings::recommended_grid(Budget::Seconds(300.0)), 192);
    // Steps say nothing of time.
    assert_eq!(FitSettings::recommended_grid(Budget::Steps(1_000_000)), 128);
    assert!(FitSettings::RECOMMENDED.check().is_ok());
}

#[test]
fn given_flags_win_over_the_saved_settings_and_the_rest_is_saved() {
    let saved = FitSettings {
        grid: 32,
        lr: 0.5,
        steps: Some(100),
        ..FitSettings::DEFAULT
    };
    let flags = FitSettings {
        lr: 0.1,
        seconds: Some(5.0),
        grid: 64,
        ..FitSettings::DEFAULT
    };
    let merged = flags.given_over(&saved, &|id| id == "lr" || id == "seconds").unwrap();
    assert_eq!(merged.lr, 0.1);
    assert_eq!(merged.grid, 32);
    // The budget is one setting: --seconds clears the saved --steps.
    assert_eq!(merged.budget(), Budget::Seconds(5.0));
    let untouched = flags.given_over(&saved, &|_| false).unwrap();
    assert_eq!(untouched, saved);
}

#[test]
fn settings_written_before_the_background_degree_read_degree_2() {
    const { assert!(FitSettings::DEFAULT.background_degree == 3) };
    let old: FitSettings = serde_json::from_str(r#"{"grid": 32, "learn_background": true}"#).unwrap();
    assert_eq!(old.background_degree, 2);
    let text = serde_json::to_string(&FitSettings::DEFAULT).unwrap();
    assert_eq!(serde_json::from_str::<FitSettings>(&text).unwrap().background_degree, 3);
    let four = FitSettings {
        background_degree: 4,
        ..FitSettings::DEFAULT
    };
    assert!(four.check().unwrap_err().to_string().contains("--background-degree"));
}

#[test]
fn settings_written_before_random_backgrounds_read_them_off() {
    const { assert!(FitSettings::DEFAULT.random_background) };
    let old: FitSettings = serde_json::from_str(r#"{"grid": 32}"#).unwrap();
    assert!(!old.random_background);
    assert_eq!(
        FitSettings {
            random_background: true,
            // The other field that settings this old read otherwise (see above).
            background_degree: FitSettings::DEFAULT.background_degree,
            ..old
        },
        FitSettings {
            grid: 32,
            ..FitSettings::DEFAULT
        }
    );
    let text = serde_json::to_string(&FitSettings::DEFAULT).unwrap();
    assert!(serde_json::from_str::<FitSettings>(&text).unwrap().random_background);
}

#[test]
fn every_setting_is_checked() {
    let ok = FitSettings::DEFAULT;
    assert!(ok.check().is_ok());
    for (bad, flag) in [
        (FitSettings { grid: 1, ..ok }, "--grid"),
        (FitSettings { batch: 0, ..ok }, "--batch"),
        (FitSettings { lr: f64::NAN, ..ok }, "--lr"),
        (FitSettings { lr_final: 0.0, ..ok }, "--lr-final"),
        (FitSettings { tv: -1.0, ..ok }, "--tv"),
        // Finite corners whose span overflows (the samplers' step would be infinite).
        (
            FitSettings {
                scene_box: Some(SceneBox {
                    min: [-1e308; 3],
                    max: [1e308; 3],
                }),
                ..ok
            },
            "--box",
        ),
        (
            FitSettings {
                shift: f64::INFINITY,
                ..ok
            },
            "--shift",
        ),
        (FitSettings { steps: Some(0), ..ok }, "--steps"),
        (
            FitSettings {
                evaluations: MAX_EVALUATIONS + 1,
                ..ok
            },
            "--evaluations",
        ),
        (
            FitSettings {
                seconds: Some(-1.0),
                ..ok
            },
            "--seconds",
        ),
    ] {
        let e = bad.check().unwrap_err().to_string();
        assert!(e.starts_with(flag), "{e}");
    }
}

#[test]
fn a_checkpoint_that_names_the_prior_smoothness_reads_as_tv() {
    let old: FitSettings = serde_json::from_str(r#"{"smoothness": 0.25}"#).unwrap();
    assert_eq!(old.tv, 0.25);
    let text = serde_json::to_string(&old).unwrap();
    assert!(text.contains(r#""tv":0.25"#) && !text.contains("smoothness"), "{text}");
}
