//! A study's runs packed in one archive (`runs.tar.xz`, written by
//! `scripts/studies/pack_runs.py`): [`generate`](super::generate) reads it as it reads the
//! directory it was packed from, by unpacking it into a temporary directory first.
//!
//! An archive is untrusted input: it is read only if it is a regular file of at most
//! [`MAX_ARCHIVE_BYTES`]; it may unpack to at most [`MAX_UNPACKED_BYTES`] in at most
//! [`MAX_ENTRIES`] entries, each a regular file or a directory whose path is relative and stays
//! inside one top-level folder (no `..`, no absolute path, no link, no device); anything else is
//! refused with the entry's name. Nothing is written outside the temporary directory, which is
//! removed when the [`Unpacked`] value is dropped.

use std::io::{Read, Write};
use std::path::{Component, Path, PathBuf};

use crate::{Error, Result};

/// Largest archive read, bytes.
pub const MAX_ARCHIVE_BYTES: u64 = 512 << 20;
/// Most bytes an archive may unpack to (the tar stream, headers included).
pub const MAX_UNPACKED_BYTES: u64 = 2 << 30;
/// Most entries (files and directories) in an archive.
pub const MAX_ENTRIES: usize = 200_000;

/// Whether `path` names a runs archive (by its name: `*.tar.xz`).
pub fn is_archive(path: &Path) -> bool {
    path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.ends_with(".tar.xz"))
}

/// How a report names an archive: its folder and file name (`obstacle-her/runs.tar.xz`), not an
/// absolute path of this machine nor the folder it unpacks to.
pub fn display_name(archive: &Path) -> String {
    let file = archive.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    match archive.parent().and_then(|p| p.file_name()) {
        Some(parent) => format!("{}/{file}", parent.to_string_lossy()),
        None => file,
    }
}

/// An archive unpacked into a temporary directory, removed on drop.
#[derive(Debug)]
pub struct Unpacked {
    temp: PathBuf,
    /// The archive's one top-level folder, inside the temporary directory.
    pub root: PathBuf,
}

impl Drop for Unpacked {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.temp);
    }
}

/// A writer that refuses to grow past a bound.
struct Bounded {
    buf: Vec<u8>,
    limit: u64,
}

