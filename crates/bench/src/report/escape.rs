//! Text made safe for an HTML page (the report's page and its figures).

/// Text for HTML, in an element or an attribute.
pub use tb_files::markup::html_escape as esc;
