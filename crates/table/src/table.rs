//! The column table of `f64`, read from and written to CSV.
//!
//! Format: one header row of column names; optionally a units row right after it (detected:
//! a row in which no field is a number, where the dimensionless unit `1` and empty fields
//! are allowed); then one record per line, every field a number. The separator is the
//! header's: a comma, else a semicolon, else a tab. Fields are trimmed and may be wrapped in
//! double quotes (no quoted separators: these are numeric files); CRLF and a UTF-8 BOM are
//! accepted; blank lines and lines starting with `#` are skipped, and line numbers in errors
//! count them, so they point at the line an editor shows. `NaN` and `inf` parse (as Rust's
//! `f64` parser reads them): rejecting them is the job of whoever knows which columns matter.
//!
//! Columns are looked up by exact name, or else by the part after the last `.`, so that a
//! signal requested as `Fz_rl` is found as `vehicle.Fz_rl` in a twinbench result file.

use crate::error::{Result, TableError as Error};
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// Column-major table of numbers with the provenance needed for error messages.
#[derive(Debug, Clone)]
pub struct Table {
    source: String,
    names: Vec<String>,
    units: Option<Vec<String>>,
    /// The numbers of every column (NaN in a text column).
    columns: Vec<Vec<f64>>,
    /// The strings of a text column (a String signal, a label in a logger's file); `None`
    /// for a column of numbers.
    text: Vec<Option<Vec<String>>>,
    /// 1-based line of each record in the file; `None` for an in-memory table.
    lines: Option<Vec<u64>>,
}

impl Table {
    /// An in-memory table (e.g. a simulation result the orchestrator holds). `source` labels
    /// it in error messages; rows are reported as the line they would have in a CSV file with
    /// one header row (row index + 2).
    pub fn from_columns(
        source: impl Into<String>,
        names: Vec<String>,
        columns: Vec<Vec<f64>>,
    ) -> Result<Self> {
        let source = source.into();
        same_count(&source, (names.len(), "names"), (columns.len(), "columns"))?;
        let len = columns.first().map_or(0, Vec::len);
        if let Some((i, c)) = columns.iter().enumerate().find(|(_, c)| c.len() != len) {
            return Err(Error::Shape(format!(
                "{source}: column `{}` has {} rows, the first has {len}",
                names[i],
                c.len()
            )));
        }
        check_duplicates(&source, &names)?;
        Ok(Self {
            source,
            text: vec![None; names.len()],
            names,
            units: None,
            columns,
            lines: None,
        })
    }

    /// An empty table with these columns and units (a recording to be filled row by row).
    pub fn new(source: impl Into<String>, names: Vec<String>, units: Vec<String>) -> Result<Self> {
        let source = source.into();
        same_count(&source, (names.len(), "names"), (units.len(), "units"))?;
        check_duplicates(&source, &names)?;
        Ok(Self {
            source,
            columns: vec![Vec::new(); names.len()],
            text: vec![None; names.len()],
            names,
            units: Some(units),
            lines: None,
        })
    }

    /// The same table with a units row (one unit per column).
    pub fn with_units(mut self, units: Vec<String>) -> Result<Self> {
        same_count(
            &self.source,
            (units.len(), "units"),
            (self.names.len(), "columns"),
        )?;
        self.units = Some(units);
        Ok(self)
    }

    /// Reads a CSV file.
    pub fn read_path(path: impl AsRef<Path>) -> Result<Self> {
        Self::read_path_keeping(path, &|_, _| true)
    }

    /// Reads a CSV file, parsing only the columns `keep(index, name)` accepts; the others
    /// are kept as text, whatever they hold (an input file's unused columns must not fail it).
    pub fn read_path_keeping(
        path: impl AsRef<Path>,
        keep: &dyn Fn(usize, &str) -> bool,
    ) -> Result<Self> {
        let path = path.as_ref();
        // A regular file within the data limit, read no further than that.
        let (file, _) =
            tb_files::input::open(path, tb_files::Limit::DATA).map_err(|source| Error::Io {
                path: path.to_path_buf(),
                source,
            })?;
        use std::io::Read as _;
        Self::from_reader_keeping(
            std::io::BufReader::new(file.take(tb_files::Limit::DATA.bytes)),
            &path.display().to_string(),
            keep,
        )
    }

