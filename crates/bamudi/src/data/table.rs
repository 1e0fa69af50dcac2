//! CSV tables with one error policy: every error names the file, the line (the header is
//! line 1), the column and what is wrong; a value is never guessed.
//!
//! [`Table::parse`] reads the header and the rows as text (checking that the header has no
//! duplicate or empty names and that every row has as many fields as the header);
//! [`Table::numbers`] then turns named columns into an `ndarray` matrix, which is the
//! workspace's shape for tabular and numpy-shaped data.

use crate::error::{BamudiError, Result};
use ndarray::Array2;

/// Whether an empty cell is an error or a missing value (`NaN` in [`Table::numbers`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Empty {
    /// An empty cell is an error.
    Refuse,
    /// An empty cell becomes `NaN` (the caller decides what a missing value means).
    Missing,
}

/// A CSV table as text: header, rows, and the line of each row in the file.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    file: String,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
    lines: Vec<u64>,
}

impl Table {
    /// Reads and parses a CSV file. A file that is not UTF-8 is refused with the line and
    /// column of its first bad byte ([`read_text`](super::read_text)).
    ///
    /// ```
    /// let path = std::env::temp_dir().join("bamudi_doc_latin1.csv");
    /// std::fs::write(&path, b"a,b\n1,2\n3,4\xb5\n").unwrap();
    /// let e = bamudi::data::Table::read(&path).unwrap_err().to_string();
    /// assert!(e.contains("line 3, column `b`") && e.contains("0xB5"), "{e}");
    /// ```
    pub fn read(path: &std::path::Path) -> Result<Self> {
        let file = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| BamudiError::Io {
            path: file.clone(),
            source,
        })?;
        let text = super::utf8(&bytes).map_err(|bad| {
            let column = csv_column_at(&bytes, &bad);
            csv_error(&file, bad.line as u64, &column, bad.reason())
        })?;
        Self::parse(text, &file)
    }

    /// Parses CSV text; `file` labels the errors. Fields are trimmed.
    ///
    /// ```
    /// use bamudi::data::Table;
    /// let t = Table::parse("a,b\n1,2\n3,4\n", "doc.csv").unwrap();
    /// assert_eq!((t.len(), t.header().len()), (2, 2));
    /// let e = Table::parse("a,a\n1,2\n", "doc.csv").unwrap_err().to_string();
    /// assert!(e.contains("doc.csv") && e.contains("line 1") && e.contains("duplicate"), "{e}");
    /// let e = Table::parse("a,b\n1,2\n3\n", "doc.csv").unwrap_err().to_string();
    /// assert!(e.contains("line 3"), "{e}");
    /// let t = Table::parse("a,b\r\n1,2\r\n\r\n3,4\r\n", "doc.csv").unwrap(); // CRLF, a blank line
    /// assert_eq!((t.line(0), t.line(1)), (2, 4));
    /// let t = Table::parse("a,b\r1,2\r3,4\r", "doc.csv").unwrap(); // classic-Mac line ends
    /// assert_eq!((t.line(0), t.line(1)), (2, 3));
    /// ```
    pub fn parse(text: &str, file: &str) -> Result<Self> {
        let mut rdr = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(text.as_bytes());
        let header: Vec<String> = rdr
            .headers()
            .map_err(|e| csv_error(file, 1, "-", e.to_string()))?
            .iter()
            .map(str::to_string)
            .collect();
        check_header(file, &header)?;
        let mut counter = LineCounter::new(text);
        let (mut rows, mut lines) = (Vec::new(), Vec::new());
        for rec in rdr.records() {
            let rec = rec.map_err(|e| {
                let line = e.position().map_or(0, |p| counter.line_at(p.byte()));
                csv_error(file, line, "-", e.to_string())
            })?;
            let line = rec.position().map_or(0, |p| counter.line_at(p.byte()));
            if rec.len() != header.len() {
                let reason = format!("{} fields, the header has {}", rec.len(), header.len());
                return Err(csv_error(file, line, "-", reason));
            }
            rows.push(rec.iter().map(str::to_string).collect());
            lines.push(line);
        }
        Ok(Self {
            file: file.to_string(),
            header,
            rows,
            lines,
        })
    }

    /// The file label used in errors.
    pub fn file(&self) -> &str {
        &self.file
    }

    /// The column names.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when there are no data rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The file line of data row `i` (the header is line 1).
    pub fn line(&self, i: usize) -> u64 {
        self.lines[i]
    }

    /// The position of the column `name`; an error naming it (and the header) when absent.
    pub fn column(&self, name: &str) -> Result<usize> {
        self.header.iter().position(|h| h == name).ok_or_else(|| {
            let reason = format!("missing column (the header has {:?})", self.header);
            csv_error(&self.file, 1, name, reason)
        })
    }

    /// The raw text of row `i`, column `c`.
    pub fn cell(&self, i: usize, c: usize) -> &str {
        &self.rows[i][c]
    }

    /// An error located at data row `i`, column `c`.
    pub fn error_at(&self, i: usize, c: usize, reason: impl Into<String>) -> BamudiError {
        let line = self.lines.get(i).copied().unwrap_or(0);
        let column = self.header.get(c).map_or("-", String::as_str);
        csv_error(&self.file, line, column, reason.into())
    }

    /// The finite number in row `i`, column `c`, or a located error (`None` for an empty cell
    /// when `empty` is [`Empty::Missing`]).
    pub fn number(&self, i: usize, c: usize, empty: Empty) -> Result<Option<f64>> {
        let cell = self.cell(i, c);
        if cell.is_empty() {
            return match empty {
                Empty::Missing => Ok(None),
                Empty::Refuse => Err(self.error_at(i, c, "empty value")),
            };
        }
        match cell.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some(v)),
            Ok(_) => Err(self.error_at(i, c, format!("value `{cell}` is not finite"))),
            Err(_) => Err(self.error_at(i, c, format!("`{cell}` is not a number"))),
        }
    }

    /// Refuses a value of the columns `names` whose magnitude exceeds `limit` (`unit` and
    /// `why` complete the message, which names the file, line and column and the allowed
    /// range). Empty cells and cells that are not numbers are left to [`number`](Self::number).
    ///
    /// ```
    /// use bamudi::data::Table;
    /// let t = Table::parse("g\n12.5\n1e300\n", "doc.csv").unwrap();
    /// let e = t.check_magnitude(&["g"], 1e5, "microstrain", "no gauge reads that").unwrap_err();
    /// assert!(e.to_string().contains("line 3, column `g`") && e.to_string().contains("100000"));
    /// ```
    pub fn check_magnitude(&self, names: &[&str], limit: f64, unit: &str, why: &str) -> Result<()> {
        for name in names {
            let c = self.column(name)?;
            for i in 0..self.len() {
                let cell = self.cell(i, c);
                if let Ok(v) = cell.parse::<f64>()
                    && v.is_finite()
                    && v.abs() > limit
                {
                    let reason = format!(
                        "value `{cell}` {unit} is outside the allowed range [-{limit}, {limit}] \
                         {unit}: {why}"
                    );
                    return Err(self.error_at(i, c, reason));
                }
            }
        }
        Ok(())
    }

    /// The named columns as a `rows x names.len()` matrix (`NaN` for missing values when
    /// `empty` allows them).
    ///
    /// ```
    /// use bamudi::data::{Empty, Table};
    /// let t = Table::parse("s,p\n1.0,2.0\n3.0,abc\n", "doc.csv").unwrap();
    /// let e = t.numbers(&["p"], Empty::Refuse).unwrap_err().to_string();
    /// assert!(e.contains("line 3") && e.contains("`p`"), "{e}");
    /// let m = t.numbers(&["s"], Empty::Refuse).unwrap();
    /// assert_eq!(m[[1, 0]], 3.0);
    /// ```
    pub fn numbers(&self, names: &[&str], empty: Empty) -> Result<Array2<f64>> {
        let cols = names
            .iter()
            .map(|n| self.column(n))
            .collect::<Result<Vec<_>>>()?;
        let mut out = Array2::from_elem((self.len(), cols.len()), f64::NAN);
        for i in 0..self.len() {
            for (j, &c) in cols.iter().enumerate() {
                if let Some(v) = self.number(i, c, empty)? {
                    out[[i, j]] = v;
                }
            }
        }
        Ok(out)
    }
}

