//! TensorBoard event files, written directly.
//!
//! The format is TFRecord: each record is `len: u64 LE`, `masked_crc32c(len bytes): u32 LE`,
//! `data`, `masked_crc32c(data): u32 LE`, where `data` is a serialised `tensorflow.Event`
//! protobuf. We encode the few fields we need by hand: `wall_time` (1, double), `step` (2, int64),
//! `file_version` (3, string) and `summary` (5) holding `Summary.Value { tag (1), simple_value
//! (2, float) }`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::io::proto::{put_f32, put_f64, put_int, put_len_delimited};
use crate::{Error, Result};

/// The CRC mask TFRecord applies: rotate right by 15 and add a constant.
pub fn masked_crc32c(data: &[u8]) -> u32 {
    let crc = crc32c::crc32c(data);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// Encode an `Event` with a wall time, step, and either a file version or one scalar.
fn encode_event(
    wall_time: f64,
    step: i64,
    file_version: Option<&str>,
    scalar: Option<(&str, f32)>,
) -> Vec<u8> {
    let mut ev = Vec::with_capacity(64);
    put_f64(&mut ev, 1, wall_time);
    put_int(&mut ev, 2, step);
    if let Some(v) = file_version {
        put_len_delimited(&mut ev, 3, v.as_bytes());
    }
    if let Some((tag, value)) = scalar {
        let mut val = Vec::with_capacity(tag.len() + 8);
        put_len_delimited(&mut val, 1, tag.as_bytes());
        put_f32(&mut val, 2, value); // simple_value
        let mut summary = Vec::with_capacity(val.len() + 4);
        put_len_delimited(&mut summary, 1, &val);
        put_len_delimited(&mut ev, 5, &summary);
    }
    ev
}

/// Frame `data` as one TFRecord.
fn frame(data: &[u8]) -> Vec<u8> {
    let len = (data.len() as u64).to_le_bytes();
    let mut rec = Vec::with_capacity(data.len() + 16);
    rec.extend_from_slice(&len);
    rec.extend_from_slice(&masked_crc32c(&len).to_le_bytes());
    rec.extend_from_slice(data);
    rec.extend_from_slice(&masked_crc32c(data).to_le_bytes());
    rec
}

/// Writes scalars to `events.out.tfevents.<unix seconds>.<host>.<pid>` in a directory.
pub struct EventWriter {
    out: BufWriter<File>,
    path: PathBuf,
}

fn now() -> f64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_secs_f64()).unwrap_or(0.0)
}

impl EventWriter {
    /// A new event file in `dir` (which must exist).
    pub fn create(dir: &Path) -> Result<EventWriter> {
        let host = std::fs::read_to_string("/etc/hostname")
            .ok()
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "localhost".into());
        let wall = now();
        let path = dir.join(format!("events.out.tfevents.{}.{host}.{}", wall as u64, std::process::id()));
        let file = File::create(&path).map_err(|e| Error::io(&path, e))?;
        let mut w = EventWriter { out: BufWriter::new(file), path };
        w.write_record(&encode_event(wall, 0, Some("brain.Event:2"), None))?;
        Ok(w)
    }

    fn write_record(&mut self, data: &[u8]) -> Result<()> {
        self.out.write_all(&frame(data)).map_err(|e| Error::io(&self.path, e))
    }

    /// Record `value` under `tag` at `step`.
    pub fn scalar(&mut self, tag: &str, step: i64, value: f64) -> Result<()> {
        self.write_record(&encode_event(now(), step, None, Some((tag, value as f32))))
    }

    /// Push buffered records to the file.
    pub fn flush(&mut self) -> Result<()> {
        self.out.flush().map_err(|e| Error::io(&self.path, e))
    }

    /// The event file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Read back the scalars of an event file as `(tag, step, value)`, checking every CRC. Used by the
/// tests and by tools that summarise runs.
pub fn read_scalars(path: &Path) -> Result<Vec<(String, i64, f32)>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (records, valid) = valid_records(&bytes);
    if valid != bytes.len() {
        return Err(Error::InvalidInput(format!(
            "{}: torn or corrupt record (length or CRC mismatch) at byte {valid} of {}",
            path.display(),
            bytes.len()
        )));
    }
    Ok(records.iter().filter_map(|r| decode_scalar(r.data)).collect())
}

