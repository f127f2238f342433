//! `fogray fit --view`: the page served while a fit trains and after it, its progress checked
//! against the fit's own `--json` output, its final frames against `fogray render` of the
//! saved model; Ctrl-C during the fit still saves it; a port in use fails before the fit.
#![cfg(unix)]

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{ChildStdout, Command, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::common::{arg, assert_refused, cameras, fogray, intrinsics, write_ball, LENS};
use crate::view::{decode, look_at, rendered, worst, Server};

/// A running `fogray fit --view`: its page, its stdout, and its stderr as read to the end.
struct LiveFit {
    server: Server,
    stdout: BufReader<ChildStdout>,
    stderr: JoinHandle<String>,
}

/// Starts `fogray fit --data DIR/ball --save-model DIR/model.safetensors --view --view-port 0
/// --json` with `flags` and waits for the page's address on stderr.
fn start(dir: &Path, flags: &[&str]) -> LiveFit {
    let data = dir.join("ball");
    write_ball(&data, &cameras(8, intrinsics(16), LENS));
    let model = dir.join("model.safetensors");
    let mut child = Command::new(env!("CARGO_BIN_EXE_fogray"))
        .args(["fit", "--data", arg(&data), "--save-model", arg(&model)])
        .args([
            "--view",
            "--view-port",
            "0",
            "--json",
            "--grid",
            "8",
            "--batch",
            "64",
            "--space",
            "box",
        ])
        .args(flags)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut seen = String::new();
    let port = loop {
        let mut line = String::new();
        assert!(
            stderr.read_line(&mut line).unwrap() > 0,
            "no address on stderr: {seen:?}"
        );
        seen += &line;
        if let Some(rest) = line
            .trim()
            .strip_prefix("fogray fit: the fit's page: http://127.0.0.1:")
        {
            break rest.trim_end_matches('/').parse::<u16>().unwrap();
        }
    };
    let rest = std::thread::spawn(move || {
        let mut text = seen;
        let _ = stderr.read_to_string(&mut text);
        text
    });
    LiveFit {
        stdout: BufReader::new(child.stdout.take().unwrap()),
        server: Server { child, port },
        stderr: rest,
    }
}

impl LiveFit {
    /// `/progress`, parsed.
    fn progress(&self) -> Value {
        let (status, body) = self.server.get("/progress");
        assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
        serde_json::from_slice(&body).unwrap()
    }

    /// Polls `/progress` until `done(progress)` (a guard against a hung fit, not a timing).
    fn wait_for(&self, done: impl Fn(&Value) -> bool) -> Value {
        let start = Instant::now();
        loop {
            let progress = self.progress();
            if done(&progress) {
                return progress;
            }
            assert!(start.elapsed() < Duration::from_secs(120), "never reached: {progress}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Sends SIGINT; the exit status and stderr.
    fn interrupt(mut self) -> (i32, String) {
        let pid = self.server.child.id().to_string();
        assert!(Command::new("kill").args(["-INT", &pid]).status().unwrap().success());
        let start = Instant::now();
        let code = loop {
            if let Some(s) = self.server.child.try_wait().unwrap() {
                break s.code().unwrap_or(-1);
            }
            assert!(start.elapsed() < Duration::from_secs(60), "fogray fit ignored SIGINT");
            std::thread::sleep(Duration::from_millis(20));
        };
        (code, self.stderr.join().unwrap())
    }
}

#[test]
fn the_page_shows_the_fits_progress_and_then_its_saved_model() {
    let dir = tempfile::tempdir().unwrap();
    let mut fit = start(dir.path(), &["--steps", "12", "--evaluations", "3"]);
    let (status, info) = fit.server.get("/info");
    assert_eq!(status, 200);
    let info: Value = serde_json::from_slice(&info).unwrap();
    assert_eq!(info["live"], true, "{info}");
    assert_eq!(info["space"], "box", "{info}");
    assert_eq!(info["views"].as_array().map(Vec::len), Some(8), "{info}");
    let progress = fit.wait_for(|p| p["done"] == true);
    // The fit's own summary, printed when it ended (the page serves on).
    let mut line = String::new();
    fit.stdout.read_line(&mut line).unwrap();
    let summary: Value = serde_json::from_str(&line).unwrap();
    assert_eq!(summary["steps"], 12, "{summary}");
    assert_eq!(progress["step"], 12, "{progress}");
    assert_eq!(progress["model_step"], 12, "{progress}");
    assert_eq!(progress["fraction"], 1.0, "{progress}");
    assert_eq!(progress["interrupted"], false, "{progress}");
    // The curve is the fit's log, entry for entry: the evaluations at steps 0, 4, 8 and 12.
    assert_eq!(progress["log"], summary["log"], "{progress} against {summary}");
    let steps: Vec<u64> = progress["log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, [0, 4, 8, 12]);

    // The final model's frame is `fogray render`'s of the saved file.
    let (camera, query) = look_at([2.5, -1.0, 1.2], 35.0, [24, 18]);
    let (status, png) = fit.server.get(&format!("/frame?{query}"));
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&png));
    let served = decode(&png);
    let reference = rendered(dir.path(), &dir.path().join("model.safetensors"), &camera);
    assert!(worst(&served, &reference) <= 1, "{}", worst(&served, &reference));
    // Above the live size, once the fit is over: as `fogray view` serves it.
    let (big, query) = look_at([2.5, -1.0, 1.2], 35.0, [500, 400]);
    let (status, png) = fit.server.get(&format!("/frame?{query}"));
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&png));
    assert!(
        worst(
            &decode(&png),
            &rendered(dir.path(), &dir.path().join("model.safetensors"), &big)
        ) <= 1
    );

    // The refusals of `fogray view`.
    for (target, want) in [
        ("/frame?eye=NaN,1,1&target=0,0,0&up=0,0,1&fov=40&w=8&h=8", 400),
        ("/frame?eye=3,0,0&target=0,0,0&up=0,0,1&fov=40&w=4096&h=4096", 400),
        ("/%2e%2e/%2e%2e/etc/passwd", 404),
        ("/photo?view=../../etc/passwd", 404),
    ] {
        let (status, body) = fit.server.get(target);
        assert_eq!(status, want, "{target}: {}", String::from_utf8_lossy(&body));
    }
    assert_eq!(
        fit.server.raw(b"GET /progress HTTP/1.1\r\nHost: example.com\r\n\r\n").0,
        421
    );

    let (code, stderr) = fit.interrupt();
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("its page shows the final model until Ctrl-C"),
        "{stderr}"
    );
}

