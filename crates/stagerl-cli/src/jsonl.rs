//! JSON-lines plumbing shared by the inspection commands: read one object per line, answer one
//! line per input, stop at the first bad line with its number.

use anyhow::{Context, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::io::{BufRead, Write};

/// For each non-blank line of `input`, parse a `T`, apply `f`, and write its result as one JSON
/// line. A line that does not parse, or that `f` rejects, ends the run with an error naming it.
pub fn process<T, U, F>(input: impl BufRead, mut output: impl Write, mut f: F) -> Result<()>
where
    T: DeserializeOwned,
    U: Serialize,
    F: FnMut(T) -> Result<U>,
{
    for (i, line) in input.lines().enumerate() {
        let lineno = i + 1;
        let line = line.with_context(|| format!("reading line {lineno} of the input"))?;
        if line.trim().is_empty() {
            continue;
        }
        let value: T =
            serde_json::from_str(&line).with_context(|| format!("line {lineno}: malformed input"))?;
        let out = f(value).with_context(|| format!("line {lineno}"))?;
        serde_json::to_writer(&mut output, &out).context("writing output")?;
        output.write_all(b"\n").context("writing output")?;
    }
    output.flush().context("writing output")?;
    Ok(())
}