/// One record of an event file: its `Event` bytes (as written, wall time included).
struct Record<'a> {
    data: &'a [u8],
}

/// The records of an event file up to the first torn or corrupt one (a length or data CRC
/// mismatch, or a record cut short, as a killed writer leaves at the end), with the offset where
/// the valid part ends.
fn valid_records(bytes: &[u8]) -> (Vec<Record<'_>>, usize) {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 12 <= bytes.len() {
        let len_bytes = &bytes[i..i + 8];
        let len = u64::from_le_bytes(len_bytes.try_into().expect("8 bytes"));
        let crc = u32::from_le_bytes(bytes[i + 8..i + 12].try_into().expect("4 bytes"));
        let start = i + 12;
        let Some(end) = usize::try_from(len).ok().and_then(|l| start.checked_add(l)) else { break };
        if crc != masked_crc32c(len_bytes) || end + 4 > bytes.len() {
            break;
        }
        let data = &bytes[start..end];
        if u32::from_le_bytes(bytes[end..end + 4].try_into().expect("4 bytes")) != masked_crc32c(data) {
            break;
        }
        out.push(Record { data });
        i = end + 4;
    }
    (out, i)
}

/// The event files of a TensorBoard directory, sorted by name (which starts with the creation
/// time); a missing directory has none.
pub fn event_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(Error::io(dir, e)),
    };
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with("events.out.tfevents.") && !crate::io::is_temp_name(&name) {
            files.push(entry.path());
        }
    }
    files.sort();
    Ok(files)
}

/// Cut the event log in `dir` back to what a checkpoint has seen, so that a resumed run logs
/// every (tag, step) exactly once, as an uninterrupted run does: keep the scalars for which
/// `keep(tag, step)` holds (say, step <= the checkpoint's episode; the first of any duplicate),
/// drop torn or corrupt trailing records, and write them into one file (the oldest file's name,
/// replaced atomically) before removing the others. Killed at any point, a later rewind still
/// gives the same result. Returns the scalars kept.
pub fn rewind(dir: &Path, keep: impl Fn(&str, i64) -> bool) -> Result<usize> {
    let files = event_files(dir)?;
    let Some(first) = files.first() else { return Ok(0) };
    let mut seen = std::collections::HashSet::new();
    let mut out = frame(&encode_event(now(), 0, Some("brain.Event:2"), None));
    for path in &files {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        for rec in valid_records(&bytes).0 {
            if let Some((tag, step, _)) = decode_scalar(rec.data) {
                if keep(&tag, step) && seen.insert((tag, step)) {
                    out.extend_from_slice(&frame(rec.data));
                }
            }
        }
    }
    crate::io::write_atomic(first, &out)?;
    for path in &files[1..] {
        std::fs::remove_file(path).map_err(|e| Error::io(path, e))?;
    }
    Ok(seen.len())
}

/// Remove every event file of `dir` (a new run replacing an older one).
pub fn remove_all(dir: &Path) -> Result<Vec<PathBuf>> {
    let files = event_files(dir)?;
    for path in &files {
        std::fs::remove_file(path).map_err(|e| Error::io(path, e))?;
    }
    Ok(files)
}

fn get_varint(d: &[u8], i: &mut usize) -> Option<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *d.get(*i)?;
        *i += 1;
        v |= u64::from(b & 0x7f) << shift;
        if b < 0x80 {
            return Some(v);
        }
    }
    None
}

