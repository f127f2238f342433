//! `fogray render --orbit`: the frames, the GIF and the depth maps a tiny fitted model gives,
//! the defaults taken from its dataset, and the flags refused (exit status 2, one line).

use std::path::Path;

use crate::common::{
    arg, assert_refused, cameras, fogray, fogray_in, frame_name, intrinsics, render_cameras, tiny_model, write_ball,
    LENS, TINY_FIT,
};

/// The size and colour type of the PNG `path`.
fn png_info(path: &Path) -> (u32, u32, image::ColorType) {
    let image = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (image.width(), image.height(), image.color())
}

/// The files in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    names
}

#[test]
fn an_orbit_writes_its_frames_a_looping_gif_and_depth_maps() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = tiny_model(dir.path());
    let out = dir.path().join("orbit");
    let gif_path = dir.path().join("orbit.gif");
    let run = fogray(&[
        "render",
        "--model",
        arg(&model),
        "--orbit",
        "4",
        "--size",
        "20x16",
        "--elevation",
        "-15",
        "--out",
        arg(&out),
        "--gif",
        arg(&gif_path),
        "--depth",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let frames: Vec<String> = (0..4).map(|k| format!("frame-{k:03}")).collect();
    let mut want: Vec<String> = frames
        .iter()
        .flat_map(|f| [format!("{f}.png"), format!("{f}-depth.png")])
        .collect();
    // stdout: each frame and its depth map, then the GIF.
    let printed: Vec<&str> = run.stdout.lines().collect();
    assert_eq!(printed.len(), 9, "{}", run.stdout);
    for (line, name) in printed.iter().zip(&want) {
        assert_eq!(Path::new(line), out.join(name));
    }
    assert_eq!(Path::new(printed[8]), gif_path);
    // No partial file left beside them.
    want.sort();
    assert_eq!(listing(&out), want);
    assert_eq!(listing(dir.path()).iter().filter(|n| n.contains("partial")).count(), 0);
    for f in &frames {
        assert_eq!(
            png_info(&out.join(format!("{f}.png"))),
            (20, 16, image::ColorType::Rgb8)
        );
        // The depth map: the frame magnified (256 / 20 = 12 times here) beside a colour bar,
        // under a heading.
        let (w, h, _) = png_info(&out.join(format!("{f}-depth.png")));
        assert!(w > 20 * 12 && h > 16 * 12, "{f}: depth map {w}x{h}");
    }

    // The GIF: four frames of 20x16, looping forever, 5 hundredths of a second each.
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::RGBA);
    let mut decoder = options.read_info(std::fs::File::open(&gif_path).unwrap()).unwrap();
    assert_eq!((decoder.width(), decoder.height()), (20, 16));
    let mut count = 0;
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        assert_eq!((frame.width, frame.height, frame.delay), (20, 16, 5));
        assert_eq!(frame.buffer.len(), 20 * 16 * 4);
        count += 1;
    }
    assert_eq!(count, 4);
    // Looping forever: the NETSCAPE2.0 application block with a loop count of 0 (the decoder
    // of gif 0.12 does not report it).
    let bytes = std::fs::read(&gif_path).unwrap();
    let forever = b"NETSCAPE2.0\x03\x01\x00\x00\x00";
    assert!(bytes.windows(forever.len()).any(|w| w == forever));
}

/// Without --size, --fov or --radius the orbit takes its frames' size from the model's
/// dataset (8x8 here); once the dataset is gone, 200x200, with a note on stderr.
#[test]
fn an_orbit_takes_its_defaults_from_the_models_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let (data, model) = tiny_model(dir.path());
    let out = dir.path().join("defaults");
    let render = || fogray(&["render", "--model", arg(&model), "--orbit", "2", "--out", arg(&out)]);
    let run = render();
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stderr.is_empty(), "{}", run.stderr);
    assert_eq!(png_info(&out.join("frame-001.png")), (8, 8, image::ColorType::Rgb8));

    std::fs::remove_dir_all(&data).unwrap();
    let run = render();
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stderr.contains("dataset cannot be read"), "{}", run.stderr);
    assert_eq!(png_info(&out.join("frame-001.png")), (200, 200, image::ColorType::Rgb8));
}

