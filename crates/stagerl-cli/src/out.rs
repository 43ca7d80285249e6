//! Everything the CLI prints goes through here. A write error (a pipe closed early, a full disk,
//! a closed standard output) is returned as an error, never a panic: `println!` and `eprintln!`
//! are not used.

use anyhow::{bail, Context, Result};
use std::fmt;
use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// Print a formatted line to standard output ([`line`]); evaluates to `anyhow::Result<()>`.
macro_rules! outln {
    ($($arg:tt)*) => { $crate::out::line(format_args!($($arg)*)) };
}

/// Print a formatted line to standard error ([`err_line`]); evaluates to `anyhow::Result<()>`.
macro_rules! errln {
    ($($arg:tt)*) => { $crate::out::err_line(format_args!($($arg)*)) };
}

/// Write one line to standard output and flush it.
pub fn line(args: fmt::Arguments<'_>) -> Result<()> {
    let mut o = io::stdout().lock();
    o.write_fmt(args)
        .and_then(|()| o.write_all(b"\n"))
        .and_then(|()| o.flush())
        .context("writing to standard output")
}

/// Write `text` as it is to standard output and flush it.
pub fn text(text: &str) -> Result<()> {
    let mut o = io::stdout().lock();
    o.write_all(text.as_bytes()).and_then(|()| o.flush()).context("writing to standard output")
}

/// Write one line to standard error, with any long echoed input cut to an excerpt
/// ([`stagerl::base::text::bound_message`]: a 100 MB input line never becomes 100 MB of messages).
/// (A closed standard error is not reported: there is nowhere to report it; the exit code still
/// tells.)
pub fn err_line(args: fmt::Arguments<'_>) -> Result<()> {
    let text = stagerl::base::text::bound_message(&args.to_string());
    let mut e = io::stderr().lock();
    e.write_all(text.as_bytes())
        .and_then(|()| e.write_all(b"\n"))
        .and_then(|()| e.flush())
        .context("writing to standard error")
}

/// Standard output for a command whose product is its output (`fk`, `reward`): buffered (flush
/// it and check the result), and an error if the process was started with standard output
/// closed, where every write would vanish into the `/dev/null` the runtime put in its place.
/// (Other commands write their results to files and accept it.)
pub fn stdout() -> Result<io::BufWriter<io::StdoutLock<'static>>> {
    ensure_stdout_open()?;
    Ok(io::BufWriter::new(io::stdout().lock()))
}

/// An error if the process was started with its standard output closed.
fn ensure_stdout_open() -> Result<()> {
    static CLOSED: OnceLock<bool> = OnceLock::new();
    if *CLOSED.get_or_init(stdout_was_closed) {
        bail!("standard output is closed (to discard the output, redirect it with `> /dev/null`)");
    }
    Ok(())
}

/// Whether standard output was closed when the process started. The Rust runtime reopens a
/// closed standard stream as `/dev/null` in read-write mode before `main`, and writes to it then
/// succeed silently; a shell's `> /dev/null` opens it write-only. (A parent that opens
/// `/dev/null` read-write itself, as Python's `subprocess.DEVNULL` does, looks the same.) Linux
/// only (elsewhere: false).
fn stdout_was_closed() -> bool {
    if !cfg!(target_os = "linux") {
        return false;
    }
    let is_null = std::fs::read_link("/proc/self/fd/1").is_ok_and(|p| p == std::path::Path::new("/dev/null"));
    let read_write = std::fs::read_to_string("/proc/self/fdinfo/1").ok().is_some_and(|info| {
        info.lines()
            .find_map(|l| l.strip_prefix("flags:"))
            .and_then(|f| u32::from_str_radix(f.trim(), 8).ok())
            .is_some_and(|flags| flags & 0o3 == 0o2)
    });
    is_null && read_write
}

/// The output of a long run (training, a sweep): lines are printed until the first write error,
/// which is kept and raises the run's stop flag, so the run saves itself and stops as on SIGINT
/// instead of losing its files.
pub struct RunOutput {
    stop: Arc<AtomicBool>,
    error: Mutex<Option<anyhow::Error>>,
}

impl RunOutput {
    /// Output that raises `stop` on its first write error.
    pub fn new(stop: Arc<AtomicBool>) -> RunOutput {
        RunOutput { stop, error: Mutex::new(None) }
    }

    /// Print a line, unless an earlier one failed.
    pub fn line(&self, args: fmt::Arguments<'_>) {
        let mut error = self.error.lock().unwrap_or_else(|p| p.into_inner());
        if error.is_none() {
            if let Err(e) = line(args) {
                self.stop.store(true, Ordering::SeqCst);
                *error = Some(e);
            }
        }
    }

    /// The first write error, if any.
    pub fn failed(&self) -> Option<String> {
        let error = self.error.lock().unwrap_or_else(|p| p.into_inner());
        error.as_ref().map(|e| format!("{e:#}"))
    }
}
