//! What the libraries say through `tracing` (warnings, and with `-v` what runs where), shown
//! on stderr as `warning: …`, `info: …`, `debug: <target>: …`.
//!
//! The level: `-q` errors only, warnings by default, `-v` info, `-vv` debug, `-vvv` trace, for
//! imprint's own crates (the graphics libraries' messages stay off). `IMPRINT_LOG`, when set,
//! replaces the flags with an `EnvFilter` directive string, as `RUST_LOG` is read elsewhere:
//! `IMPRINT_LOG=warn,imprint_graph=debug`, `IMPRINT_LOG=off`, or `IMPRINT_LOG=warn,wgpu_hal=info`
//! for wgpu's own messages too (targets it does not name are off).

use indicatif::ProgressBar;
use std::fmt;
use std::io::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields, MakeWriter};
use tracing_subscriber::registry::LookupSpan;

/// The environment variable that overrides `-v`/`-q`.
pub const ENV: &str = "IMPRINT_LOG";

static QUIET: AtomicBool = AtomicBool::new(false);

/// The progress bar on screen, if any: messages clear it, print, and redraw it.
static BAR: Mutex<Option<ProgressBar>> = Mutex::new(None);

/// Whether `-q` asked for errors only (no notes such as "resuming at frame …" either).
pub fn quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// The filter `-v` (counted) and `-q` ask for: imprint's crates (`imprint`, `imprint_*`) at
/// that level, other crates silent.
fn flags_filter(verbose: u8, quiet: bool) -> EnvFilter {
    let level = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "info",
        (false, 2) => "debug",
        (false, _) => "trace",
    };
    // A target directive matches by prefix: `imprint` covers `imprint_graph::…` too.
    EnvFilter::new(format!("imprint={level}"))
}

/// Installs the subscriber; call once, early in `main` (it starts no thread).
pub fn init(verbose: u8, quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
    let mut bad_env = None;
    let filter = match std::env::var(ENV) {
        Ok(s) if !s.trim().is_empty() => EnvFilter::try_new(&s).unwrap_or_else(|e| {
            bad_env = Some(format!(
                "{ENV}={s:?} is not a filter ({e}); using the flags"
            ));
            flags_filter(verbose, quiet)
        }),
        _ => flags_filter(verbose, quiet),
    };
    // Also takes the `log` crate's records (wgpu's), which the filter then selects by target.
    // Only fails if a subscriber is already set, which `main` does not do.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(false)
        .event_format(Plain)
        .with_writer(Stderr)
        .try_init();
    if let Some(msg) = bad_env {
        tracing::warn!("{msg}");
    }
}

/// Shows `bar` until the returned guard drops; messages logged meanwhile suspend it.
pub fn drawing(bar: &ProgressBar) -> BarGuard {
    *BAR.lock().unwrap_or_else(|p| p.into_inner()) = Some(bar.clone());
    BarGuard
}

pub struct BarGuard;

impl Drop for BarGuard {
    fn drop(&mut self) {
        *BAR.lock().unwrap_or_else(|p| p.into_inner()) = None;
    }
}

/// `warning: message`, as the CLI printed warnings before it logged them; debug and trace
/// lines name their module (`debug: imprint_graph::executor: …`).
struct Plain;

impl<S, N> FormatEvent<S, N> for Plain
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &FmtContext<'_, S, N>,
        mut writer: Writer<'_>,
        event: &Event<'_>,
    ) -> fmt::Result {
        let meta = event.metadata();
        let level = *meta.level();
        let name = match level {
            Level::ERROR => "error",
            Level::WARN => "warning",
            Level::INFO => "info",
            Level::DEBUG => "debug",
            Level::TRACE => "trace",
        };
        write!(writer, "{name}: ")?;
        if level >= Level::DEBUG {
            // (More verbose levels compare greater.)
            write!(writer, "{}: ", meta.target())?;
        }
        ctx.field_format().format_fields(writer.by_ref(), event)?;
        writeln!(writer)
    }
}

/// Standard error, with the progress bar (if one is drawn) cleared around each message.
struct Stderr;

impl<'a> MakeWriter<'a> for Stderr {
    type Writer = Stderr;
    fn make_writer(&'a self) -> Stderr {
        Stderr
    }
}

impl Write for Stderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.write_all(buf)?;
        Ok(buf.len())
    }

    /// One formatted message is one `write_all`, so the bar is cleared once per message.
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        let bar = BAR.lock().unwrap_or_else(|p| p.into_inner()).clone();
        let put = || std::io::stderr().lock().write_all(buf);
        match bar {
            Some(bar) => bar.suspend(put),
            None => put(),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}
