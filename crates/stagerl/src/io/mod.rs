//! What runs read and write, as bytes: file writes that never leave a half-written file behind
//! (here), checkpoints ([`checkpoint`]), the CSV files ([`csv`]), TensorBoard event files
//! ([`tensorboard`]) and the protobuf encoder those and the ONNX export share ([`proto`]).

pub mod checkpoint;
pub mod csv;
pub mod proto;
pub mod tensorboard;

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// The temporary sibling `path` is first written to.
fn temp_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".tmp-{}", std::process::id()));
    path.with_file_name(name)
}

/// Write `bytes` to `path` atomically: into a temporary file beside it, fsync, rename over `path`,
/// then fsync the directory. A reader sees the old file or the new one, never a mix.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_path(path);
    let result = (|| {
        // A file of that name is a dead writer's of the same pid (or a symbolic link someone
        // put there): removed, never written through.
        if let Err(e) = fs::remove_file(&tmp) {
            if e.kind() != std::io::ErrorKind::NotFound {
                return Err(e);
            }
        }
        let mut f = fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)?;
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            // Persist the rename; not every platform lets a directory be opened, so best effort.
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    })();
    result.map_err(|e| {
        let _ = fs::remove_file(&tmp);
        Error::io(path, e)
    })
}

/// What [`write_new`] (or a writer like it) did with a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Written {
    /// A new file.
    New,
    /// The file held these very contents; left as is.
    Unchanged,
    /// The file held other contents and was replaced (`force`).
    Replaced,
}

impl std::fmt::Display for Written {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Written::New => "written",
            Written::Unchanged => "unchanged: the same contents",
            Written::Replaced => "replaced (--force)",
        })
    }
}

/// What a path that is not a regular file is, for messages: `a directory`, `a FIFO (named
/// pipe)`, `a character device`, ...
pub fn file_kind(meta: &fs::Metadata) -> &'static str {
    let t = meta.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

/// Open `path` for reading without blocking on a FIFO that has no writer (the flag is cleared
/// once open: reads of a regular file never block anyway).
fn open_nonblocking(path: &Path) -> std::io::Result<File> {
    let mut o = fs::OpenOptions::new();
    o.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        o.custom_flags(libc::O_NONBLOCK);
    }
    o.open(path)
}