#[test]
fn ctrl_c_while_the_page_is_open_stops_and_saves_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    // A budget far beyond the test: Ctrl-C ends it.
    let fit = start(dir.path(), &["--steps", "100000000"]);
    fit.wait_for(|p| p["step"].as_u64().unwrap() >= 2);
    // A frame while it trains: from a copy of the model the fit hands over.
    let (_, query) = look_at([2.5, -1.0, 1.2], 35.0, [24, 18]);
    let (status, png) = fit.server.get(&format!("/frame?{query}"));
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&png));
    assert_eq!(decode(&png).dim(), (18, 24, 3));
    let progress = fit.progress();
    let copied = progress["model_step"].as_u64().unwrap();
    assert!(
        copied >= 2 && copied <= progress["step"].as_u64().unwrap(),
        "{progress}"
    );
    assert_eq!(progress["done"], false, "{progress}");
    // Larger than frames are while it trains: refused, for now.
    let (_, query) = look_at([2.5, -1.0, 1.2], 35.0, [500, 400]);
    let (status, body) = fit.server.get(&format!("/frame?{query}"));
    let body = String::from_utf8(body).unwrap();
    assert_eq!(status, 503, "{body}");
    assert!(body.contains("while the fit trains"), "{body}");

    let (code, stderr) = fit.interrupt();
    assert_eq!(code, 130, "{stderr}");
    assert!(stderr.contains("interrupted: the fit is saved to"), "{stderr}");
    assert!(dir.path().join("model.safetensors").exists(), "{stderr}");
}

#[test]
fn a_port_in_use_and_bad_combinations_fail_before_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("ball");
    write_ball(&data, &cameras(8, intrinsics(8), LENS));
    let model = dir.path().join("model.safetensors");
    let taken = std::net::TcpListener::bind(("127.0.0.1", 0)).unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let base = [
        "fit",
        "--data",
        arg(&data),
        "--save-model",
        arg(&model),
        "--steps",
        "2",
        "--json",
    ];
    let cases: [(&[&str], &str); 3] = [
        (&["--view", "--view-port", &port], "--view-port"),
        (&["--view-port", "8080"], "--view"),
        (&["--view", "--model", "splats"], "--view"),
    ];
    for (flags, says) in cases {
        let run = fogray(&[&base[..], flags].concat());
        assert_refused(&run, says, &format!("{flags:?}"));
        assert!(!model.exists(), "{flags:?}: a model was fitted");
    }
}
