//! Quoting user input in messages without echoing all of it.

/// Characters of an input quoted in a message before it is cut.
pub const EXCERPT_CHARS: usize = 80;

/// `s` whole when it is at most [`EXCERPT_CHARS`] characters, otherwise its first
/// [`EXCERPT_CHARS`] characters, `...` and its full size: a message quoting a 100 MB input stays
/// short.
pub fn excerpt(s: &str) -> String {
    match s.char_indices().nth(EXCERPT_CHARS) {
        None => s.to_string(),
        Some((cut, _)) => format!("{}... ({} bytes)", &s[..cut], s.len()),
    }
}

/// Longest line [`bound_message`] leaves whole, characters.
pub const MAX_LINE_CHARS: usize = 400;

/// `msg` with every quoted part (between backticks or double quotes) longer than
/// [`EXCERPT_CHARS`] replaced by its [`excerpt`], and every line still longer than
/// [`MAX_LINE_CHARS`] cut in the middle: an error that echoes a 100 MB input stays short.
pub fn bound_message(msg: &str) -> String {
    msg.split('\n').map(bound_line).collect::<Vec<_>>().join("\n")
}

fn bound_line(line: &str) -> String {
    let mut out = String::with_capacity(line.len().min(4 * MAX_LINE_CHARS));
    let mut rest = line;
    while let Some(open) = rest.find(['`', '"']) {
        let quote = rest.as_bytes()[open];
        out.push_str(&rest[..=open]);
        let after = &rest[open + 1..];
        match closing_quote(after, quote) {
            Some(close) => {
                out.push_str(&excerpt(&after[..close]));
                out.push(quote as char);
                rest = &after[close + 1..];
            }
            None => {
                rest = after;
            }
        }
    }
    out.push_str(rest);
    match out.char_indices().nth(MAX_LINE_CHARS) {
        None => out,
        Some(_) => {
            let chars: Vec<(usize, char)> = out.char_indices().collect();
            let head = chars[MAX_LINE_CHARS / 2].0;
            let tail = chars[chars.len() - MAX_LINE_CHARS / 4].0;
            format!("{} ... ({} bytes) ... {}", &out[..head], out.len(), &out[tail..])
        }
    }
}

/// The byte offset of the `quote` closing a quoted part that starts `s` (a backslash escapes the
/// next character inside double quotes).
fn closing_quote(s: &str, quote: u8) -> Option<usize> {
    let b = s.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'\\' && quote == b'"' {
            i += 2;
            continue;
        }
        if b[i] == quote {
            return Some(i);
        }
        i += 1;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_quoted_parts_and_lines_are_cut() {
        let long = "x".repeat(1_000_000);
        let m = bound_message(&format!("unknown field `{long}`, expected `joints` at line 1"));
        assert_eq!(
            m,
            format!("unknown field `{}... (1000000 bytes)`, expected `joints` at line 1", "x".repeat(80))
        );
        let m = bound_message(&format!("invalid type: string \"a\\\"{long}\", expected a sequence"));
        assert!(m.len() < 200 && m.ends_with("bytes)\", expected a sequence"), "{m}");
        let m = bound_message(&format!("TOML parse error at line 2\n2 | x = {long}\n  | ^\nend"));
        let lines: Vec<&str> = m.lines().collect();
        assert_eq!(lines.len(), 4);
        assert!(lines[1].starts_with("2 | x = xxx") && lines[1].contains("... (1000008 bytes) ..."), "{m}");
        assert!(lines[1].len() < MAX_LINE_CHARS + 100);
        assert_eq!(lines[3], "end");
        // Short messages are unchanged; a lone quote is no quote.
        let short = "line 3: `q` has 3 values, expected 6; it's \"fine\" ` unmatched";
        assert_eq!(bound_message(short), short);
    }

    #[test]
    fn short_whole_long_cut_with_size() {
        assert_eq!(excerpt("abc"), "abc");
        let exact = "x".repeat(EXCERPT_CHARS);
        assert_eq!(excerpt(&exact), exact);
        let long = "é".repeat(1000);
        let e = excerpt(&long);
        assert_eq!(e, format!("{}... (2000 bytes)", "é".repeat(EXCERPT_CHARS)));
    }
}
