//! Advisory locks on run and sweep directories, so that two processes never write one run.
//!
//! A process that writes a run directory (`train`, `train --resume`, `eval`, each run of
//! `reproduce`) first takes the directory's lock: an exclusive `flock` on `DIR/.stagerl.lock`,
//! which holds the holder's pid for the error message of a second process. The kernel releases
//! the lock when the holder ends, however it ends (SIGKILL included), so no stale lock is ever
//! left; the lock file itself stays (deleting it would race with a process opening it). Readers
//! (`report`) take no lock: every file they read is replaced atomically.
//!
//! Taking a run directory's lock also removes the temporary files a killed writer left there
//! ([`crate::io::remove_stale_temps`]): under the lock no live process can be writing them.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::run::dir::RunDir;
use crate::{Error, Result};

/// A held lock on a directory; released on drop (or when the process ends).
#[derive(Debug)]
pub struct DirLock {
    dir: PathBuf,
    _file: File,
}

impl DirLock {
    /// Lock the run directory `dir` (created if needed) without waiting, then remove stale
    /// temporary files from it. Fails with [`Error::Locked`] (naming the holder's pid) when
    /// another process holds it.
    pub fn run(dir: &Path) -> Result<DirLock> {
        let lock = DirLock::take(dir, false)?;
        for d in RunDir::new(dir).written_dirs() {
            crate::io::remove_stale_temps(&d)?;
        }
        Ok(lock)
    }

    /// Lock the sweep directory `dir` (created if needed), waiting for the holder, then remove
    /// stale temporary files of its own files (not of its runs'). For short critical sections
    /// (writing `preset.toml`).
    pub fn sweep(dir: &Path) -> Result<DirLock> {
        let lock = DirLock::take(dir, true)?;
        crate::io::remove_stale_temps(dir)?;
        Ok(lock)
    }

    /// [`Error::Locked`] when another process holds the lock of `dir`, without creating or
    /// changing anything (a directory never locked has no lock file).
    pub fn check_free(dir: &Path) -> Result<()> {
        let path = RunDir::new(dir).lock_file();
        let Ok(mut file) = File::open(&path) else { return Ok(()) };
        match flock(&file, false) {
            Ok(false) => Err(holder_error(dir, &mut file)),
            // Free (the probe's own lock ends with `file`), or not lockable here: let the real
            // attempt report it.
            _ => Ok(()),
        }
    }

    /// The locked directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn take(dir: &Path, wait: bool) -> Result<DirLock> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let path = RunDir::new(dir).lock_file();
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        match flock(&file, wait) {
            Ok(true) => {}
            Ok(false) => return Err(holder_error(dir, &mut file)),
            Err(e) => return Err(Error::io(&path, e)),
        }
        let pid = std::process::id().to_string();
        (|| {
            file.set_len(0)?;
            file.seek(SeekFrom::Start(0))?;
            file.write_all(pid.as_bytes())
        })()
        .map_err(|e| Error::io(&path, e))?;
        Ok(DirLock { dir: dir.to_path_buf(), _file: file })
    }
}

/// The error for a lock held by another process, with the pid it wrote into the lock file.
fn holder_error(dir: &Path, file: &mut File) -> Error {
    let mut text = String::new();
    let _ = file.read_to_string(&mut text);
    let lock_file = RunDir::new(dir).lock_file();
    Error::Locked { dir: dir.to_path_buf(), holder: text.trim().parse().ok(), lock_file }
}

/// Take an exclusive `flock` on `file`: `Ok(false)` when another open file holds it and `wait`
/// is false.
#[cfg(unix)]
fn flock(file: &File, wait: bool) -> std::io::Result<bool> {
    use std::os::unix::io::AsRawFd;
    let op = if wait { libc::LOCK_EX } else { libc::LOCK_EX | libc::LOCK_NB };
    loop {
        // SAFETY: flock on a file descriptor this function borrows for the duration of the call.
        if unsafe { libc::flock(file.as_raw_fd(), op) } == 0 {
            return Ok(true);
        }
        let e = std::io::Error::last_os_error();
        match e.raw_os_error() {
            Some(libc::EINTR) => continue,
            Some(libc::EWOULDBLOCK) => return Ok(false),
            _ => return Err(e),
        }
    }
}

/// Without `flock`, directories are not locked.
#[cfg(not(unix))]
fn flock(_file: &File, _wait: bool) -> std::io::Result<bool> {
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn second_lock_is_refused_with_the_holder_pid_until_the_first_is_dropped() {
        let dir = std::env::temp_dir().join(format!("stagerl-lock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let first = DirLock::run(&dir).unwrap();
        let e = DirLock::run(&dir).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, Error::Locked { holder: Some(p), .. } if p == std::process::id()), "{msg}");
        assert!(msg.contains(&dir.display().to_string()) && msg.contains("pid"), "{msg}");
        assert!(matches!(DirLock::check_free(&dir), Err(Error::Locked { .. })));
        drop(first);
        DirLock::check_free(&dir).unwrap();
        DirLock::check_free(&dir.join("never-locked")).unwrap();
        let again = DirLock::run(&dir).unwrap();
        assert_eq!(again.dir(), dir);
        drop(again);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
