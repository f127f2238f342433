//! `fogray view`: the server started on a port the system chooses, its routes asked over a
//! plain TCP connection, its frames compared with `fogray render`'s PNGs of the same cameras,
//! its refusals (bad cameras, sizes, paths, heads), Ctrl-C; and the page in headless Chromium,
//! dragged, where Chromium is installed.
#![cfg(unix)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fogray_data::write_instant_ngp;
use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::Array3;
use serde_json::Value;

use crate::common::{arg, assert_refused, cameras, fogray, intrinsics, render_cameras, write_ball, LENS, TINY_FIT};

/// A running `fogray view`, stopped (SIGINT) when dropped.
pub(crate) struct Server {
    pub(crate) child: Child,
    pub(crate) port: u16,
}

impl Server {
    /// Starts `fogray view --model model --port 0` and waits for the address it prints.
    fn start(model: &Path) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_fogray"))
            .args(["view", "--model", arg(model), "--port", "0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let port = line
            .trim()
            .strip_prefix("fogray view: http://127.0.0.1:")
            .and_then(|rest| rest.strip_suffix('/'))
            .and_then(|p| p.parse().ok())
            .unwrap_or_else(|| panic!("no address in {line:?}"));
        Server { child, port }
    }

    fn url(&self, path: &str) -> String {
        format!("http://127.0.0.1:{}{path}", self.port)
    }

    /// Sends `raw` (a whole request) and returns the status and body.
    pub(crate) fn raw(&self, raw: &[u8]) -> (u16, Vec<u8>) {
        let mut stream = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
        // The server may answer and close before a long request is all sent.
        let _ = stream.write_all(raw);
        let mut response = Vec::new();
        let _ = stream.read_to_end(&mut response);
        let split = response
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .unwrap_or_else(|| panic!("no head in {:?}", String::from_utf8_lossy(&response)));
        let head = String::from_utf8_lossy(&response[..split]).to_string();
        let status = head.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap();
        (status, response[split + 4..].to_vec())
    }

    /// `GET target` (sent as written: no client normalises it).
    pub(crate) fn get(&self, target: &str) -> (u16, Vec<u8>) {
        let request = format!(
            "GET {target} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nConnection: close\r\n\r\n",
            self.port
        );
        self.raw(request.as_bytes())
    }

    /// Sends SIGINT and returns the exit status and stderr.
    fn interrupt(mut self) -> (i32, String) {
        let status = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let start = Instant::now();
        let code = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s.code().unwrap_or(-1);
            }
            assert!(start.elapsed() < Duration::from_secs(30), "fogray view ignored SIGINT");
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut stderr = String::new();
        self.child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
        (code, stderr)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A fit of the ball saved in `dir` with `flags` (the budget and lattice among them).
fn fit_model(dir: &Path, name: &str, flags: &[&str]) -> PathBuf {
    let data = dir.join("ball");
    if !data.exists() {
        write_ball(&data, &cameras(8, intrinsics(16), LENS));
    }
    let model = dir.join(format!("{name}.safetensors"));
    let mut args = vec!["fit", "--data", arg(&data), "--save-model", arg(&model)];
    args.extend(flags);
    let run = fogray(&args);
    assert_eq!(run.code, 0, "{}", run.stderr);
    model
}

/// An 8-bit RGB PNG as `[row][column][channel]`.
pub(crate) fn decode(png: &[u8]) -> Array3<u8> {
    let image = image::load_from_memory(png).unwrap().to_rgb8();
    let (w, h) = image.dimensions();
    Array3::from_shape_vec((h as usize, w as usize, 3), image.into_raw()).unwrap()
}

/// The largest difference between two pictures of one size, in 8-bit levels.
pub(crate) fn worst(a: &Array3<u8>, b: &Array3<u8>) -> u8 {
    assert_eq!(a.dim(), b.dim());
    a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max().unwrap_or(0)
}

/// `fogray render`'s frame of `camera` from `model` (written as a one-frame transforms file).
pub(crate) fn rendered(dir: &Path, model: &Path, camera: &PinholeCamera) -> Array3<u8> {
    let k = camera.intrinsics();
    let photo = Array3::from_elem((k.height, k.width, 3), 0.5);
    let transforms = write_instant_ngp(&dir.join("cameras"), &[("probe", camera, &photo)]).unwrap();
    let out = dir.join("renders");
    let run = render_cameras(model, &transforms, &out, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    decode(&std::fs::read(out.join("probe.png")).unwrap())
}

/// The look-at camera of a frame query's numbers.
pub(crate) fn look_at(eye: [f64; 3], fov: f64, [w, h]: [usize; 2]) -> (PinholeCamera, String) {
    let k = Intrinsics::from_vertical_fov(w, h, fov.to_radians()).unwrap();
    let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let list = |v: [f64; 3]| v.map(|x| x.to_string()).join(",");
    let query = format!("eye={}&target=0,0,0&up=0,0,1&fov={fov}&w={w}&h={h}", list(eye));
    (camera, query)
}

/// Checks a model's routes and that its frames are `fogray render`'s, to 8-bit rounding.
fn check_model(dir: &Path, model: &Path, space: &str) {
    let server = Server::start(model);
    let (status, page) = server.get("/");
    let page = String::from_utf8(page).unwrap();
    assert_eq!(status, 200);
    assert!(page.contains("<canvas") && page.contains("fogray view"), "{page}");

    let (status, info) = server.get("/info");
    assert_eq!(status, 200);
    let info: Value = serde_json::from_slice(&info).unwrap();
    assert_eq!(info["space"], space, "{info}");
    let c = &info["camera"];
    for key in ["eye", "target", "up"] {
        assert_eq!(c[key].as_array().map(Vec::len), Some(3), "{info}");
    }
    // The checkpoint names its dataset: its eight cameras are offered.
    assert_eq!(info["views"].as_array().map(Vec::len), Some(8), "{info}");
    if space == "box" {
        assert!(info["bounds"]["min"].is_array(), "{info}");
    } else {
        assert!(info["framing"]["radius"].as_f64().unwrap() > 0.0, "{info}");
    }
    // The first camera's frame is served.
    let first = format!(
        "/frame?eye={}&target={}&up={}&fov={}&w=8&h=6",
        c["eye"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(","),
        c["target"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(","),
        c["up"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(","),
        c["fov"]
    );
    let (status, png) = server.get(&first);
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&png));
    assert_eq!(decode(&png).dim(), (6, 8, 3));

    // A camera of the request's own, as look-at numbers and as a matrix, beside fogray render's
    // frame of the same camera.
    let (camera, query) = look_at([2.5, -1.0, 1.2], 35.0, [24, 18]);
    let (status, png) = server.get(&format!("/frame?{query}"));
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&png));
    let served = decode(&png);
    let reference = rendered(dir, model, &camera);
    assert!(worst(&served, &reference) <= 1, "{}", worst(&served, &reference));
    let m = camera.camera_to_world();
    let c2w: Vec<String> = m[..3].iter().flatten().map(|v| v.to_string()).collect();
    let (status, png) = server.get(&format!("/frame?c2w={}&fov=35&w=24&h=18", c2w.join(",")));
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&png));
    assert!(worst(&decode(&png), &reference) <= 1);
    // A dataset view, as it is.
    let (status, png) = server.get("/frame?view=3");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&png));
    assert_eq!(decode(&png).dim(), (16, 16, 3));
    // Its photograph, the dataset's file as it is.
    assert_eq!(info["views"][3]["photo"], true, "{info}");
    let (status, photo) = server.get("/photo?view=3");
    assert_eq!(status, 200);
    assert_eq!(photo, std::fs::read(dir.join("ball/images/view_03.png")).unwrap());

    let (code, stderr) = server.interrupt();
    assert_eq!(code, 130, "{stderr}");
    assert!(stderr.contains("fogray view: stopped"), "{stderr}");
}