/// The contents of the regular file `path` (`what` names it in errors: "checkpoint",
/// "config"), at most `max_bytes` of them. Its type is looked at before it is opened and again
/// through the open handle: a FIFO, a device (`/dev/zero`), a socket or a directory is refused
/// (never read), and so is a larger file, before anything is allocated for it.
pub fn read_regular(path: &Path, max_bytes: u64, what: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let not_regular = |m: &fs::Metadata| {
        Error::InvalidInput(format!(
            "the {what} {} is {}; a {what} must be a regular file",
            path.display(),
            file_kind(m)
        ))
    };
    let meta = fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let file = open_nonblocking(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let too_large = |size: u64| {
        Error::InvalidInput(format!(
            "the {what} {} holds {size} bytes, more than the {max_bytes} bytes a {what} may hold; refused",
            path.display()
        ))
    };
    if meta.len() > max_bytes {
        return Err(too_large(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max_bytes + 1).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// An error unless `path` (symbolic links followed) is a regular file or does not exist: a
/// FIFO, a device (`/dev/full`, `/dev/stdout`), a socket or a directory is no place for
/// [`write_new`]'s output. Looks at the type only (never opens `path`): call it before the work
/// whose output goes there.
pub fn check_output_kind(path: &Path) -> Result<()> {
    match fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(Error::io(path, e)),
        Ok(m) if m.is_file() => Ok(()),
        Ok(m) if m.is_dir() => {
            Err(Error::InvalidInput(format!("{} is a directory, not a file", path.display())))
        }
        Ok(m) => Err(Error::InvalidInput(format!(
            "{} is {}, not a regular file: the output is written to a file beside it and renamed \
             over it; give the path of a regular file (then copy it where it should go)",
            path.display(),
            file_kind(&m)
        ))),
    }
}

/// Write `bytes` to `path` atomically ([`write_atomic`]) unless `path` already holds them; a
/// file with other contents is replaced only with `force` (never silently).
///
/// `path` must be a regular file or not exist: a FIFO, a device (`/dev/full`, `/dev/stdout`), a
/// socket or a directory is refused before anything is read from or written to it (the output is
/// written beside it and renamed over it, which a device or a pipe cannot take). An existing
/// file is compared only when it has the very size of `bytes`. Temporary files that killed
/// writers of `path` left beside it ([`remove_dead_temps`]) are removed first.
pub fn write_new(path: &Path, bytes: &[u8], force: bool) -> Result<Written> {
    check_output_kind(path)?;
    let written = match fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Written::New,
        Err(e) => return Err(Error::io(path, e)),
        // Replaced by a FIFO or a device since the check: refused as it was.
        Ok(m) if !m.is_file() => return check_output_kind(path).map(|()| Written::New),
        Ok(m)
            if m.len() == bytes.len() as u64
                && read_regular(path, m.len(), "output").is_ok_and(|old| old == bytes) =>
        {
            return Ok(Written::Unchanged)
        }
        Ok(_) if force => Written::Replaced,
        Ok(_) => {
            return Err(Error::InvalidInput(format!(
                "{} exists and holds something else; pass --force to replace it",
                path.display()
            )))
        }
    };
    remove_dead_temps(path)?;
    write_atomic(path, bytes)?;
    Ok(written)
}

/// Whether process `pid` is alive (Linux and other Unix: `kill(pid, 0)`; elsewhere assumed
/// alive, so that nothing of a live writer is ever removed).
fn pid_alive(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(pid) = libc::pid_t::try_from(pid) else { return true };
        if pid <= 0 {
            return true;
        }
        // SAFETY: signal 0 only checks that the process exists; nothing is sent.
        if unsafe { libc::kill(pid, 0) } == 0 {
            return true;
        }
        std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// Remove the temporary files of [`write_atomic`] for `path` (`<name>.tmp-<pid>` beside it) whose
/// writer is dead: a killed export or view leaves one behind. Only regular files (not symbolic
/// links) of that exact name are removed, and only when no process of that pid is alive (this
/// process's own is never touched). Returns what was removed.
pub fn remove_dead_temps(path: &Path) -> Result<Vec<PathBuf>> {
    let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return Ok(Vec::new());
    };
    let dir = match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(d) => d.to_path_buf(),
        None => PathBuf::from("."),
    };
    let Ok(entries) = fs::read_dir(&dir) else { return Ok(Vec::new()) };
    let prefix = format!("{name}.tmp-");
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let entry_name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = entry_name.strip_prefix(&prefix) else { continue };
        if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        let Ok(pid) = pid.parse::<u32>() else { continue };
        if pid == std::process::id() || pid_alive(pid) {
            continue;
        }
        // `file_type` does not follow symbolic links.
        if !entry.file_type().is_ok_and(|t| t.is_file()) {
            continue;
        }
        let p = entry.path();
        match fs::remove_file(&p) {
            Ok(()) => removed.push(p),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(Error::io(&p, e)),
        }
    }
    Ok(removed)
}

