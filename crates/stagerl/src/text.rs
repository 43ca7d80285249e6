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

#[cfg(test)]
mod tests {
    use super::*;

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