    /// Reads CSV from any reader; `source` names it in error messages.
    pub fn from_reader<R: Read>(reader: R, source: &str) -> Result<Self> {
        Self::from_reader_keeping(reader, source, &|_, _| true)
    }

    /// [`Table::from_reader`], parsing only the columns `keep` accepts.
    pub fn from_reader_keeping<R: Read>(
        reader: R,
        source: &str,
        keep: &dyn Fn(usize, &str) -> bool,
    ) -> Result<Self> {
        let mut file = Lines::new(reader, source);
        let mut line = String::new();
        let (sep, names) = read_header(&mut file, &mut line, source)?;
        let ncol = names.len();
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); ncol];
        let mut text: Vec<Option<Vec<String>>> = names
            .iter()
            .enumerate()
            .map(|(k, n)| (!keep(k, n)).then(Vec::new))
            .collect();
        let mut lines = Vec::new();
        let mut units = None;
        let mut first = true;
        let mut row_fields: Vec<String> = Vec::with_capacity(ncol);
        while let Some(row) = file.next(&mut line)? {
            split_record(&line, sep, row, ncol, &mut row_fields, source)?;
            if first {
                first = false;
                if is_units_row(&row_fields) {
                    units = Some(row_fields.clone());
                    continue;
                }
            }
            if lines.is_empty() {
                mark_text_columns(&row_fields, &mut text);
            }
            push_record(&row_fields, row, &names, &mut text, &mut columns, source)?;
            lines.push(row);
        }
        if lines.is_empty() {
            return Err(Error::Empty {
                file: source.into(),
                what: "no data rows after the header",
            });
        }
        Ok(Self {
            source: source.into(),
            names,
            units,
            columns,
            text,
            lines: Some(lines),
        })
    }

    /// Appends one row (one value per column, in column order).
    #[inline]
    pub fn push_row(&mut self, row: impl IntoIterator<Item = f64>) {
        for (c, x) in self.columns.iter_mut().zip(row) {
            c.push(x);
        }
    }

    /// Appends a string to text column `index` (see [`Table::set_text`]); its number is NaN.
    pub fn push_text(&mut self, index: usize, value: &str) {
        if let Some(t) = &mut self.text[index] {
            t.push(value.to_string());
        }
    }

    /// Makes column `index` a text column (empty; a recording fills it row by row).
    pub fn set_text(&mut self, index: usize) {
        self.text[index] = Some(Vec::new());
    }

    /// Whether column `index` holds text.
    pub fn is_text(&self, index: usize) -> bool {
        self.text[index].is_some()
    }

    /// The strings of text column `index`.
    pub fn text_at(&self, index: usize) -> Option<&[String]> {
        self.text[index].as_deref()
    }

    /// Removes every row (keeps names, units and capacity).
    pub fn clear(&mut self) {
        for c in &mut self.columns {
            c.clear();
        }
        for t in self.text.iter_mut().flatten() {
            t.clear();
        }
        self.lines = None;
    }

    /// Keeps the first `rows` rows.
    pub fn truncate(&mut self, rows: usize) {
        for c in &mut self.columns {
            c.truncate(rows);
        }
        for t in self.text.iter_mut().flatten() {
            t.truncate(rows);
        }
        if let Some(l) = &mut self.lines {
            l.truncate(rows);
        }
    }

    /// Renames column `index` (an error if the new name is taken).
    pub fn rename(&mut self, index: usize, name: &str) -> Result<()> {
        if self
            .names
            .iter()
            .enumerate()
            .any(|(i, n)| i != index && n == name)
        {
            return Err(Error::DuplicateColumn {
                file: self.source.clone(),
                column: name.to_string(),
            });
        }
        self.names[index] = name.to_string();
        Ok(())
    }

    /// Renames several columns at once (`(index, new name)`), checking once that the names
    /// stay unique: linear in the columns, where a `rename` each is quadratic.
    pub fn rename_many(&mut self, renames: &[(usize, String)]) -> Result<()> {
        let mut names = self.names.clone();
        for (i, n) in renames {
            names[*i] = n.clone();
        }
        check_duplicates(&self.source, &names)?;
        self.names = names;
        Ok(())
    }

    /// The numbers of column `index`, to change in place (same length).
    pub fn values_mut(&mut self, index: usize) -> &mut [f64] {
        &mut self.columns[index]
    }

    /// Sets the unit of column `index` (a units row is added if there was none).
    pub fn set_unit(&mut self, index: usize, unit: &str) {
        let n = self.names.len();
        let units = self.units.get_or_insert_with(|| vec![String::new(); n]);
        units[index] = unit.to_string();
    }

    /// Every column, in order.
    pub fn columns(&self) -> &[Vec<f64>] {
        &self.columns
    }

    /// The table as CSV: header, units row (when known), then the values in shortest
    /// round-trip text (reading the file back gives the same bits).
    pub fn to_csv(&self) -> Vec<u8> {
        use std::fmt::Write as _;
        let mut out = String::with_capacity(self.len() * self.names.len() * 12 + 256);
        out.push_str(
            &self
                .names
                .iter()
                .map(|n| quote_if_needed(n))
                .collect::<Vec<_>>()
                .join(","),
        );
        out.push('\n');
        if let Some(u) = &self.units {
            let quoted: Vec<String> = u.iter().map(|n| quote_if_needed(n)).collect();
            out.push_str(&quoted.join(","));
            out.push('\n');
        }
        for r in 0..self.len() {
            for (k, c) in self.columns.iter().enumerate() {
                if k > 0 {
                    out.push(',');
                }
                match &self.text[k] {
                    // Text is always quoted ("" inside), so it can hold separators.
                    Some(t) => {
                        out.push('"');
                        out.push_str(&t.get(r).map_or(String::new(), |x| x.replace('"', "\"\"")));
                        out.push('"');
                    }
                    None => {
                        let _ = write!(out, "{}", c[r]);
                    }
                }
            }
            out.push('\n');
        }
        out.into_bytes()
    }

    /// Writes [`Table::to_csv`] atomically: nothing half-written is ever visible at `path`.
    pub fn write_csv(&self, path: &Path) -> std::io::Result<()> {
        crate::write_atomic(path, &self.to_csv())
    }

    /// The file path or label this table came from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Column names in file order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The units row, if the file had one.
    pub fn units(&self) -> Option<&[String]> {
        self.units.as_deref()
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    /// True when the table has no data rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The 1-based line in the file of data row `index` (row index + 2 for in-memory tables).
    pub fn line_of(&self, index: usize) -> u64 {
        match &self.lines {
            Some(l) => l[index],
            None => index as u64 + 2,
        }
    }

    /// Index of a column: the exact name, or else the unique column whose name ends in
    /// `.name`. `Ok(None)` when absent; an error when several columns match.
    pub fn find(&self, name: &str) -> Result<Option<usize>> {
        if let Some(i) = self.names.iter().position(|n| n == name) {
            return Ok(Some(i));
        }
        let mut hits = self.names.iter().enumerate().filter(|(_, n)| {
            n.len() > name.len() + 1
                && n.ends_with(name)
                && n.as_bytes()[n.len() - name.len() - 1] == b'.'
        });
        let first = hits.next();
        match (first, hits.next()) {
            (None, _) => Ok(None),
            (Some((i, _)), None) => Ok(Some(i)),
            (Some(_), Some(_)) => Err(Error::AmbiguousColumn {
                file: self.source.clone(),
                column: name.into(),
                candidates: self
                    .names
                    .iter()
                    .filter(|n| n.ends_with(&format!(".{name}")))
                    .map(|n| format!("`{n}`"))
                    .collect::<Vec<_>>()
                    .join(", "),
            }),
        }
    }

    /// The numbers of column `name` (see [`Table::find`]), if present; a text column is an
    /// error naming its first value.
    pub fn column(&self, name: &str) -> Result<Option<&[f64]>> {
        match self.find(name)? {
            Some(i) => self.numbers(i).map(Some),
            None => Ok(None),
        }
    }

    /// The numbers of column `name`, or a [`Error::MissingColumn`].
    pub fn require(&self, name: &str) -> Result<&[f64]> {
        let i = self.require_index(name)?;
        self.numbers(i)
    }

    /// The numbers of column `i`; a text column is an error naming its first value.
    fn numbers(&self, i: usize) -> Result<&[f64]> {
        match &self.text[i] {
            None => Ok(&self.columns[i]),
            Some(t) => Err(Error::Malformed {
                file: self.source.clone(),
                row: if t.is_empty() { 0 } else { self.line_of(0) },
                column: self.names[i].clone(),
                value: t.first().map(|v| tb_files::excerpt(v)).unwrap_or_default(),
            }),
        }
    }

    /// Index of the column `name`, or a [`Error::MissingColumn`].
    pub fn require_index(&self, name: &str) -> Result<usize> {
        self.find(name)?.ok_or_else(|| Error::MissingColumn {
            file: self.source.clone(),
            column: name.into(),
            available: self.names.join(", "),
        })
    }

    /// Column by index.
    pub fn column_at(&self, index: usize) -> &[f64] {
        &self.columns[index]
    }

    /// Name of the column at `index`.
    pub fn name_at(&self, index: usize) -> &str {
        &self.names[index]
    }

    /// Appends a column (same length as the others).
    pub fn push_column(&mut self, name: impl Into<String>, values: Vec<f64>) -> Result<()> {
        let name = name.into();
        if !self.names.is_empty() && values.len() != self.len() {
            return Err(Error::Shape(format!(
                "{}: new column `{name}` has {} rows, the table {}",
                self.source,
                values.len(),
                self.len()
            )));
        }
        if self.names.contains(&name) {
            return Err(Error::DuplicateColumn {
                file: self.source.clone(),
                column: name,
            });
        }
        self.names.push(name);
        if let Some(u) = &mut self.units {
            u.push(String::new());
        }
        self.columns.push(values);
        self.text.push(None);
        Ok(())
    }

    /// First non-finite value of column `index`, as an error naming its line.
    pub fn check_finite(&self, index: usize) -> Result<()> {
        match self.columns[index].iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(i) => Err(self.non_finite(index, i)),
        }
    }

    /// The error for the non-finite value at (`col`, `row`).
    pub fn non_finite(&self, col: usize, row: usize) -> Error {
        Error::NonFinite {
            file: self.source.clone(),
            row: self.line_of(row),
            column: self.names[col].clone(),
            value: self.columns[col][row],
        }
    }
}

