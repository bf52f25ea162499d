//! The import's state: the package, its unpacked FMUs and the components read so far.

use super::error::SspImportError;
use super::xml::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tb_fmi::units::UnitDef;
use tb_fmi::{FmuCache, ModelDescription};

/// What the import understands of the SSD, then turns into a [`SystemFile`].
pub(super) struct Importer<'a> {
    pub(super) ssp: &'a Path,
    pub(super) dir: PathBuf,
    pub(super) cache: &'a FmuCache,
    /// SSD `Units`.
    pub(super) units: Vec<(String, UnitDef)>,
}

/// A component: its FMU (archive entry and loaded description) and declared connectors.
pub(super) struct Component {
    pub(super) name: String,
    pub(super) fmu_key: String,
    pub(super) entry: String,
    pub(super) md: ModelDescription,
    /// `implementation="CoSimulation"` or `"ModelExchange"` (None: "any").
    pub(super) interface: Option<tb_fmi::Interface>,
    /// Connector name -> (declared unit, line).
    pub(super) connectors: BTreeMap<String, (Option<String>, usize)>,
}

/// The components' names, for a message naming a missing one.
pub(super) fn component_names(components: &[Component]) -> String {
    components
        .iter()
        .map(|c| c.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

impl Importer<'_> {
    pub(super) fn invalid(
        &self,
        file: &str,
        line: usize,
        message: impl Into<String>,
    ) -> SspImportError {
        SspImportError::Invalid {
            ssp: self.ssp.to_path_buf(),
            file: file.to_string(),
            line,
            message: message.into(),
        }
    }

    pub(super) fn unsupported(&self, file: &str, node: &Node, supported: &str) -> SspImportError {
        SspImportError::Unsupported {
            ssp: self.ssp.to_path_buf(),
            file: file.to_string(),
            line: node.line,
            element: node.name.clone(),
            supported: supported.to_string(),
        }
    }

    /// The children of `node`, each one of `allowed` (in an SSP namespace) or `ignored`
    /// (graphical, without effect on a run); `Annotations` are always allowed. Anything else
    /// is refused, naming what `node` may contain.
    pub(super) fn children<'n>(
        &self,
        file: &str,
        node: &'n Node,
        allowed: &[&str],
        ignored: &[&str],
    ) -> Result<Vec<&'n Node>, SspImportError> {
        let mut out = Vec::new();
        for c in &node.children {
            if c.is_ssp() && (c.name == "Annotations" || ignored.contains(&c.name.as_str())) {
                continue;
            }
            if c.is_ssp() && allowed.contains(&c.name.as_str()) {
                out.push(c);
                continue;
            }
            return Err(self.unsupported(
                file,
                c,
                &format!(
                    "<{}> may contain {}",
                    node.name,
                    if allowed.is_empty() {
                        "annotations only".to_string()
                    } else {
                        allowed
                            .iter()
                            .map(|a| format!("<{a}>"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    }
                ),
            ));
        }
        Ok(out)
    }

    /// An XML file of the package by its relative URI (no scheme, inside the package).
    pub(super) fn read_entry(
        &self,
        from: &str,
        line: usize,
        uri: &str,
    ) -> Result<PathBuf, SspImportError> {
        let rel = uri.strip_prefix("./").unwrap_or(uri);
        if rel.is_empty()
            || rel.contains(':')
            || rel.starts_with('/')
            || rel.split(['/', '\\']).any(|c| c == "..")
        {
            return Err(self.invalid(
                from,
                line,
                format!(
                    "'{uri}' is not a relative path inside the package (URIs with a scheme, absolute paths and '..' are not supported)"
                ),
            ));
        }
        Ok(self.dir.join(rel))
    }

    pub(super) fn read_xml(&self, file: &str, path: &Path) -> Result<Node, SspImportError> {
        let package = |message: String| SspImportError::Package {
            ssp: self.ssp.to_path_buf(),
            message,
        };
        let meta =
            std::fs::metadata(path).map_err(|_| package(format!("the package has no {file}")))?;
        if !meta.is_file() || meta.len() > MAX_XML_BYTES {
            return Err(package(format!(
                "{file} is not a regular file of at most {} MiB",
                MAX_XML_BYTES >> 20
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| package(format!("cannot read {file}: {e}")))?;
        let text = String::from_utf8(bytes).map_err(|e| {
            let valid = e.utf8_error().valid_up_to();
            SspImportError::Xml {
                ssp: self.ssp.to_path_buf(),
                file: file.to_string(),
                line: 1 + e.as_bytes()[..valid]
                    .iter()
                    .filter(|&&b| b == b'\n')
                    .count(),
                message: format!("not UTF-8 (byte {valid})"),
            }
        })?;
        parse_xml(&text, self.ssp, file)
    }

    /// A unit's definition: the SSD's `Units`, then the FMU's, then twinbench's table.
    pub(super) fn unit_md(&self, md: &ModelDescription) -> ModelDescription {
        ModelDescription {
            units: self
                .units
                .iter()
                .cloned()
                .chain(md.units.iter().cloned())
                .collect(),
            ..Default::default()
        }
    }

    pub(super) fn f64_attr(
        &self,
        file: &str,
        node: &Node,
        name: &str,
    ) -> Result<Option<f64>, SspImportError> {
        node.attr(name)
            .map(|v| {
                parse_double(v).ok_or_else(|| {
                    self.invalid(
                        file,
                        node.line,
                        format!("<{}> {name}=\"{v}\" is not a number", node.name),
                    )
                })
            })
            .transpose()
    }
}
