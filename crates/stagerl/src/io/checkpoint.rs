//! Checkpoint files: named f32 tensors plus string metadata, in the `safetensors` format (readable
//! from Python with `safetensors.numpy.load_file`). Written atomically.
//!
//! Everything that is not a float array (counters, random-generator states, the config, the
//! algorithm's name) goes in the metadata as text, usually JSON.
//!
//! The header's JSON is written with its keys sorted (the metadata's and each tensor's), so the
//! same contents give the same file, byte for byte, in any process.
//!
//! Every file carries a SHA-256 checksum of its contents in the metadata entry `sha256` (lowercase
//! hex), checked on every load: a file without it or with a wrong one is refused, naming the file.
//! It is the SHA-256 of a sequence of parts, each written as its length in bytes (8 bytes, little
//! endian) followed by its bytes: for each tensor in name order, its name, its shape as decimal
//! numbers joined by `,` (empty for a scalar) and its values as little-endian f32 bytes (as stored);
//! then for each other metadata entry in key order, its key and its value (UTF-8). In Python:
//!
//! ```python
//! import hashlib
//! from safetensors import safe_open
//! def part(h, b): h.update(len(b).to_bytes(8, "little")); h.update(b)
//! h = hashlib.sha256()
//! with safe_open(path, "numpy") as f:
//!     meta = f.metadata()
//!     for name in sorted(f.keys()):
//!         t = f.get_tensor(name)
//!         part(h, name.encode()); part(h, ",".join(map(str, t.shape)).encode())
//!         part(h, t.astype("<f4").tobytes())
//!     for k in sorted(meta):
//!         if k != "sha256": part(h, k.encode()); part(h, meta[k].encode())
//! assert h.hexdigest() == meta["sha256"]
//! ```

use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// The largest checkpoint file read, bytes: 17 GiB (a run is refused beyond an estimated 16 GiB,
/// `config::MAX_RUN_MEMORY_BYTES`, which bounds its replay buffer and networks).
pub const MAX_CHECKPOINT_BYTES: u64 = 17 << 30;

/// The metadata key of the checksum.
pub const CHECKSUM_KEY: &str = "sha256";

/// A safetensors file with its header's JSON keys sorted (safetensors writes its maps in hash
/// order, which differs from process to process): the same JSON values, re-serialised (serde_json
/// maps are sorted) and padded with spaces to the header's length, so every data offset stays.
/// A header that does not parse or would not fit is left as it is (it cannot happen for a file
/// safetensors just wrote).
fn sorted_header(mut bytes: Vec<u8>) -> Vec<u8> {
    let Some(n) = bytes.get(..8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")) as usize) else {
        return bytes;
    };
    let Some(header) = bytes.get(8..8usize.saturating_add(n)) else { return bytes };
    let Ok(value) = serde_json::from_slice::<serde_json::Value>(header) else { return bytes };
    let Ok(sorted) = serde_json::to_vec(&value) else { return bytes };
    if sorted.len() <= n {
        bytes[8..8 + sorted.len()].copy_from_slice(&sorted);
        bytes[8 + sorted.len()..8 + n].fill(b' ');
    }
    bytes
}

/// The checksum described in the module docs, over tensors given as (name, shape, f32 LE bytes).
fn checksum<'a>(
    tensors: impl Iterator<Item = (&'a str, &'a [usize], &'a [u8])>,
    metadata: &BTreeMap<String, String>,
) -> String {
    let mut h = Sha256::new();
    let mut part = |b: &[u8]| {
        h.update((b.len() as u64).to_le_bytes());
        h.update(b);
    };
    for (name, shape, bytes) in tensors {
        part(name.as_bytes());
        part(shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(",").as_bytes());
        part(bytes);
    }
    for (k, v) in metadata.iter().filter(|(k, _)| *k != CHECKSUM_KEY) {
        part(k.as_bytes());
        part(v.as_bytes());
    }
    format!("{:x}", h.finalize())
}

/// A checkpoint being assembled or one that was read back.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Checkpoint {
    tensors: BTreeMap<String, (Vec<usize>, Vec<f32>)>,
    metadata: BTreeMap<String, String>,
    /// Where it was read from, for error messages.
    origin: Option<PathBuf>,
}

impl Checkpoint {
    /// An empty checkpoint.
    pub fn new() -> Checkpoint {
        Checkpoint::default()
    }

    /// Add a tensor; `shape`'s product must equal `data.len()`.
    pub fn put_tensor(&mut self, name: &str, shape: &[usize], data: &[f32]) {
        assert_eq!(
            shape.iter().product::<usize>(),
            data.len(),
            "tensor {name}: shape {shape:?} does not fit"
        );
        self.tensors.insert(name.to_string(), (shape.to_vec(), data.to_vec()));
    }