/// The lines of a CSV file as the table reads them: blank lines and `#` comments skipped,
/// each line trimmed of its terminator (and the first of a UTF-8 BOM), and numbered as an
/// editor shows them (the skipped lines counted) so that errors point at the right line.
struct Lines<'s, R> {
    rdr: BufReader<R>,
    lineno: u64,
    source: &'s str,
}

impl<'s, R: Read> Lines<'s, R> {
    fn new(reader: R, source: &'s str) -> Self {
        Lines {
            rdr: BufReader::new(reader),
            lineno: 0,
            source,
        }
    }

    /// The next non-blank line, trimmed of its terminator, into `line`, and its 1-based
    /// number; `None` at the end of the file.
    fn next(&mut self, line: &mut String) -> Result<Option<u64>> {
        loop {
            line.clear();
            let n = self.rdr.read_line(line).map_err(|e| Error::Io {
                path: self.source.into(),
                source: e,
            })?;
            if n == 0 {
                return Ok(None);
            }
            self.lineno += 1;
            let t = line.trim_end_matches(['\n', '\r']);
            let t = if self.lineno == 1 {
                t.trim_start_matches('\u{feff}')
            } else {
                t
            };
            if !t.trim().is_empty() && !t.trim_start().starts_with('#') {
                *line = t.to_owned();
                return Ok(Some(self.lineno));
            }
        }
    }
}

