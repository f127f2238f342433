//! `fogray fit --view`: the page of `fogray view` served while a fit trains, showing the model
//! as it stands, the held-out PSNR so far and the step (`GET /progress`), and the final model
//! once the fit ends, until Ctrl-C.
//!
//! The fit's session knows nothing of HTTP: it talks to a [`LiveScene`] through the library's
//! [`LiveSink`] hook. A frame request marks a copy of the model as wanted when the one held is
//! older than [`MODEL_AGE`]; the training thread makes the copy at its next step boundary and
//! hands it over, and frames render from the latest copy on this side. So that the fit keeps
//! its cores, frames while it trains are rendered on one thread of their own, no larger than
//! [`LIVE_MAX_PIXELS`], and each is followed by a pause [`IDLE_PER_BUSY`] times as long as it
//! took: the renders take a bounded share of one core whatever the page asks. Once the fit has
//! ended, frames are rendered as `fogray view` renders them (every core, any size it allows).

use std::collections::BTreeMap;
use std::io::Write;
use std::net::TcpListener;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use fogray_fit::checkpoint::ModelInfo;
use fogray_fit::dataset::Dataset;
use fogray_fit::images::to_u8;
use fogray_fit::interrupt::StopFlag;
use fogray_fit::live::{LiveHook, LiveModel, LiveSink};
use fogray_fit::render::RenderOptions;
use fogray_fit::settings::{FitSettings, Method};
use fogray_fit::train::{LogEntry, Progress};
use fogray_ops::limits::{self, Bytes};
use fogray_ops::PinholeCamera;
use serde_json::json;

use super::server::{RgbFrame, Scene, Site};
use super::{dataset_cameras, dataset_photos, describe, http};
use crate::error::CliError;
use crate::render_memory::render_need;

/// The most pixels a frame may have while the fit trains: a 400x400 page's; the page stretches
/// a smaller frame over a larger canvas.
pub const LIVE_MAX_PIXELS: usize = 400 * 400;

/// How long a frame's render while the fit trains is followed by a pause: this many times its
/// own time, so that the renders take at most a ninth of one core.
pub const IDLE_PER_BUSY: u32 = 8;

/// How old the model copy a frame renders may be before a fresh one is asked of the fit.
pub const MODEL_AGE: Duration = Duration::from_secs(1);

/// How long a frame asked for before the fit's first step waits for its model.
const FIRST_MODEL_WAIT: Duration = Duration::from_secs(10);

/// The page's port, bound before the fit loads anything: a port in use fails at once.
#[derive(Debug)]
pub struct LivePage {
    listener: TcpListener,
}

impl LivePage {
    /// Listens on 127.0.0.1 at `port` (0: one the system chooses).
    ///
    /// Errors: [`CliError::Listen`] naming `--view-port` when the port cannot be bound.
    pub fn bind(port: u16) -> Result<LivePage, CliError> {
        let listener = http::bind(port).map_err(|source| CliError::Listen {
            flag: "--view-port",
            port,
            source,
        })?;
        Ok(LivePage { listener })
    }

    /// Serves the page of the fit of `data` with `settings` (its scene box given; `entries` the
    /// model file's, which name the dataset) while `fit` runs with the hook it is handed; when
    /// `fit` returns `Ok((out, true))`, on until Ctrl-C, then `out` is returned. Ctrl-C during
    /// the fit raises the hook's stop flag (the fit stops and saves, as without the page) and
    /// stops the page. The address goes to stderr once the page serves.
    ///
    /// Errors: the fit's; Ctrl-C that cannot be caught; settings whose space cannot be
    /// decided; the listener's.
    pub fn serve<T>(
        self,
        data: &Dataset,
        settings: &FitSettings,
        entries: &BTreeMap<String, String>,
        fit: impl FnOnce(LiveHook) -> Result<(T, bool), CliError>,
    ) -> Result<T, CliError> {
        // The space the session will decide, so that the page's first camera looks at it.
        let (settings, _) = fogray_fit::space::resolve(settings, data)?;
        let info = ModelInfo {
            settings,
            kind: serde_json::to_value(settings.model)?.as_str().unwrap_or("").to_string(),
            nodes: settings.grid,
            step: 0,
            seconds: 0.0,
            extra: entries.clone(),
        };
        let name = Path::new("the fit");
        let views = dataset_cameras(name, &info);
        let photos = dataset_photos(&info, &views);
        let mut page_info = describe(name, &info, data.background, &views, !photos.is_empty());
        page_info["model"] = json!("the fit under way");
        page_info["live"] = json!(true);
        page_info["limits"]["live_max_pixels"] = json!(LIVE_MAX_PIXELS);
        let scene = Arc::new(LiveScene::new(info, data.background)?);
        let stop = StopFlag::on_ctrl_c()?;
        let site = Site {
            scene: &*scene,
            info: page_info.to_string(),
            views: views.into_iter().map(|(_, c)| c).collect(),
            photos,
            rendering: Mutex::new(()),
        };
        let address = self.listener.local_addr().map_err(CliError::ListenAddress)?;
        let hook = LiveHook {
            sink: scene.clone(),
            stop: stop.clone(),
        };
        eprintln!("fogray fit: the fit's page: http://{address}/");
        let _ = std::io::stderr().flush();
        std::thread::scope(|scope| {
            let server = scope.spawn(|| http::serve(&self.listener, &site, &stop));
            let outcome = fit(hook);
            if !matches!(outcome, Ok((_, true))) {
                stop.raise();
            }
            let served = server.join();
            let (out, _) = outcome?;
            match served {
                Ok(Ok(())) => Ok(out),
                Ok(Err(source)) => Err(CliError::Serve { address, source }),
                Err(_) => Err(CliError::Missing("the page's server thread panicked")),
            }
        })
    }
}