impl Write for Bounded {
    fn write(&mut self, data: &[u8]) -> std::io::Result<usize> {
        if self.buf.len() as u64 + data.len() as u64 > self.limit {
            return Err(std::io::Error::other(format!("unpacks to more than {} bytes", self.limit)));
        }
        self.buf.extend_from_slice(data);
        Ok(data.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn bad(archive: &Path, what: impl std::fmt::Display) -> Error {
    Error::InvalidInput(format!("{}: {what}", archive.display()))
}

/// Unpack `archive` (xz-compressed tar) into a new temporary directory.
pub fn unpack(archive: &Path) -> Result<Unpacked> {
    let meta = std::fs::metadata(archive).map_err(|e| Error::io(archive, e))?;
    if !meta.is_file() {
        return Err(bad(archive, "not a regular file (a runs archive is a .tar.xz file)"));
    }
    if meta.len() > MAX_ARCHIVE_BYTES {
        return Err(bad(
            archive,
            format!("{} bytes; a runs archive is at most {MAX_ARCHIVE_BYTES}", meta.len()),
        ));
    }
    let file = std::fs::File::open(archive).map_err(|e| Error::io(archive, e))?;
    let mut input = std::io::BufReader::new(file.take(MAX_ARCHIVE_BYTES));
    let mut tar = Bounded { buf: Vec::new(), limit: MAX_UNPACKED_BYTES };
    lzma_rs::xz_decompress(&mut input, &mut tar)
        .map_err(|e| bad(archive, format!("not a readable .tar.xz archive: {e}")))?;
    let temp = temp_dir()?;
    // From here the directory is removed on every return.
    let mut unpacked = Unpacked { temp: temp.clone(), root: PathBuf::new() };
    let mut top: Option<std::ffi::OsString> = None;
    let mut reader = tar::Archive::new(&tar.buf[..]);
    let entries = reader.entries().map_err(|e| bad(archive, format!("tar: {e}")))?;
    for (count, entry) in entries.enumerate() {
        let mut entry = entry.map_err(|e| bad(archive, format!("tar entry {}: {e}", count + 1)))?;
        if count >= MAX_ENTRIES {
            return Err(bad(archive, format!("more than {MAX_ENTRIES} entries")));
        }
        let name =
            entry.path().map_err(|e| bad(archive, format!("tar entry {}: {e}", count + 1)))?.into_owned();
        let shown = name.display().to_string();
        let mut parts = Vec::new();
        for c in name.components() {
            match c {
                Component::Normal(p) => parts.push(p.to_owned()),
                Component::CurDir => {}
                _ => {
                    return Err(bad(
                        archive,
                        format!("entry `{shown}` leaves the archive's folder (an entry's path is relative, without `..`)"),
                    ))
                }
            }
        }
        let Some(first) = parts.first() else { continue };
        match &top {
            None => top = Some(first.clone()),
            Some(t) if t != first => {
                return Err(bad(
                    archive,
                    format!(
                        "entries in two top-level folders (`{}` and `{}`); a runs archive holds one",
                        t.to_string_lossy(),
                        first.to_string_lossy()
                    ),
                ))
            }
            Some(_) => {}
        }
        let dest: PathBuf = parts.iter().fold(temp.clone(), |p, c| p.join(c));
        let kind = entry.header().entry_type();
        if kind.is_dir() {
            std::fs::create_dir_all(&dest).map_err(|e| Error::io(&dest, e))?;
        } else if kind.is_file() {
            if let Some(parent) = dest.parent() {
                std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            let mut data = Vec::new();
            entry.read_to_end(&mut data).map_err(|e| bad(archive, format!("entry `{shown}`: {e}")))?;
            let (dest, data) =
                match dest.to_str().filter(|d| d.ends_with(TRANSPOSED)).and_then(|d| d.strip_suffix(".T")) {
                    Some(csv) => (
                        PathBuf::from(csv),
                        untranspose(&data).map_err(|e| bad(archive, format!("entry `{shown}`: {e}")))?,
                    ),
                    None => (dest, data),
                };
            std::fs::write(&dest, &data).map_err(|e| Error::io(&dest, e))?;
        } else {
            return Err(bad(
                archive,
                format!(
                    "entry `{shown}` is not a regular file or a directory (links and devices are refused)"
                ),
            ));
        }
    }
    let Some(top) = top else { return Err(bad(archive, "holds no file")) };
    unpacked.root = temp.join(top);
    if !unpacked.root.is_dir() {
        return Err(bad(archive, "its top-level entry is not a folder of runs"));
    }
    Ok(unpacked)
}

/// The suffix of a CSV stored transposed: `NAME.csv.T` holds column i of `NAME.csv` on line i
/// (its name, then its values), which compresses better; it unpacks as `NAME.csv`.
pub const TRANSPOSED: &str = ".csv.T";

/// The suffix of a transposed column's name whose values are stored as differences: line
/// `NAME:diff,v1,d2,d3,...` holds the integer column `NAME` as `v1, v1 + d2, v1 + d2 + d3, ...`
/// (a running count such as `env_steps` then compresses to almost nothing).
pub const DIFFERENCES: &str = ":diff";

/// `NAME.csv` from the text of `NAME.csv.T`: every line (column) must have the same number of
/// fields; a column named `NAME:diff` ([`DIFFERENCES`]) is summed back into `NAME`.
pub fn untranspose(data: &[u8]) -> std::result::Result<Vec<u8>, String> {
    let text = std::str::from_utf8(data).map_err(|_| "not UTF-8 text".to_string())?;
    let mut summed: Vec<Vec<String>> = Vec::new();
    let mut cols: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    let rows = cols.first().map_or(0, Vec::len);
    if let Some((i, c)) = cols.iter().enumerate().find(|(_, c)| c.len() != rows) {
        return Err(format!(
            "column {} (`{}`) holds {} fields where the first holds {rows}",
            i + 1,
            c[0],
            c.len()
        ));
    }
    for c in &cols {
        if let Some(name) = c[0].strip_suffix(DIFFERENCES) {
            summed.push(running_sums(name, &c[1..])?);
        }
    }
    let mut next = summed.iter();
    for c in &mut cols {
        if c[0].ends_with(DIFFERENCES) {
            if let Some(values) = next.next() {
                *c = values.iter().map(String::as_str).collect();
            }
        }
    }
    let mut out = Vec::with_capacity(data.len() + rows);
    for r in 0..rows {
        for (j, c) in cols.iter().enumerate() {
            if j > 0 {
                out.push(b',');
            }
            out.extend_from_slice(c[r].as_bytes());
        }
        out.push(b'\n');
    }
    Ok(out)
}

/// `name` followed by the running sums of `diffs` (integers), as text.
fn running_sums(name: &str, diffs: &[&str]) -> std::result::Result<Vec<String>, String> {
    let mut out = Vec::with_capacity(diffs.len() + 1);
    out.push(name.to_owned());
    let mut total: i64 = 0;
    for (i, d) in diffs.iter().enumerate() {
        let step: i64 = d
            .parse()
            .map_err(|_| format!("column `{name}{DIFFERENCES}`, value {}: `{d}` is not an integer", i + 1))?;
        total = total
            .checked_add(step)
            .ok_or_else(|| format!("column `{name}{DIFFERENCES}`, value {}: the sum overflows", i + 1))?;
        out.push(total.to_string());
    }
    Ok(out)
}

/// A new, empty directory under the system's temporary directory.
fn temp_dir() -> Result<PathBuf> {
    let base = std::env::temp_dir();
    let pid = std::process::id();
    let nanos =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    for attempt in 0..100u32 {
        let p = base.join(format!("stagerl-report-{pid}-{nanos:x}-{attempt}"));
        match std::fs::create_dir(&p) {
            Ok(()) => return Ok(p),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(Error::io(&p, e)),
        }
    }
    Err(Error::InvalidInput(format!("no free temporary directory name under {}", base.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An xz-compressed tar of `entries`: (name written raw into the header, type, data).
    fn archive(entries: &[(&str, tar::EntryType, &[u8])]) -> Vec<u8> {
        let mut b = tar::Builder::new(Vec::new());
        for (name, kind, data) in entries {
            let mut h = tar::Header::new_gnu();
            // Raw name bytes: Header::set_path would refuse the hostile ones under test.
            let field = &mut h.as_old_mut().name;
            field.fill(0);
            field[..name.len()].copy_from_slice(name.as_bytes());
            h.set_entry_type(*kind);
            h.set_size(data.len() as u64);
            h.set_mode(0o644);
            if *kind == tar::EntryType::Symlink {
                h.set_link_name("/etc").unwrap();
            }
            h.set_cksum();
            b.append(&h, *data).unwrap();
        }
        let tar = b.into_inner().unwrap();
        let mut xz = Vec::new();
        lzma_rs::xz_compress(&mut &tar[..], &mut xz).unwrap();
        xz
    }

    fn write(name: &str, bytes: &[u8]) -> PathBuf {
        let dir = temp_dir().unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn an_archive_is_named_by_its_folder_and_file() {
        assert_eq!(
            display_name(Path::new("/home/u/docs/results/obstacle-her/runs.tar.xz")),
            "obstacle-her/runs.tar.xz"
        );
        assert_eq!(display_name(Path::new("runs.tar.xz")), "runs.tar.xz");
    }

    #[test]
    fn unpacks_one_folder_and_removes_it_on_drop() {
        use tar::EntryType::{Directory, Regular};
        let p = write(
            "runs.tar.xz",
            &archive(&[
                ("runs/", Directory, b""),
                ("runs/a/config.toml", Regular, b"x = 1\n"),
                ("runs/b.csv", Regular, b"1,2\n"),
            ]),
        );
        let u = unpack(&p).unwrap();
        assert_eq!(u.root.file_name().unwrap(), "runs");
        assert_eq!(std::fs::read(u.root.join("a/config.toml")).unwrap(), b"x = 1\n");
        assert_eq!(std::fs::read(u.root.join("b.csv")).unwrap(), b"1,2\n");
        let temp = u.temp.clone();
        assert!(temp.starts_with(std::env::temp_dir()));
        drop(u);
        assert!(!temp.exists(), "the temporary directory is removed");
        std::fs::remove_dir_all(p.parent().unwrap()).unwrap();
    }

    #[test]
    fn hostile_or_malformed_archives_are_refused_naming_the_entry() {
        use tar::EntryType::{Regular, Symlink};
        // A name no other process uses: the test asserts that nothing was written under it.
        let evil = format!("stagerl-archive-test-evil-{}", std::process::id());
        let up = format!("runs/../../{evil}");
        let abs = format!("/etc/{evil}");
        let cases: Vec<(Vec<u8>, String)> = vec![
            (archive(&[(&up, Regular, b"x")]), format!("entry `{up}` leaves the archive's folder")),
            (archive(&[(&abs, Regular, b"x")]), format!("entry `{abs}` leaves the archive's folder")),
            (
                archive(&[("runs/link", Symlink, b"")]),
                "entry `runs/link` is not a regular file or a directory".into(),
            ),
            (
                archive(&[("runs/a", Regular, b"x"), ("other/b", Regular, b"y")]),
                "two top-level folders".into(),
            ),
            (archive(&[("runs", Regular, b"x")]), "not a folder of runs".into()),
            (b"not xz at all".to_vec(), "not a readable .tar.xz archive".into()),
        ];
        for (bytes, want) in cases {
            let p = write("runs.tar.xz", &bytes);
            let err = unpack(&p).unwrap_err().to_string();
            assert!(err.contains(&want), "{err:?} lacks {want:?}");
            assert!(!std::env::temp_dir().join(&evil).exists() && !Path::new(&abs).exists());
            std::fs::remove_dir_all(p.parent().unwrap()).unwrap();
        }
        let dir = temp_dir().unwrap();
        let err = unpack(&dir).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
        std::fs::remove_dir(&dir).unwrap();
    }

    #[test]
    fn a_transposed_csv_unpacks_as_the_csv() {
        use tar::EntryType::Regular;
        let t = b"episode,1,2,3\nreward,-1.5,0,20.25\nwall_s,0,0.1,0.2\n";
        assert_eq!(untranspose(t).unwrap(), b"episode,reward,wall_s\n1,-1.5,0\n2,0,0.1\n3,20.25,0.2\n");
        let err = untranspose(b"episode,1,2\nreward,5\n").unwrap_err();
        assert!(err.contains("column 2 (`reward`) holds 2 fields where the first holds 3"), "{err}");
        // a running count stored as differences sums back to the count
        let d = b"episode,1,2,3\nenv_steps:diff,50,7,12\nwall_s,0,0.1,0.2\n";
        assert_eq!(untranspose(d).unwrap(), b"episode,env_steps,wall_s\n1,50,0\n2,57,0.1\n3,69,0.2\n");
        let err = untranspose(b"episode,1,2\nenv_steps:diff,50,x\n").unwrap_err();
        assert!(err.contains("column `env_steps:diff`, value 2: `x` is not an integer"), "{err}");
        let err = untranspose(format!("a,1,2\nn:diff,{},1\n", i64::MAX).as_bytes()).unwrap_err();
        assert!(err.contains("value 2: the sum overflows"), "{err}");
        let p = write("runs.tar.xz", &archive(&[("runs/r/episodes.csv.T", Regular, t)]));
        let u = unpack(&p).unwrap();
        assert_eq!(std::fs::read(u.root.join("r/episodes.csv")).unwrap(), untranspose(t).unwrap());
        assert!(!u.root.join("r/episodes.csv.T").exists());
        drop(u);
        std::fs::remove_dir_all(p.parent().unwrap()).unwrap();
    }

    #[test]
    fn an_archive_that_unpacks_too_large_is_refused() {
        let mut w = Bounded { buf: Vec::new(), limit: 10 };
        assert!(w.write(&[0; 10]).is_ok());
        let err = w.write(&[0; 1]).unwrap_err().to_string();
        assert!(err.contains("more than 10 bytes"), "{err}");
    }
}