/// The header row: the separator it uses and the column names (no name twice). A file
/// without one is empty.
fn read_header<R: Read>(
    file: &mut Lines<'_, R>,
    line: &mut String,
    source: &str,
) -> Result<(char, Vec<String>)> {
    if file.next(line)?.is_none() {
        return Err(Error::Empty {
            file: source.into(),
            what: "no header row",
        });
    }
    let sep = separator(line);
    let names: Vec<String> = fields(line, sep).collect();
    check_duplicates(source, &names)?;
    Ok((sep, names))
}

/// The fields of the record on line `row` into `row_fields`: as many as the header has
/// columns, else the row is ragged.
fn split_record(
    line: &str,
    sep: char,
    row: u64,
    ncol: usize,
    row_fields: &mut Vec<String>,
    source: &str,
) -> Result<()> {
    row_fields.clear();
    row_fields.extend(fields(line, sep));
    let found = row_fields.len();
    if found != ncol {
        return Err(Error::RaggedRow {
            file: source.into(),
            row,
            expected: ncol,
            found,
        });
    }
    Ok(())
}

/// On the first record: a column whose first value is words, not a number, holds text.
fn mark_text_columns(row_fields: &[String], text: &mut [Option<Vec<String>>]) {
    for (j, f) in row_fields.iter().enumerate() {
        if f.parse::<f64>().is_err() && is_words(f) {
            text[j] = Some(Vec::new());
        }
    }
}

