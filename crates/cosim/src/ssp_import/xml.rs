//! The package's XML as a tree of elements with their lines, and its number and boolean
//! literals.

use super::error::SspImportError;
use std::path::Path;

pub const NS_SSD: &str = crate::ssp::NS_SSD;

pub const NS_SSC: &str = crate::ssp::NS_SSC;

pub const NS_SSV: &str = crate::ssp::NS_SSV;

pub(super) const NS_OSP: &str = "http://opensimulationplatform.com/SSP/OSPAnnotations";

pub(super) const NS_TB: &str = "https://github.com/twinbench/ssp";

pub(super) const SSD: &str = "SystemStructure.ssd";

/// The deepest element nesting read (an SSD needs about ten levels; the tree is dropped
/// recursively).
pub(super) const MAX_DEPTH: usize = 256;

/// The largest SSD or SSV read (as for a modelDescription.xml).
pub(super) const MAX_XML_BYTES: u64 = tb_fmi::import::archive::MAX_DESCRIPTION_BYTES;

/// One XML element: namespace, local name, attributes (unprefixed), children, line.
#[derive(Debug)]
pub(super) struct Node {
    pub(super) ns: String,
    pub(super) name: String,
    pub(super) attrs: Vec<(String, String)>,
    pub(super) children: Vec<Node>,
    pub(super) line: usize,
}

impl Node {
    pub(super) fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
    pub(super) fn is_ssp(&self) -> bool {
        self.ns == NS_SSD || self.ns == NS_SSC || self.ns == NS_SSV
    }
}

/// Line numbers of positions in a text, counted on from the last position asked for:
/// positions come in order while parsing, so the whole count stays linear in the text's
/// size (counting from the start each time made a file of many small elements quadratic).
pub(super) struct Lines<'t> {
    pub(super) text: &'t [u8],
    pub(super) pos: usize,
    pub(super) line: usize,
    /// Bytes looked at so far (the work done: the text's size when asked in order).
    pub(super) scanned: usize,
}

impl<'t> Lines<'t> {
    pub(super) fn new(text: &'t str) -> Self {
        Lines {
            text: text.as_bytes(),
            pos: 0,
            line: 1,
            scanned: 0,
        }
    }

    pub(super) fn at(&mut self, pos: u64) -> usize {
        let pos = (pos as usize).min(self.text.len());
        if pos < self.pos {
            // Backwards (an error position before the last element): count afresh.
            self.pos = 0;
            self.line = 1;
        }
        self.line += self.text[self.pos..pos]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.scanned += pos - self.pos;
        self.pos = pos;
        self.line
    }
}

/// A namespace prefix used without a declaration.
#[derive(Debug)]
pub(super) struct Undeclared(String);

/// A resolved namespace (empty: none), or the undeclared prefix.
pub(super) fn ns_uri(ns: quick_xml::name::ResolveResult<'_>) -> Result<String, Undeclared> {
    use quick_xml::name::ResolveResult;
    match ns {
        ResolveResult::Bound(n) => Ok(String::from_utf8_lossy(n.as_ref()).into_owned()),
        ResolveResult::Unbound => Ok(String::new()),
        ResolveResult::Unknown(p) => Err(Undeclared(String::from_utf8_lossy(&p).into_owned())),
    }
}

/// Parse an XML document into a tree (namespaces resolved).
pub(super) fn parse_xml(text: &str, ssp: &Path, file: &str) -> Result<Node, SspImportError> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::NsReader::from_str(text);
    let xml_err = |line: usize, message: String| SspImportError::Xml {
        ssp: ssp.to_path_buf(),
        file: file.to_string(),
        line,
        message,
    };
    let mut stack: Vec<Node> = Vec::new();
    let mut root: Option<Node> = None;
    let mut lines = Lines::new(text);
    loop {
        let start = reader.buffer_position();
        let (ns, ev) = match reader.read_resolved_event() {
            Ok((ns, ev)) => (ns_uri(ns), ev),
            Err(e) => {
                let message = e.to_string();
                return Err(xml_err(lines.at(reader.error_position()), message));
            }
        };
        let (e, empty) = match ev {
            Event::Start(e) => (e, false),
            Event::Empty(e) => (e, true),
            Event::End(_) => {
                let Some(node) = stack.pop() else {
                    return Err(xml_err(
                        lines.at(start),
                        "an end tag without its start".into(),
                    ));
                };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(node),
                    None => root = Some(node),
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let line = lines.at(start);
        if root.is_some() && stack.is_empty() {
            return Err(xml_err(line, "content after the root element".into()));
        }
        let ns =
            ns.map_err(|p| xml_err(line, format!("namespace prefix '{}' is not declared", p.0)))?;
        let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
        let mut attrs = Vec::new();
        for a in e.attributes() {
            let a = a.map_err(|err| xml_err(line, err.to_string()))?;
            let key = a.key;
            if key.as_namespace_binding().is_some() {
                continue;
            }
            let value = a
                .decode_and_unescape_value(reader.decoder())
                .map_err(|err| xml_err(line, err.to_string()))?
                .into_owned();
            attrs.push((
                String::from_utf8_lossy(key.local_name().as_ref()).into_owned(),
                value,
            ));
        }
        let node = Node {
            ns,
            name,
            attrs,
            children: Vec::new(),
            line,
        };
        if empty {
            match stack.last_mut() {
                Some(parent) => parent.children.push(node),
                None => root = Some(node),
            }
        } else {
            if stack.len() >= MAX_DEPTH {
                return Err(xml_err(
                    line,
                    format!("elements nested deeper than {MAX_DEPTH} levels"),
                ));
            }
            stack.push(node);
        }
    }
    if let Some(open) = stack.last() {
        return Err(xml_err(
            lines.at(text.len() as u64),
            format!(
                "unexpected end of the file: <{}> (line {}) is not closed",
                open.name, open.line
            ),
        ));
    }
    root.ok_or_else(|| xml_err(1, "no root element".into()))
}

/// xs:double text (INF, -INF, NaN as the schema writes them).
pub(super) fn parse_double(s: &str) -> Option<f64> {
    match s.trim() {
        "INF" => Some(f64::INFINITY),
        "-INF" => Some(f64::NEG_INFINITY),
        "NaN" => Some(f64::NAN),
        t if t.eq_ignore_ascii_case("inf") || t.eq_ignore_ascii_case("nan") => None,
        t => t.parse().ok(),
    }
}

pub(super) fn parse_bool(s: &str) -> Option<bool> {
    match s.trim() {
        "true" | "1" => Some(true),
        "false" | "0" => Some(false),
        _ => None,
    }
}

#[cfg(test)]
mod lines_tests {
    use super::Lines;

    /// N10: 250,000 empty elements, their line numbers asked in order as the parser asks
    /// them: right, and each byte looked at once (counting from the start every time looked
    /// at 3·10^10 bytes and took 48 s).
    #[test]
    fn line_numbers_are_counted_on_in_linear_work() {
        let text = "<a/>\n".repeat(250_000);
        let mut lines = Lines::new(&text);
        for k in 0..250_000usize {
            assert_eq!(lines.at((k * 5) as u64), k + 1);
        }
        assert_eq!(lines.scanned, text.len() - 5);
        // Backwards (an error before the last position): counted afresh, still right.
        assert_eq!(lines.at(12), 3);
    }
}