    /// Add a metadata entry.
    pub fn put_meta(&mut self, key: &str, value: impl Into<String>) {
        assert_ne!(key, CHECKSUM_KEY, "`{CHECKSUM_KEY}` is written by `to_bytes`");
        self.metadata.insert(key.to_string(), value.into());
    }

    /// Add a metadata entry as JSON.
    pub fn put_json<T: serde::Serialize>(&mut self, key: &str, value: &T) {
        self.put_meta(key, serde_json::to_string(value).expect("metadata serialises"));
    }

    /// The file it was read from, or "checkpoint", for error messages.
    pub fn name(&self) -> String {
        self.where_()
    }

    fn where_(&self) -> String {
        self.origin.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "checkpoint".into())
    }

    /// A tensor by name with its shape.
    pub fn tensor(&self, name: &str) -> Result<(&[usize], &[f32])> {
        self.tensors
            .get(name)
            .map(|(s, d)| (s.as_slice(), d.as_slice()))
            .ok_or_else(|| Error::InvalidInput(format!("{}: no tensor `{name}`", self.where_())))
    }

    /// Copy tensor `name` into `out`, which must have exactly its number of values.
    pub fn read_tensor_into(&self, name: &str, out: &mut [f32]) -> Result<()> {
        let (shape, data) = self.tensor(name)?;
        if data.len() != out.len() {
            return Err(Error::InvalidInput(format!(
                "{}: tensor `{name}` has shape {shape:?} ({} values), expected {} values",
                self.where_(),
                data.len(),
                out.len()
            )));
        }
        out.copy_from_slice(data);
        Ok(())
    }

    /// A metadata entry.
    pub fn meta(&self, key: &str) -> Result<&str> {
        self.metadata
            .get(key)
            .map(String::as_str)
            .ok_or_else(|| Error::InvalidInput(format!("{}: no metadata `{key}`", self.where_())))
    }

    /// A metadata entry parsed from JSON.
    pub fn json<T: serde::de::DeserializeOwned>(&self, key: &str) -> Result<T> {
        serde_json::from_str(self.meta(key)?)
            .map_err(|e| Error::InvalidInput(format!("{}: metadata `{key}`: {e}", self.where_())))
    }

    /// Every metadata entry, sorted by key.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// Same tensors (names, shapes, bit-identical values) and same metadata (then the files are
    /// the same too: [`sorted_header`]).
    pub fn same_contents(&self, other: &Checkpoint) -> bool {
        self.metadata == other.metadata
            && self.tensors.len() == other.tensors.len()
            && self.tensors.iter().zip(&other.tensors).all(|((na, (sa, da)), (nb, (sb, db)))| {
                na == nb && sa == sb && da.iter().zip(db).all(|(x, y)| x.to_bits() == y.to_bits())
            })
    }

    /// Tensor names, sorted.
    pub fn tensor_names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(String::as_str)
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let bytes: Vec<(&String, Vec<u8>, &Vec<usize>)> = self
            .tensors
            .iter()
            .map(|(name, (shape, data))| (name, data.iter().flat_map(|x| x.to_le_bytes()).collect(), shape))
            .collect();
        let views = bytes
            .iter()
            .map(|(name, b, shape)| {
                TensorView::new(Dtype::F32, shape.to_vec(), b).map(|v| (name.as_str(), v))
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| Error::InvalidInput(format!("checkpoint: {e}")))?;
        let sum = checksum(
            bytes.iter().map(|(name, b, shape)| (name.as_str(), shape.as_slice(), b.as_slice())),
            &self.metadata,
        );
        let mut meta: HashMap<String, String> = self.metadata.clone().into_iter().collect();
        meta.insert(CHECKSUM_KEY.to_string(), sum);
        safetensors::tensor::serialize(views, Some(meta))
            .map(sorted_header)
            .map_err(|e| Error::InvalidInput(format!("checkpoint: {e}")))
    }

    /// Write atomically to `path`.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::io::write_atomic(path, &self.to_bytes()?)
    }

    /// Parse a checkpoint and check its checksum; `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &Path) -> Result<Checkpoint> {
        let bad = |what: String| {
            Error::InvalidInput(format!("{}: not a valid checkpoint: {what}", origin.display()))
        };
        let st = SafeTensors::deserialize(bytes)
            .map_err(|e| bad(crate::base::text::bound_message(&e.to_string())))?;
        let (_, header) = SafeTensors::read_metadata(bytes)
            .map_err(|e| bad(crate::base::text::bound_message(&e.to_string())))?;
        let mut ck = Checkpoint { origin: Some(origin.to_path_buf()), ..Checkpoint::default() };
        if let Some(m) = header.metadata() {
            ck.metadata = m.clone().into_iter().collect();
        }
        let mut names = st.names();
        names.sort();
        let mut views = Vec::with_capacity(names.len());
        for name in names {
            let view = st.tensor(name).map_err(|e| bad(e.to_string()))?;
            if view.dtype() != Dtype::F32 {
                return Err(bad(format!("tensor `{name}` is {:?}, expected F32", view.dtype())));
            }
            views.push((name, view));
        }
        let Some(stored) = ck.metadata.remove(CHECKSUM_KEY) else {
            return Err(bad(format!(
                "no `{CHECKSUM_KEY}` checksum in its metadata (every stagerl checkpoint has one); refused"
            )));
        };
        let computed = checksum(views.iter().map(|(name, v)| (*name, v.shape(), v.data())), &ck.metadata);
        if computed != stored {
            return Err(bad(format!(
                "checksum mismatch (stored sha256 {}, contents hash to {computed}): the file is corrupted; refused",
                crate::base::text::excerpt(&stored)
            )));
        }
        for (name, view) in views {
            let data: Vec<f32> =
                view.data().chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
            ck.tensors.insert(name.to_string(), (view.shape().to_vec(), data));
        }
        Ok(ck)
    }

    /// Read a checkpoint file: a regular file of at most [`MAX_CHECKPOINT_BYTES`] (a FIFO or a
    /// device such as `/dev/zero` is refused unread).
    pub fn load(path: &Path) -> Result<Checkpoint> {
        let bytes = crate::io::read_regular(path, MAX_CHECKPOINT_BYTES, "checkpoint")?;
        Checkpoint::from_bytes(&bytes, path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same contents give the same bytes, whatever order the hash maps of safetensors take
    /// (each `to_bytes` makes new ones, with new random keys), and the sorted file reads back.
    #[test]
    fn the_same_contents_give_the_same_file() {
        let mut ck = Checkpoint::new();
        for k in 0..12 {
            ck.put_tensor(&format!("layer{k}.weight"), &[2, 2], &[k as f32, 1.0, -2.0, 0.5]);
            ck.put_meta(&format!("key{k}"), format!("value {k}"));
        }
        let first = ck.to_bytes().unwrap();
        let header = |b: &[u8]| {
            let n = u64::from_le_bytes(b[..8].try_into().unwrap()) as usize;
            String::from_utf8(b[8..8 + n].to_vec()).unwrap()
        };
        let h = header(&first);
        let (k0, k11) = (h.find("\"key0\"").unwrap(), h.find("\"key11\"").unwrap());
        let (l0, l11) = (h.find("\"layer0.weight\"").unwrap(), h.find("\"layer11.weight\"").unwrap());
        assert!(k0 < k11 && l0 < l11 && h.starts_with("{\"__metadata__\""), "{h}");
        for _ in 0..20 {
            assert_eq!(ck.to_bytes().unwrap(), first);
        }
        let back = Checkpoint::from_bytes(&first, Path::new("mem")).unwrap();
        assert!(back.same_contents(&ck));
    }

    #[test]
    fn round_trip_and_errors() {
        let dir = std::env::temp_dir().join(format!("stagerl-ck-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.safetensors");
        let mut ck = Checkpoint::new();
        ck.put_tensor("actor.layer0.weight", &[2, 3], &[1.0, -2.0, 3.5, 0.0, 1e-30, f32::MAX]);
        ck.put_tensor("actor.layer0.bias", &[2], &[0.25, -0.5]);
        ck.put_meta("algorithm", "sac");
        ck.put_json("episode", &1234u64);
        ck.save(&p).unwrap();
        let back = Checkpoint::load(&p).unwrap();
        assert_eq!(
            back.tensor("actor.layer0.weight").unwrap(),
            (&[2usize, 3][..], &[1.0, -2.0, 3.5, 0.0, 1e-30, f32::MAX][..])
        );
        assert_eq!(back.meta("algorithm").unwrap(), "sac");
        assert_eq!(back.json::<u64>("episode").unwrap(), 1234);
        let mut out = [0.0; 3];
        let e = back.read_tensor_into("actor.layer0.bias", &mut out).unwrap_err().to_string();
        assert!(e.contains("actor.layer0.bias") && e.contains("expected 3"), "{e}");
        assert!(back.tensor("critic").unwrap_err().to_string().contains("critic"));
        // Truncated and garbage files are errors naming the file, not panics.
        let bytes = std::fs::read(&p).unwrap();
        for cut in [0, 4, 8, 20, bytes.len() - 3] {
            let e = Checkpoint::from_bytes(&bytes[..cut], &p).unwrap_err().to_string();
            assert!(e.contains("a.safetensors"), "{e}");
        }
        assert!(Checkpoint::from_bytes(b"definitely not a checkpoint", &p).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
