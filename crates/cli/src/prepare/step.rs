//! One COLMAP step run as a child process: its output copied line by line into
//! `DIR/colmap.log`, its progress shown on stderr (the step, the time since it started, the
//! count it prints), and Ctrl-C answered by killing it.

use std::ffi::OsString;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use fogray_data::shown;
use fogray_fit::interrupt::StopFlag;

use super::colmap::{Step, PROGRAM};
use super::error::PrepareError;
use super::progress::{self, Progress};

/// How often the stop flag is looked at while COLMAP is quiet.
const POLL: Duration = Duration::from_millis(100);

/// `DIR/colmap.log`: every command run and everything it printed.
pub struct Log {
    file: BufWriter<File>,
    path: PathBuf,
}

impl Log {
    /// Creates the log at `path`.
    ///
    /// Errors: [`PrepareError::File`].
    pub fn create(path: &Path) -> Result<Log, PrepareError> {
        let file = File::create_new(path).map_err(PrepareError::file("create", path))?;
        Ok(Log {
            file: BufWriter::new(file),
            path: path.to_path_buf(),
        })
    }

    /// The log's path, as displayed.
    pub fn shown(&self) -> String {
        shown(&self.path).to_string()
    }

    /// Appends `bytes` and a newline.
    fn line(&mut self, bytes: &[u8]) -> Result<(), PrepareError> {
        self.file
            .write_all(bytes)
            .and_then(|()| self.file.write_all(b"\n"))
            .map_err(PrepareError::file("write", &self.path))
    }

    /// Writes what is buffered.
    fn flush(&mut self) -> Result<(), PrepareError> {
        self.file.flush().map_err(PrepareError::file("write", &self.path))
    }
}

/// Where a step stands among the run's steps, for the display (`[2/3]`).
#[derive(Debug, Clone, Copy)]
pub struct Place {
    /// This step, from 1.
    pub number: usize,
    /// How many the run takes.
    pub of: usize,
}

/// Sends each line `pipe` yields to `lines` until it closes.
fn forward(pipe: impl Read + Send + 'static, lines: mpsc::Sender<Vec<u8>>) {
    std::thread::spawn(move || {
        for line in BufReader::new(pipe).split(b'\n') {
            let Ok(mut line) = line else { return };
            if line.last() == Some(&b'\r') {
                line.pop();
            }
            if lines.send(line).is_err() {
                return;
            }
        }
    });
}

/// Whether a child ended by SIGINT (Ctrl-C at a terminal reaches the whole process group).
fn by_sigint(status: ExitStatus) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        status.signal() == Some(2)
    }
    #[cfg(not(unix))]
    {
        let _ = status;
        false
    }
}

/// How a child ended, in words.
fn ended(status: ExitStatus) -> String {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(signal) = status.signal() {
            return format!("killed by signal {signal}");
        }
    }
    match status.code() {
        Some(code) => format!("exit status {code}"),
        None => status.to_string(),
    }
}

/// A spinner on stderr (drawn only on a terminal).
fn spinner(prefix: String) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new_spinner().with_prefix(prefix);
    if let Ok(style) = indicatif::ProgressStyle::with_template("{spinner} {prefix} ({elapsed}) {msg}") {
        bar.set_style(style);
    }
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// Kills `child` (it may be gone already: a terminal's Ctrl-C reaches it too) and waits
/// for it, so that it writes nothing after this returns.
fn stop_child(child: &mut Child) {
    // An error here is a child already reaped or gone: nothing more to stop.
    let _ = child.kill();
    let _ = child.wait();
}

/// Runs `colmap ARGS` for `step`, its output into `log`, until it ends or `stop` is raised.
/// Returns the last count it printed, if any.
///
/// Errors: [`PrepareError::Interrupted`] (`out` names the output folder) when `stop` is
/// raised (COLMAP is killed first); [`PrepareError::StepFailed`] when COLMAP fails;
/// [`PrepareError::CannotRun`], [`PrepareError::NoColmap`], or [`PrepareError::File`] if the
/// log cannot be written (COLMAP is killed first).
pub fn run(
    step: Step,
    args: &[OsString],
    place: Place,
    log: &mut Log,
    stop: &StopFlag,
    out: &Path,
) -> Result<Option<Progress>, PrepareError> {
    let command_line: Vec<String> = std::iter::once(PROGRAM.to_string())
        .chain(args.iter().map(|a| a.to_string_lossy().into_owned()))
        .collect();
    log.line(format!("$ {}", command_line.join(" ")).as_bytes())?;
    log.flush()?;
    let mut child = Command::new(PROGRAM)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => PrepareError::NoColmap,
            _ => PrepareError::CannotRun(e),
        })?;
    let (send, lines) = mpsc::channel();
    if let Some(pipe) = child.stdout.take() {
        forward(pipe, send.clone());
    }
    if let Some(pipe) = child.stderr.take() {
        forward(pipe, send);
    }
    let started = Instant::now();
    let bar = spinner(format!("[{}/{}] {}", place.number, place.of, step.name()));
    let watched = watch(&lines, &bar, step, log, stop);
    bar.finish_and_clear();
    if watched.is_err() || stop.is_raised() {
        stop_child(&mut child);
    }
    let last = watched?;
    let status = child.wait().map_err(PrepareError::CannotRun);
    log.flush()?;
    // Checked after the child ended: a terminal's Ctrl-C kills COLMAP too (its SIGINT may
    // arrive before the flag is raised), which is no failure.
    if stop.is_raised() || status.as_ref().is_ok_and(|s| by_sigint(*s)) {
        return Err(PrepareError::Interrupted {
            step: step.name().to_string(),
            out: shown(out).to_string(),
        });
    }
    let status = status?;
    if !status.success() {
        return Err(PrepareError::StepFailed {
            step: step.name().to_string(),
            status: ended(status),
            log: log.shown(),
        });
    }
    // The mapper's last count is a try, not a result: the summary reads the model instead.
    let counted = match last {
        Some(p @ Progress::Of { .. }) => format!(", {}", progress::describe(p, blocks(step))),
        _ => String::new(),
    };
    eprintln!(
        "[{}/{}] {}: done in {:.0} s{counted}",
        place.number,
        place.of,
        step.name(),
        started.elapsed().as_secs_f64()
    );
    Ok(last)
}

/// Whether `step` counts blocks of pairs rather than photographs.
fn blocks(step: Step) -> bool {
    step == Step::Matching(super::Matching::Exhaustive)
}

/// Copies `lines` into `log` and their counts onto `bar` until both pipes close or `stop` is
/// raised; returns the last count.
fn watch(
    lines: &Receiver<Vec<u8>>,
    bar: &indicatif::ProgressBar,
    step: Step,
    log: &mut Log,
    stop: &StopFlag,
) -> Result<Option<Progress>, PrepareError> {
    let mut last = None;
    loop {
        if stop.is_raised() {
            return Ok(last);
        }
        match lines.recv_timeout(POLL) {
            Ok(line) => {
                log.line(&line)?;
                if let Some(p) = progress::parse(&String::from_utf8_lossy(&line)) {
                    bar.set_message(progress::describe(p, blocks(step)));
                    last = Some(p);
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => return Ok(last),
        }
    }
}