#[test]
fn frames_are_fogray_renders_for_each_kind_of_model() {
    let dir = tempfile::tempdir().unwrap();
    let sparse = fit_model(
        dir.path(),
        "sparse",
        &[&TINY_FIT[..], &["--model", "sparse", "--space", "box"]].concat(),
    );
    check_model(dir.path(), &sparse, "box");
    let flags = ["--model", "dense", "--precision", "f64", "--space", "contracted"];
    let dense = fit_model(dir.path(), "dense", &[&TINY_FIT[..], &flags].concat());
    check_model(dir.path(), &dense, "contracted");
}

#[test]
fn bad_requests_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let model = fit_model(dir.path(), "sparse", &[&TINY_FIT[..], &["--space", "box"]].concat());
    let server = Server::start(&model);
    let good = "target=0,0,0&up=0,0,1&fov=40&w=8&h=8";
    let cases = [
        (format!("/frame?eye=NaN,1,1&{good}"), 400, "eye: not finite"),
        (format!("/frame?eye=1,1&{good}"), 400, "eye: 2 numbers, expected 3"),
        (format!("/frame?eye=1,1,1,1&{good}"), 400, "expected 3"),
        (format!("/frame?eye=inf,1,1&{good}"), 400, "not finite"),
        (format!("/frame?{good}"), 400, "eye is missing"),
        (
            "/frame?eye=0,0,3&target=0,0,0&up=0,0,1&fov=40&w=8&h=8".into(),
            400,
            "camera:",
        ),
        (
            "/frame?eye=3,0,0&target=0,0,0&up=0,0,1&fov=40&w=4096&h=4096".into(),
            400,
            "w 4096",
        ),
        (
            "/frame?eye=3,0,0&target=0,0,0&up=0,0,1&fov=40&w=8&h=99999999999999999999".into(),
            400,
            "h 9999",
        ),
        (
            "/frame?eye=3,0,0&target=0,0,0&up=0,0,1&fov=40&w=0&h=8".into(),
            400,
            "w 0",
        ),
        (
            "/frame?eye=3,0,0&target=0,0,0&up=0,0,1&fov=0&w=8&h=8".into(),
            400,
            "fov 0",
        ),
        (
            "/frame?c2w=1,0,0,3,0,1,0,0,0,0.5,1,0&fov=40&w=8&h=8".into(),
            400,
            "not orthonormal",
        ),
        (
            "/frame?c2w=1,0,0,3&fov=40&w=8&h=8".into(),
            400,
            "c2w: 4 numbers, expected 12",
        ),
        ("/frame?view=8".into(), 400, "the model's dataset has 8 cameras"),
        ("/frame?view=-1".into(), 400, "view -1"),
        ("/../../etc/passwd".into(), 404, "no such page"),
        ("/%2e%2e/%2e%2e/etc/passwd".into(), 404, "no such page"),
        ("/..%2f..%2fetc%2fpasswd".into(), 404, "no such page"),
        ("/frame/../info".into(), 404, "no such page"),
        ("/nothing".into(), 404, "no such page"),
        ("/progress".into(), 404, "no fit under way"),
        ("/photo?view=../../etc/passwd".into(), 404, "8 photographs are offered"),
        ("/photo?view=8".into(), 404, "8 photographs are offered"),
        ("/photo?file=/etc/passwd".into(), 400, "view=N alone"),
        ("/photo?view=1&file=/etc/passwd".into(), 400, "view=N alone"),
    ];
    for (target, want, says) in cases {
        let (status, body) = server.get(&target);
        let body = String::from_utf8(body).unwrap();
        assert_eq!(status, want, "{target}: {body}");
        assert!(body.contains(says), "{target}: {body:?} does not say {says:?}");
        assert_eq!(body.lines().count(), 1, "{target}: {body:?}");
    }
    // A head larger than the server reads, another method, a foreign Host.
    let long = format!(
        "GET /info?{} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\n\r\n",
        "a".repeat(20_000),
        server.port
    );
    assert_eq!(server.raw(long.as_bytes()).0, 431);
    let post = format!("POST /info HTTP/1.1\r\nHost: 127.0.0.1:{}\r\n\r\n", server.port);
    assert_eq!(server.raw(post.as_bytes()).0, 405);
    assert_eq!(server.raw(b"GET /info HTTP/1.1\r\nHost: example.com\r\n\r\n").0, 421);
    assert_eq!(server.raw(b"\x16\x03\x01 not http\r\n\r\n").0, 400);
    // Still serving after all of it.
    assert_eq!(server.get("/info").0, 200);
    let (code, stderr) = server.interrupt();
    assert_eq!(code, 130, "{stderr}");
}