/// File lines of records, counted from their byte offsets (in increasing order). The
/// reader's own line count is not used: it counts `\n` only, so after a CRLF line end it puts
/// the next record on the previous line, and in a file with classic-Mac `\r` line ends every
/// record on line 1. Here `\r\n`, `\n` and a lone `\r` each end a line.
struct LineCounter<'a> {
    bytes: &'a [u8],
    /// Bytes before `at` are counted; `line` is the line of byte `at`.
    at: usize,
    line: u64,
}

impl<'a> LineCounter<'a> {
    fn new(text: &'a str) -> Self {
        Self {
            bytes: text.as_bytes(),
            at: 0,
            line: 1,
        }
    }

    /// The line of the record that starts at byte `start` (line ends before it skipped).
    fn line_at(&mut self, start: u64) -> u64 {
        let b = self.bytes;
        let mut end = usize::try_from(start).unwrap_or(b.len()).min(b.len());
        while end < b.len() && matches!(b[end], b'\r' | b'\n') {
            end += 1;
        }
        for i in self.at..end.max(self.at) {
            let ends_line = b[i] == b'\n' || (b[i] == b'\r' && b.get(i + 1) != Some(&b'\n'));
            self.line += u64::from(ends_line);
        }
        self.at = end.max(self.at);
        self.line
    }
}

fn csv_error(file: &str, line: u64, column: &str, reason: String) -> BamudiError {
    BamudiError::Csv {
        file: file.to_string(),
        row: line as usize,
        column: column.to_string(),
        reason,
    }
}

/// The header name of the column holding the bad byte `bad` of a CSV file (`-` on the header
/// line, past the header, or when the header itself is not UTF-8): fields are counted by
/// their commas, which is exact for the unquoted files the tools write.
fn csv_column_at(bytes: &[u8], bad: &super::BadUtf8) -> String {
    let header_end = bytes
        .iter()
        .position(|b| *b == b'\n')
        .unwrap_or(bytes.len());
    let (Ok(header), true) = (std::str::from_utf8(&bytes[..header_end]), bad.line > 1) else {
        return "-".into();
    };
    let line_start = bytes[..bad.offset]
        .iter()
        .rposition(|b| *b == b'\n')
        .map_or(0, |p| p + 1);
    let field = bytes[line_start..bad.offset]
        .iter()
        .filter(|b| **b == b',')
        .count();
    header
        .trim_end_matches('\r')
        .split(',')
        .nth(field)
        .map_or("-".into(), |h| h.trim().to_string())
}

fn check_header(file: &str, header: &[String]) -> Result<()> {
    for (i, h) in header.iter().enumerate() {
        if h.is_empty() {
            return Err(csv_error(
                file,
                1,
                "-",
                format!("column {} has no name", i + 1),
            ));
        }
        if let Some(j) = header[..i].iter().position(|g| g == h) {
            let reason = format!("duplicate column (at positions {} and {})", j + 1, i + 1);
            return Err(csv_error(file, 1, h, reason));
        }
    }
    Ok(())
}