/// One record's fields appended to the columns: a text column keeps the string (its
/// number NaN), any other must hold a number (else the line `row` is malformed).
fn push_record(
    row_fields: &[String],
    row: u64,
    names: &[String],
    text: &mut [Option<Vec<String>>],
    columns: &mut [Vec<f64>],
    source: &str,
) -> Result<()> {
    for (j, field) in row_fields.iter().enumerate() {
        if let Some(t) = &mut text[j] {
            t.push(field.clone());
            columns[j].push(f64::NAN);
            continue;
        }
        let v: f64 = field.parse().map_err(|_| Error::Malformed {
            file: source.into(),
            row,
            column: names[j].clone(),
            value: tb_files::excerpt(field),
        })?;
        columns[j].push(v);
    }
    Ok(())
}

fn check_duplicates(source: &str, names: &[String]) -> Result<()> {
    // A set, not a scan of the names before each: a header of a million columns is checked
    // in linear time (M10), and the first repeated name is the one named.
    let mut seen = std::collections::HashSet::with_capacity(names.len());
    for n in names {
        if !seen.insert(n.as_str()) {
            return Err(Error::DuplicateColumn {
                file: source.into(),
                column: n.clone(),
            });
        }
    }
    Ok(())
}

/// The separator of a file, from its header: a comma, else a semicolon, else a tab.
fn separator(header: &str) -> char {
    [',', ';', '\t']
        .into_iter()
        .find(|c| header.contains(*c))
        .unwrap_or(',')
}

/// The fields of a line, trimmed; a field in double quotes may hold the separator and
/// `""` for a quote.
fn fields(line: &str, sep: char) -> impl Iterator<Item = String> + '_ {
    let mut rest = Some(line);
    std::iter::from_fn(move || {
        let r = rest?;
        let t = r.trim_start();
        if let Some(q) = t.strip_prefix('"') {
            let mut value = String::new();
            let mut chars = q.char_indices();
            let mut end = None;
            while let Some((i, c)) = chars.next() {
                if c == '"' {
                    if q[i + 1..].starts_with('"') {
                        value.push('"');
                        chars.next();
                    } else {
                        end = Some(i + 1);
                        break;
                    }
                } else {
                    value.push(c);
                }
            }
            let after = end.map_or("", |e| &q[e..]);
            rest = after.find(sep).map(|k| &after[k + sep.len_utf8()..]);
            return Some(value);
        }
        match r.find(sep) {
            Some(k) => {
                rest = Some(&r[k + sep.len_utf8()..]);
                Some(r[..k].trim().to_string())
            }
            None => {
                rest = None;
                Some(r.trim().to_string())
            }
        }
    })
}

/// A name written to a CSV header: quoted when it holds a separator, a quote or a line break.
fn quote_if_needed(name: &str) -> String {
    if name.contains([',', ';', '\t', '"', '\n', '\r']) {
        format!("\"{}\"", name.replace('"', "\"\""))
    } else {
        name.to_string()
    }
}

/// A field that is words (a label), not a mistyped number: it does not start like a number.
fn is_words(field: &str) -> bool {
    field
        .chars()
        .next()
        .is_some_and(|c| !(c.is_ascii_digit() || "+-.".contains(c)))
}