/// Decode the fields this module writes; `None` for events without a scalar.
fn decode_scalar(d: &[u8]) -> Option<(String, i64, f32)> {
    let (mut i, mut step, mut result) = (0, 0i64, None);
    while i < d.len() {
        let key = get_varint(d, &mut i)?;
        match (key >> 3, key & 7) {
            (1, 1) => i += 8,
            (2, 0) => step = get_varint(d, &mut i)? as i64,
            (_, 2) => {
                let len = get_varint(d, &mut i)? as usize;
                let body = d.get(i..i + len)?;
                if key >> 3 == 5 {
                    // Summary { value: Value { tag, simple_value } }
                    let mut j = 0;
                    get_varint(body, &mut j)?;
                    let vlen = get_varint(body, &mut j)? as usize;
                    let val = body.get(j..j + vlen)?;
                    let mut k = 0;
                    get_varint(val, &mut k)?;
                    let tlen = get_varint(val, &mut k)? as usize;
                    let tag = String::from_utf8(val.get(k..k + tlen)?.to_vec()).ok()?;
                    k += tlen;
                    get_varint(val, &mut k)?;
                    let v = f32::from_le_bytes(val.get(k..k + 4)?.try_into().ok()?);
                    result = Some((tag, v));
                }
                i += len;
            }
            _ => return None,
        }
    }
    result.map(|(tag, v)| (tag, step, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_known_vector() {
        // The standard check value of CRC-32C.
        assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
        assert_eq!(masked_crc32c(b""), 0u32.rotate_right(15).wrapping_add(0xa282_ead8));
    }

    #[test]
    fn write_then_read_back() {
        let dir = std::env::temp_dir().join(format!("stagerl-tb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut w = EventWriter::create(&dir).unwrap();
        w.scalar("train/episode_reward", 1, 12.5).unwrap();
        w.scalar("loss/critic", 300, -0.25).unwrap();
        w.flush().unwrap();
        let got = read_scalars(w.path()).unwrap();
        assert_eq!(got, vec![("train/episode_reward".into(), 1, 12.5), ("loss/critic".into(), 300, -0.25)]);
        // A flipped byte is caught by the CRC.
        let mut bytes = std::fs::read(w.path()).unwrap();
        let n = bytes.len();
        bytes[n - 6] ^= 1;
        std::fs::write(w.path(), &bytes).unwrap();
        assert!(read_scalars(w.path()).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn rewind_keeps_each_step_once_up_to_the_checkpoint_and_drops_a_torn_tail() {
        let dir = std::env::temp_dir().join(format!("stagerl-tb-rewind-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, steps: std::ops::RangeInclusive<i64>, torn: bool| {
            let mut bytes = frame(&encode_event(1.0, 0, Some("brain.Event:2"), None));
            for s in steps {
                bytes.extend(frame(&encode_event(2.0, s, None, Some(("a", s as f32)))));
                bytes.extend(frame(&encode_event(2.0, s, None, Some(("b", -s as f32)))));
            }
            if torn {
                let rec = frame(&encode_event(2.0, 99, None, Some(("a", 99.0))));
                bytes.extend(&rec[..rec.len() - 3]);
            }
            std::fs::write(dir.join(name), bytes).unwrap();
        };
        // Session 1 logged 1..=7 (checkpoint at 5) and was killed mid-record; session 2 resumed
        // at 5 without a rewind (as before this fix) and logged 6..=9.
        write("events.out.tfevents.100.h.1", 1..=7, true);
        write("events.out.tfevents.200.h.2", 6..=9, false);
        std::fs::write(dir.join("events.out.tfevents.300.h.3.tmp-3"), b"junk").unwrap();
        assert_eq!(rewind(&dir, |_, s| s <= 8).unwrap(), 16);
        let files = event_files(&dir).unwrap();
        assert_eq!(files, [dir.join("events.out.tfevents.100.h.1")]);
        let got = read_scalars(&files[0]).unwrap();
        let mut want = Vec::new();
        for s in 1..=8 {
            want.push(("a".to_string(), s, s as f32));
            want.push(("b".to_string(), s, -s as f32));
        }
        assert_eq!(got, want);
        // Rewinding again, or to an earlier step, is consistent.
        assert_eq!(rewind(&dir, |_, s| s <= 8).unwrap(), 16);
        assert_eq!(rewind(&dir, |t, s| s < 3 || (s == 3 && t == "a")).unwrap(), 5);
        assert_eq!(read_scalars(&files[0]).unwrap(), want[..5]);
        assert_eq!(remove_all(&dir).unwrap().len(), 1);
        assert_eq!(rewind(&dir, |_, _| true).unwrap(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
