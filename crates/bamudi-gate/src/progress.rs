//! The command line's view of a running calibration: the engine's [`Observer`] events as
//! indicatif progress bars (on a terminal only, never under `CI`), and a stderr logger for the
//! `log` facade (warnings by default; `--verbose` or `RUST_LOG=info|debug` for more).

use bamudi::observe::{Event, Observer, Stage};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Mutex;

/// Progress bars for the stages of a calibration.
#[derive(Debug)]
pub struct Bars {
    enabled: bool,
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    /// Bars drawn on stderr when it is a terminal and `CI` is not set; otherwise silent.
    pub fn new() -> Self {
        let enabled = std::io::stderr().is_terminal() && std::env::var_os("CI").is_none();
        Self {
            enabled,
            bar: Mutex::new(None),
        }
    }

    /// Bars that never draw.
    pub fn hidden() -> Self {
        Self {
            enabled: false,
            bar: Mutex::new(None),
        }
    }

    fn start(&self, stage: Stage, work: u64) {
        let pb = if work > 0 {
            ProgressBar::new(work)
        } else {
            ProgressBar::new_spinner()
        };
        let template = if work > 0 {
            "{msg:28} [{bar:40}] {pos}/{len} ({eta})"
        } else {
            "{msg:28} {spinner} {elapsed}"
        };
        if let Ok(style) = ProgressStyle::with_template(template) {
            pb.set_style(style);
        }
        pb.set_message(stage.label());
        if let Ok(mut b) = self.bar.lock()
            && let Some(old) = b.replace(pb)
        {
            old.finish_and_clear();
        }
    }

    fn with_bar(&self, f: impl FnOnce(&ProgressBar)) {
        if let Ok(b) = self.bar.lock()
            && let Some(pb) = b.as_ref()
        {
            f(pb);
        }
    }
}

impl Default for Bars {
    fn default() -> Self {
        Self::new()
    }
}

impl Observer for Bars {
    fn observe(&self, event: &Event<'_>) {
        if !self.enabled {
            return;
        }
        match event {
            Event::Started { stage, work } => self.start(*stage, *work),
            Event::Advanced { by, .. } => self.with_bar(|pb| pb.inc(*by)),
            Event::Epoch {
                epoch,
                epochs,
                train_loss,
                val_loss,
            } => self.with_bar(|pb| {
                let val = val_loss.map_or(String::new(), |v| format!(", val {v:.4}"));
                pb.set_message(format!("epoch {epoch}/{epochs}: loss {train_loss:.4}{val}"));
            }),
            Event::Finished { .. } => self.with_bar(ProgressBar::finish_and_clear),
            Event::Notice { message, .. } => self.with_bar(|pb| pb.println(*message)),
        }
    }
}

/// A `log` logger that writes `level: target: message` lines to stderr.
struct Stderr;

impl log::Log for Stderr {
    fn enabled(&self, metadata: &log::Metadata<'_>) -> bool {
        metadata.level() <= log::max_level()
    }
    fn log(&self, record: &log::Record<'_>) {
        if self.enabled(record.metadata()) {
            eprintln!(
                "{}: {}: {}",
                record.level().as_str().to_lowercase(),
                record.target(),
                record.args()
            );
        }
    }
    fn flush(&self) {}
}

static LOGGER: Stderr = Stderr;

/// Installs the stderr logger: `info` with `verbose`, else the level of `RUST_LOG`
/// (`error`, `warn`, `info`, `debug`, `trace`), else `warn`.
pub fn init_logging(verbose: bool) {
    let level = if verbose {
        log::LevelFilter::Info
    } else {
        std::env::var("RUST_LOG")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(log::LevelFilter::Warn)
    };
    if log::set_logger(&LOGGER).is_ok() {
        log::set_max_level(level);
    }
}