/// A units row: no field parses as a number, except the dimensionless unit `1`; empty
/// fields allowed; at least one field is not a number.
fn is_units_row(fields: &[String]) -> bool {
    let mut any_text = false;
    for f in fields.iter().map(String::as_str) {
        if f.is_empty() || f == "1" {
            continue;
        }
        if f.parse::<f64>().is_ok() {
            return false;
        }
        any_text = true;
    }
    any_text
}

/// As many of the one (count, what) as of the other, else a shape error that says both.
fn same_count(source: &str, (n, what): (usize, &str), (m, of): (usize, &str)) -> Result<()> {
    if n == m {
        return Ok(());
    }
    Err(Error::Shape(format!("{source}: {n} {what} for {m} {of}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TableError;

    fn parse(s: &str) -> Result<Table> {
        Table::from_reader(s.as_bytes(), "t.csv")
    }

    /// M10: a header of a million columns (about 9 MB) is read and its one repeated name
    /// found in linear time. (The check was quadratic: 20k columns took 0.37 s, a million
    /// many minutes; the deadline here is a hang's, not a benchmark's.)
    #[test]
    fn m10_a_million_columns_are_checked_for_duplicates_in_linear_time() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let n = 1_000_000;
            let mut header: Vec<String> = (0..n).map(|k| format!("c{k}")).collect();
            header[n - 1] = "c17".into();
            let text = format!("{}\n", header.join(","));
            let _ = tx.send(parse(&text).err());
        });
        let e = rx
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("a million columns still being checked after 60 s")
            .expect("a repeated column is refused");
        assert!(
            matches!(&e, TableError::DuplicateColumn { column, .. } if column == "c17"),
            "{e}"
        );
    }

    #[test]
    fn names_and_units_with_separators_or_quotes_round_trip_through_csv() {
        // Variable names come from FMUs: a comma or a quote must not shift the columns.
        let names = vec![
            "time".to_string(),
            "a.x,y".into(),
            "b.\"q\"".into(),
            "c.z".into(),
        ];
        let units = vec!["s".to_string(), "N,m".into(), "1".into(), "m;s".into()];
        let mut t = Table::new("t", names.clone(), units.clone()).unwrap();
        t.push_row([0.0, 1.0, 2.0, 3.0]);
        t.push_row([0.5, 4.0, 5.0, 6.0]);
        let back = Table::from_reader(t.to_csv().as_slice(), "t.csv").unwrap();
        assert_eq!(back.names(), names.as_slice());
        assert_eq!(back.units().unwrap(), units.as_slice());
        assert_eq!(back.require("b.\"q\"").unwrap(), &[2.0, 5.0]);
    }

    #[test]
    fn reads_header_units_and_suffix_lookup() {
        let t = parse("time,vehicle.Fz_rl,pedal\ns,N,1\n0,1.5,0\n\n0.1,2.5,1\n").unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t.units().unwrap()[1], "N");
        assert_eq!(t.require("Fz_rl").unwrap(), &[1.5, 2.5]);
        assert_eq!(t.line_of(1), 5, "blank line skipped, line numbers kept");
        assert!(t.column("rl").unwrap().is_none());
    }

    #[test]
    fn ambiguous_suffix_is_an_error() {
        let t = parse("time,a.v,b.v\n0,1,2\n").unwrap();
        let e = t.find("v").unwrap_err();
        assert!(
            matches!(&e, TableError::AmbiguousColumn { column, candidates, .. } if column == "v" && candidates.contains("`a.v`")),
            "{e}"
        );
        assert_eq!(t.find("a.v").unwrap(), Some(1));
    }

    #[test]
    fn malformed_field_in_first_row_is_not_taken_for_units() {
        let e = parse("time,x\n0,1.2.3\n").unwrap_err();
        assert!(
            matches!(&e, TableError::Malformed { row: 2, column, .. } if column == "x"),
            "{e}"
        );
    }

    #[test]
    fn ragged_row() {
        let e = parse("time,x\n0,1\n1\n").unwrap_err();
        assert!(
            matches!(
                e,
                TableError::RaggedRow {
                    row: 3,
                    expected: 2,
                    found: 1,
                    ..
                }
            ),
            "{e}"
        );
    }
}