/// A model fitted from a relative `--data` path still finds its dataset from another folder:
/// the checkpoint names it absolutely.
#[test]
fn a_model_fitted_from_a_relative_path_finds_its_dataset_from_anywhere() {
    let dir = tempfile::tempdir().unwrap();
    write_ball(&dir.path().join("data"), &cameras(8, intrinsics(8), LENS));
    let mut args = vec!["fit", "--data", "data", "--save-model", "m.safetensors"];
    args.extend(TINY_FIT);
    let fit = fogray_in(dir.path(), &args);
    assert_eq!(fit.code, 0, "{}", fit.stderr);
    let out = dir.path().join("frames");
    let model = dir.path().join("m.safetensors");
    let run = fogray(&["render", "--model", arg(&model), "--orbit", "2", "--out", arg(&out)]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stderr.is_empty(), "{}", run.stderr);
    assert_eq!(png_info(&out.join("frame-001.png")), (8, 8, image::ColorType::Rgb8));
}

/// `--depth` with `--cameras`: `DIR/<name>-depth.png` beside each frame.
#[test]
fn depth_maps_are_written_beside_a_transforms_files_frames() {
    let dir = tempfile::tempdir().unwrap();
    let (data, model) = tiny_model(dir.path());
    let out = dir.path().join("views");
    let run = render_cameras(&model, &data, &out, &["--depth"]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let mut want: Vec<String> = (0..8)
        .flat_map(|i| [format!("{}.png", frame_name(i)), format!("{}-depth.png", frame_name(i))])
        .collect();
    want.sort();
    assert_eq!(listing(&out), want);
    assert_eq!(run.stdout.lines().count(), 16);
}

#[test]
fn bad_orbit_flags_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (data, model) = tiny_model(dir.path());
    let out = dir.path().join("refused");
    let gif_path = dir.path().join("refused.gif");
    let cases: [(&[&str], &str); 10] = [
        (&["--orbit", "0"], "zero frames"),
        (&["--orbit", "3", "--radius", "0"], "--radius"),
        (&["--orbit", "3", "--radius", "-2"], "--radius"),
        (&["--orbit", "3", "--elevation", "90"], "--elevation"),
        (&["--orbit", "3", "--elevation", "-95"], "--elevation"),
        (&["--orbit", "3", "--size", "0x20"], "--size 0x20"),
        (&["--orbit", "3", "--width", "0"], "--width"),
        (&["--orbit", "3", "--height", "0"], "--height"),
        (&["--orbit", "3", "--fov", "180"], "--fov"),
        (
            &["--orbit", "3", "--size", "70000x10", "--gif", arg(&gif_path)],
            "65535",
        ),
    ];
    for (flags, names) in cases {
        let mut args = vec!["render", "--model", arg(&model), "--out", arg(&out)];
        args.extend_from_slice(flags);
        assert_refused(&fogray(&args), names, &format!("{flags:?}"));
        assert!(!out.exists(), "{flags:?} made {}", out.display());
        assert!(!gif_path.exists(), "{flags:?} made {}", gif_path.display());
    }

    // A file that is not a model, named.
    let not_a_model = dir.path().join("not-a-model.safetensors");
    std::fs::write(&not_a_model, "{\"frames\": []}").unwrap();
    let run = fogray(&[
        "render",
        "--model",
        arg(&not_a_model),
        "--orbit",
        "3",
        "--out",
        arg(&out),
    ]);
    assert_refused(&run, "not-a-model.safetensors", "not a model");

    // --orbit and --cameras together, or neither, or orbit flags without --orbit: usage
    // errors (clap's, folded to one line), status 2.
    let usage: [&[&str]; 5] = [
        &["--orbit", "3", "--cameras", arg(&data)],
        &[],
        &["--cameras", arg(&data), "--elevation", "10"],
        &["--cameras", arg(&data), "--gif", arg(&gif_path)],
        &["--orbit", "3", "--downscale", "2"],
    ];
    for flags in usage {
        let mut args = vec!["render", "--model", arg(&model), "--out", arg(&out)];
        args.extend_from_slice(flags);
        let run = fogray(&args);
        assert_eq!(run.code, 2, "{flags:?}: {}", run.stderr);
        assert!(run.stdout.is_empty() && !run.stderr.contains("panicked"), "{flags:?}");
    }
    assert!(!out.exists());
}