/// Whether `name` is a temporary file of [`write_atomic`] (`<name>.tmp-<pid>`).
pub fn is_temp_name(name: &str) -> bool {
    name.rsplit_once(".tmp-")
        .is_some_and(|(_, pid)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// Remove the temporary files of [`write_atomic`] in `dir` (not recursively) that a killed
/// writer left behind; a missing `dir` has none. Call it only while no live process can be
/// writing into `dir` (under its lock, see [`crate::run::lock`]). Returns what was removed.
pub fn remove_stale_temps(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(Error::io(dir, e)),
    };
    let mut removed = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let is_file = entry.file_type().is_ok_and(|t| t.is_file());
        if is_file && is_temp_name(&entry.file_name().to_string_lossy()) {
            let p = entry.path();
            match fs::remove_file(&p) {
                Ok(()) => removed.push(p),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(Error::io(&p, e)),
            }
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_whole_file_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("stagerl-io-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.txt");
        write_atomic(&p, b"first version, longer").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"second");
        let names: Vec<_> = fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let e = write_atomic(&dir.join("missing/b.txt"), b"x").unwrap_err().to_string();
        assert!(e.contains("missing/b.txt"), "{e}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn write_new_refuses_other_contents_without_force() {
        let dir = std::env::temp_dir().join(format!("stagerl-io-new-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let p = dir.join("model.onnx");
        assert_eq!(write_new(&p, b"one", false).unwrap(), Written::New);
        assert_eq!(write_new(&p, b"one", false).unwrap(), Written::Unchanged);
        let e = write_new(&p, b"two", false).unwrap_err().to_string();
        assert!(e.contains("model.onnx") && e.contains("--force"), "{e}");
        assert_eq!(fs::read(&p).unwrap(), b"one");
        assert_eq!(write_new(&p, b"two", true).unwrap(), Written::Replaced);
        assert_eq!(fs::read(&p).unwrap(), b"two");
        let e = write_new(&dir, b"x", true).unwrap_err().to_string();
        assert!(e.contains("is a directory"), "{e}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_link_at_the_temporary_path_is_not_written_through() {
        let dir = std::env::temp_dir().join(format!("stagerl-io-link-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let (p, victim) = (dir.join("model.onnx"), dir.join("victim"));
        fs::write(&victim, b"keep me").unwrap();
        std::os::unix::fs::symlink(&victim, temp_path(&p)).unwrap();
        write_atomic(&p, b"model").unwrap();
        assert_eq!(fs::read(&victim).unwrap(), b"keep me");
        assert_eq!(fs::read(&p).unwrap(), b"model");
        assert!(!fs::symlink_metadata(&p).unwrap().file_type().is_symlink());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn devices_are_neither_read_nor_written() {
        let e = read_regular(Path::new("/dev/zero"), 1 << 20, "checkpoint").unwrap_err().to_string();
        assert!(e.contains("/dev/zero is a character device; a checkpoint must be a regular file"), "{e}");
        for out in ["/dev/full", "/dev/null"] {
            let e = write_new(Path::new(out), b"x", true).unwrap_err().to_string();
            assert!(e.contains(&format!("{out} is a character device, not a regular file")), "{e}");
        }
        let dir = std::env::temp_dir().join(format!("stagerl-io-kind-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let big = dir.join("big.safetensors");
        fs::write(&big, vec![0u8; 100]).unwrap();
        let e = read_regular(&big, 99, "checkpoint").unwrap_err().to_string();
        assert!(e.contains("holds 100 bytes, more than the 99 bytes"), "{e}");
        assert_eq!(read_regular(&big, 100, "checkpoint").unwrap().len(), 100);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn stale_temps_are_removed_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("stagerl-io-stale-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        for name in
            ["latest.safetensors.tmp-4242", "eval.csv.tmp-1", "keep.tmp-", "keep.tmp-12a", "notes.txt"]
        {
            fs::write(dir.join(name), b"x").unwrap();
        }
        let mut removed: Vec<String> = remove_stale_temps(&dir)
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        removed.sort();
        assert_eq!(removed, ["eval.csv.tmp-1", "latest.safetensors.tmp-4242"]);
        let mut left: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["keep.tmp-", "keep.tmp-12a", "notes.txt"]);
        assert!(remove_stale_temps(&dir.join("missing")).unwrap().is_empty());
        fs::remove_dir_all(&dir).unwrap();
    }
}