/// What the fit has told the page.
#[derive(Default)]
struct Told {
    step: usize,
    fraction: f64,
    log: Vec<LogEntry>,
    /// The latest copy of the model, and when it came.
    model: Option<(Arc<dyn LiveModel>, Instant)>,
    /// Set when the fit's loop has ended: whether Ctrl-C stopped it.
    ended: Option<bool>,
}

/// The fit as the page sees it: what the session tells it ([`LiveSink`]) and frames rendered
/// from it ([`Scene`]).
pub struct LiveScene {
    /// Whether a fresh copy of the model is wanted (set by a frame, cleared by the copy).
    wanted: AtomicBool,
    told: Mutex<Told>,
    /// Signalled when a copy of the model comes.
    arrived: Condvar,
    /// When the next frame may start rendering while the fit trains.
    next_frame: Mutex<Instant>,
    /// The one thread frames render on while the fit trains.
    pool: rayon::ThreadPool,
    options: RenderOptions,
    /// The fit's settings and size, for a frame's memory check.
    info: ModelInfo,
}

impl LiveScene {
    /// A scene of the fit `info` describes, rendered over `background`.
    ///
    /// Errors: no thread to be had for the renders.
    fn new(info: ModelInfo, background: [f64; 3]) -> Result<LiveScene, CliError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .thread_name(|_| "fogray-live-frame".into())
            .build()
            .map_err(CliError::RenderThread)?;
        Ok(LiveScene {
            wanted: AtomicBool::new(false),
            told: Mutex::new(Told::default()),
            arrived: Condvar::new(),
            next_frame: Mutex::new(Instant::now()),
            pool,
            // As `fogray render` and `fogray view` render a saved model.
            options: RenderOptions {
                background,
                method: Method::Fused,
                depth: false,
            },
            info,
        })
    }

    /// The state, whatever a panicking thread left (it holds plain values).
    fn told(&self) -> MutexGuard<'_, Told> {
        self.told.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The model a frame renders now, and whether the fit has ended; a fresh copy is asked
    /// for when the one held is old, and the first is waited for (a bounded time).
    ///
    /// Errors: [`CliError::NotYet`] when the fit has handed no model in that time.
    fn model(&self) -> Result<(Arc<dyn LiveModel>, bool), CliError> {
        let deadline = Instant::now() + FIRST_MODEL_WAIT;
        let mut told = self.told();
        loop {
            let ended = told.ended.is_some();
            if let Some((model, at)) = &told.model {
                if !ended && at.elapsed() >= MODEL_AGE {
                    self.wanted.store(true, Ordering::Release);
                }
                return Ok((model.clone(), ended));
            }
            if ended {
                return Err(CliError::NotYet("the fit ended without a model to show".into()));
            }
            self.wanted.store(true, Ordering::Release);
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(CliError::NotYet("the fit has not taken its first step yet".into()));
            }
            told = self
                .arrived
                .wait_timeout(told, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

impl LiveSink for LiveScene {
    fn wants_model(&self) -> bool {
        self.wanted.load(Ordering::Acquire)
    }

    fn step(&self, progress: Progress) {
        let mut told = self.told();
        told.step = progress.step;
        told.fraction = progress.fraction;
    }

    fn evaluated(&self, entry: &LogEntry) {
        self.told().log.push(*entry);
    }

    fn model(&self, model: Arc<dyn LiveModel>) {
        self.wanted.store(false, Ordering::Release);
        self.told().model = Some((model, Instant::now()));
        self.arrived.notify_all();
    }

    fn finished(&self, log: &[LogEntry], interrupted: bool) {
        let mut told = self.told();
        told.log = log.to_vec();
        told.ended = Some(interrupted);
        drop(told);
        self.arrived.notify_all();
    }
}

impl Scene for LiveScene {
    fn render(&self, camera: &PinholeCamera) -> Result<RgbFrame, CliError> {
        let k = camera.intrinsics();
        let (width, height) = (k.width, k.height);
        let (model, ended) = self.model()?;
        if !ended && width * height > LIVE_MAX_PIXELS {
            return Err(CliError::NotYet(format!(
                "a {width}x{height} frame: while the fit trains, frames have at most {LIVE_MAX_PIXELS} pixels"
            )));
        }
        Bytes::check(
            render_need(&self.info, 1, [width, height]),
            limits::available(),
            &format!("a {width}x{height} frame"),
            "rendering",
        )?;
        let color = if ended {
            model.render(camera, &self.options)?
        } else {
            // Frames render one at a time (the site's lock); the pause is taken before the
            // next one, so that a frame asked for after a still spell comes at once.
            let mut next = self.next_frame.lock().unwrap_or_else(|e| e.into_inner());
            std::thread::sleep(next.saturating_duration_since(Instant::now()));
            let started = Instant::now();
            let color = self.pool.install(|| model.render(camera, &self.options))?;
            *next = Instant::now() + started.elapsed() * IDLE_PER_BUSY;
            color
        };
        Ok(RgbFrame {
            width,
            height,
            pixels: color.iter().map(|&v| to_u8(v)).collect(),
        })
    }

    fn progress(&self) -> Option<String> {
        let told = self.told();
        let value = json!({
            "step": told.step,
            "fraction": told.fraction,
            "log": told.log,
            "model_step": told.model.as_ref().map(|(m, _)| m.step()),
            "done": told.ended.is_some(),
            "interrupted": told.ended == Some(true),
        });
        Some(value.to_string())
    }
}
