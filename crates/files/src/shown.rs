//! What a message may show of text it did not write: a field of a user's file, a path
//! parameter's value, an FMU's log message. Cut to a length a terminal can take, with the
//! cut said; control characters (a terminal's escape sequences, carriage returns) shown
//! as escapes, never sent to the terminal.

/// `text` for a message: at most `max_chars` characters (then `… (N more bytes)`), each
/// control character escaped (`\u{1b}`), line breaks kept only when `lines` is true.
pub fn shown(text: &str, max_chars: usize, lines: bool) -> String {
    let mut out = String::with_capacity(text.len().min(max_chars * 4 + 32));
    for (count, (i, c)) in text.char_indices().enumerate() {
        if count == max_chars {
            out.push_str(&format!("… ({} more bytes)", text.len() - i));
            return out;
        }
        match c {
            '\n' if lines => out.push(c),
            '\t' => out.push(c),
            c if c.is_control() => out.extend(c.escape_unicode()),
            c => out.push(c),
        }
    }
    out
}

/// A number a user gave, for a message: as written for ordinary sizes (`0.5`, `200`), in
/// exponent form for huge or tiny ones (`1e308`, not 309 digits; `5e-324`, not 324 zeros).
pub fn number(x: f64) -> String {
    let a = x.abs();
    if x != 0.0 && a.is_finite() && !(1e-5..1e15).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// A short excerpt of a field or a value (one line, 60 characters).
pub fn excerpt(text: &str) -> String {
    shown(text, 60, false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_read_as_written_and_huge_ones_short() {
        assert_eq!(number(0.5), "0.5");
        assert_eq!(number(200.0), "200");
        assert_eq!(number(1e308), "1e308");
        assert_eq!(number(5e-324), "5e-324");
        assert_eq!(number(f64::NAN), "NaN");
    }

    #[test]
    fn control_characters_are_escaped_and_long_text_cut() {
        assert_eq!(shown("ok\tfine", 10, false), "ok\tfine");
        assert_eq!(shown("\u{1b}[31mred", 20, false), "\\u{1b}[31mred");
        assert_eq!(shown("a\nb\rc", 20, false), "a\\u{a}b\\u{d}c");
        assert_eq!(shown("a\nb", 20, true), "a\nb");
        assert_eq!(shown("abcdef", 3, false), "abc… (3 more bytes)");
        assert_eq!(
            excerpt(&"x".repeat(100_000_000)).len(),
            60 + "… (99999940 more bytes)".len()
        );
    }
}
