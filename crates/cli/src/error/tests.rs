//! Each typed refusal of the command line prints the one line it printed as text before (the
//! integration tests and the docs quote them): checked against the line written out by hand.

use std::io;
use std::path::PathBuf;

use fogray_ops::Intrinsics;

use super::{CliError, InputError};

#[test]
fn each_refusal_reads_as_written_by_hand() {
    let model = || PathBuf::from("m.safetensors");
    let gif = || PathBuf::from("o.gif");
    let failed = || io::Error::other("disk full");
    let fov = Intrinsics::from_vertical_fov(4, 3, 0.0).unwrap_err();
    let cases: Vec<(CliError, &str)> = vec![
        (
            CliError::Flag {
                flag: "--opacity",
                value: Some("1.5".into()),
                rule: "must be in (0, 1)".into(),
            },
            "--opacity 1.5: must be in (0, 1)",
        ),
        (
            CliError::Flag {
                flag: "--projections",
                value: None,
                rule: "must be at least 1".into(),
            },
            "--projections must be at least 1",
        ),
        (
            CliError::FlagOp {
                flag: "--fov",
                source: fov,
            },
            "--fov: rays: vertical field of view is 0 (must be in (0, pi) radians)",
        ),
        (
            CliError::FlagsExclude {
                first: "--level",
                second: "--opacity",
                why: "the surface's level is one or the other",
            },
            "--level and --opacity both given: the surface's level is one or the other",
        ),
        (
            CliError::MissingFlag {
                give: "--data PATH, or --resume FILE",
            },
            "give --data PATH, or --resume FILE",
        ),
        (
            CliError::UnknownModelKind {
                path: model(),
                kind: "splats".into(),
                command: "fogray render",
            },
            "m.safetensors: a \"splats\" model, which fogray render does not know",
        ),
        (
            CliError::NoSavedEntry {
                path: model(),
                key: "downscale",
            },
            "m.safetensors has no saved downscale (it was not written by fogray fit): give --downscale",
        ),
        (
            CliError::SavedEntry {
                path: model(),
                key: "background",
                text: "[1, 2]".into(),
                reason: "two numbers, not three".into(),
            },
            "m.safetensors: its saved background \"[1, 2]\" cannot be read: two numbers, not three",
        ),
        (
            CliError::FrameNameClash {
                path: PathBuf::from("scene"),
                name: "a".into(),
            },
            "scene: two frames' files are named \"a\" (their PNGs would overwrite each other)",
        ),
        (
            CliError::GifTooLarge {
                width: 70000,
                height: 10,
            },
            "--gif: 70000x10 frames, the format holds at most 65535 pixels each way",
        ),
        (
            CliError::GifFrame {
                path: gif(),
                got: (4, 5, 3),
                size: [6, 7],
            },
            "o.gif: a frame of (4, 5, 3), the GIF's are 7x6x3",
        ),
        (
            CliError::Gif {
                path: gif(),
                source: failed().into(),
            },
            "cannot write o.gif: disk full",
        ),
        (
            CliError::Listen {
                flag: "--port",
                port: 8080,
                source: failed(),
            },
            "--port 8080: cannot listen on 127.0.0.1: disk full",
        ),
        (
            CliError::Listen {
                flag: "--view-port",
                port: 8080,
                source: failed(),
            },
            "--view-port 8080: cannot listen on 127.0.0.1: disk full",
        ),
        (
            CliError::FlagsExclude {
                first: "--view",
                second: "--model splats",
                why: "the page shows a grid as it trains (--model dense or sparse)",
            },
            "--view and --model splats both given: the page shows a grid as it trains (--model dense or sparse)",
        ),
        (
            CliError::ListenAddress(failed()),
            "cannot read the address listened on: disk full",
        ),
        (
            CliError::Serve {
                address: ([127, 0, 0, 1], 8080).into(),
                source: failed(),
            },
            "serving 127.0.0.1:8080: disk full",
        ),
        (
            CliError::Report(std::fmt::Error),
            "report.md: an error occurred when formatting an argument",
        ),
        (
            InputError::MinTransmittanceNotFused.into(),
            "min_transmittance is offered by the fused method only (the taped twins are exact)",
        ),
    ];
    for (e, line) in cases {
        assert_eq!(e.to_string(), line, "{e:?}");
    }
}
