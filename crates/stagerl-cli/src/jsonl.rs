//! JSON-lines plumbing shared by the inspection commands: read one object per line, answer one
//! line per input, stop at the first bad line with its number.

use anyhow::{bail, Context, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::io::{BufRead, Read, Write};

/// The longest input line read, bytes (16 MiB): a longer one is an error, not an unbounded read.
pub const MAX_LINE_BYTES: usize = 16 << 20;

/// For each non-blank line of `input`, parse a `T`, apply `f`, and write its result as one JSON
/// line. A line that does not parse, or that `f` rejects, or longer than [`MAX_LINE_BYTES`], ends
/// the run with an error naming it.
pub fn process<T, U, F>(mut input: impl BufRead, mut output: impl Write, mut f: F) -> Result<()>
where
    T: DeserializeOwned,
    U: Serialize,
    F: FnMut(T) -> Result<U>,
{
    let mut buf = Vec::new();
    for lineno in 1.. {
        buf.clear();
        let n = (&mut input)
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut buf)
            .with_context(|| format!("reading line {lineno} of the input"))?;
        if n == 0 {
            break;
        }
        if buf.len() > MAX_LINE_BYTES {
            bail!("line {lineno} is longer than {MAX_LINE_BYTES} bytes; one JSON object per line");
        }
        let line = std::str::from_utf8(&buf).with_context(|| format!("line {lineno} is not UTF-8"))?;
        if line.trim().is_empty() {
            continue;
        }
        let value: T =
            serde_json::from_str(line).with_context(|| format!("line {lineno}: malformed input"))?;
        let out = f(value).with_context(|| format!("line {lineno}"))?;
        serde_json::to_writer(&mut output, &out).context("writing output")?;
        output.write_all(b"\n").context("writing output")?;
    }
    output.flush().context("writing output")?;
    Ok(())
}