/// Chromium's command, where it is installed.
fn chromium() -> Option<&'static str> {
    ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|name| {
            Command::new(name)
                .arg("--version")
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        })
}

/// Runs headless Chromium on `url` with `output` (`--dump-dom` or `--screenshot=FILE`), giving
/// the page's scripts and fetches up to `budget_ms` of virtual time; its stdout.
fn headless(browser: &str, profile: &Path, url: &str, output: &str, budget_ms: u32) -> String {
    let out = Command::new(browser)
        .args([
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            "--window-size=900,600",
            "--no-first-run",
            &format!("--user-data-dir={}", profile.display()),
            &format!("--virtual-time-budget={budget_ms}"),
            output,
            url,
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// The frame query the page reports when ready (`data-frame` on its body), or `None`.
fn ready_frame(dom: &str) -> Option<String> {
    let start = dom.find("data-frame=\"")? + "data-frame=\"".len();
    let end = start + dom[start..].find('"')?;
    Some(dom[start..end].replace("&amp;", "&"))
}

/// Chromium's virtual time for the page: it runs far ahead of the clock while a frame is
/// awaited (on a machine busy with other tests, a frame can take thousands of virtual
/// seconds: an hour's budget once ran out before the page was ready), and once the page is
/// still (no timer, no fetch) the rest passes at once, so a generous budget costs nothing.
const BUDGET_MS: u32 = 100_000_000;

/// Takes a screenshot of the page at `query` (after its drag, if any) and returns it with the
/// frame query the page showed last.
fn screenshot(browser: &str, dir: &Path, server: &Server, query: &str, name: &str) -> (Array3<u8>, String) {
    let url = server.url(&format!("/?{query}"));
    let dom = headless(browser, &dir.join(format!("{name}-dom")), &url, "--dump-dom", BUDGET_MS);
    let frame = ready_frame(&dom).unwrap_or_else(|| panic!("the page never got ready: {dom}"));
    let file = dir.join(format!("{name}.png"));
    let shot = format!("--screenshot={}", file.display());
    headless(browser, &dir.join(format!("{name}-shot")), &url, &shot, BUDGET_MS);
    (decode(&std::fs::read(&file).unwrap()), frame)
}

/// The picture at the top-left corner of `shot`, `h x w`.
fn corner(shot: &Array3<u8>, [w, h]: [usize; 2]) -> Array3<u8> {
    shot.slice(ndarray::s![..h, ..w, ..]).to_owned()
}

#[test]
fn a_drag_in_the_browser_moves_the_camera_and_shows_the_served_frame() {
    let Some(browser) = chromium() else {
        eprintln!("skipped: no chromium on PATH (apt-get install chromium)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // Enough steps for the ball to show; orbited about a point beside its centre, so that a
    // drag moves it across the frame.
    let flags = [
        "--steps", "60", "--grid", "12", "--batch", "512", "--space", "box", "--json",
    ];
    let model = fit_model(dir.path(), "sparse", &flags);
    let server = Server::start(&model);
    let size = [48, 40];
    let camera = format!(
        "eye=3,-1,1.5&target=0.4,0.3,0&up=0,0,1&fov=40&w={}&h={}",
        size[0], size[1]
    );
    let (before, first) = screenshot(browser, dir.path(), &server, &camera, "before");
    let (after, last) = screenshot(browser, dir.path(), &server, &format!("{camera}&drag=40,-15"), "after");
    assert_eq!(first, camera, "the page's first frame is the camera of its address");
    assert_ne!(last, first, "the drag did not move the camera");
    for (shot, query) in [(&before, &first), (&after, &last)] {
        let (status, png) = server.get(&format!("/frame?{query}"));
        assert_eq!(status, 200);
        let served = decode(&png);
        let shown = corner(shot, size);
        assert_eq!(
            worst(&shown, &served),
            0,
            "the screenshot's frame is not the served one"
        );
    }
    assert!(
        worst(&corner(&before, size), &corner(&after, size)) > 10,
        "the picture did not change"
    );
}

#[test]
fn refusals_before_serving_are_one_line() {
    for (args, says) in [
        (&["view", "--port", "70000"][..], "70000"),
        (&["view"][..], "--model"),
        (
            &["view", "--model", "no-such-model.safetensors"][..],
            "no-such-model.safetensors",
        ),
    ] {
        let run = fogray(args);
        assert_refused(&run, says, &format!("{args:?}"));
        assert!(run.stderr.starts_with("fogray view: error: "), "{}", run.stderr);
    }
    // A port another program holds.
    let dir = tempfile::tempdir().unwrap();
    let model = fit_model(dir.path(), "sparse", &[&TINY_FIT[..], &["--space", "box"]].concat());
    let taken = std::net::TcpListener::bind(("127.0.0.1", 0)).unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let run = fogray(&["view", "--model", arg(&model), "--port", &port]);
    assert_refused(&run, &format!("--port {port}"), "a taken port");
}
