//! Text made safe for XML and HTML, in an element or an attribute: one escaping for the
//! model descriptions, the SSP files and the report's page.

/// Text for XML (`'` as `&apos;`).
pub fn xml_escape(s: &str) -> String {
    escape(s, "&apos;")
}

/// Text for HTML (`'` as `&#39;`, which HTML 4 also knows).
pub fn html_escape(s: &str) -> String {
    escape(s, "&#39;")
}

fn escape(s: &str, apostrophe: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str(apostrophe),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_five_characters_are_escaped_and_nothing_else() {
        let text = r#"a<b & "c" > 'd' é"#;
        assert_eq!(
            xml_escape(text),
            "a&lt;b &amp; &quot;c&quot; &gt; &apos;d&apos; é"
        );
        assert_eq!(
            html_escape(text),
            "a&lt;b &amp; &quot;c&quot; &gt; &#39;d&#39; é"
        );
    }
}
