//! Data in and out: CSV tables ([`Table`], one error policy), the experiments of a calibration
//! ([`Experiments`]), and atomic file writes.

mod experiments;
mod table;

pub use experiments::Experiments;
pub use table::{Empty, Table};

use crate::error::{BamudiError, Result};
use std::io::Write;
use std::path::Path;

/// Where a file stops being UTF-8: the byte offset, the file line (1-based) and the byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BadUtf8 {
    /// Offset of the first byte that is not UTF-8.
    pub offset: usize,
    /// Its file line (the first line is 1).
    pub line: usize,
    /// The byte itself.
    pub byte: u8,
    /// The file starts with a UTF-16 byte-order mark (what spreadsheets call "Unicode text").
    pub utf16: bool,
}

impl BadUtf8 {
    /// What is wrong and what to do, for a message that names the file and line.
    pub fn reason(&self) -> String {
        if self.utf16 {
            return "the file is UTF-16 (it starts with a UTF-16 byte-order mark), not UTF-8; \
                    save it as UTF-8"
                .into();
        }
        format!(
            "byte 0x{:02X} is not UTF-8 (a Latin-1 or Windows-1252 character such as `µ` or \
             `°`?); save the file as UTF-8",
            self.byte
        )
    }
}

/// `bytes` as UTF-8 text, or where they stop being UTF-8.
///
/// ```
/// let bad = bamudi::data::utf8(b"a\nb\xb5\n").unwrap_err();
/// assert_eq!((bad.line, bad.byte, bad.utf16), (2, 0xB5, false));
/// assert!(bamudi::data::utf8(&[0xFF, 0xFE, b'a', 0]).unwrap_err().utf16);
/// assert_eq!(bamudi::data::utf8(b"ok").unwrap(), "ok");
/// ```
pub fn utf8(bytes: &[u8]) -> std::result::Result<&str, BadUtf8> {
    std::str::from_utf8(bytes).map_err(|e| {
        let offset = e.valid_up_to();
        BadUtf8 {
            offset,
            line: 1 + bytes[..offset].iter().filter(|b| **b == b'\n').count(),
            byte: bytes[offset],
            utf16: bytes.starts_with(&[0xFF, 0xFE]) || bytes.starts_with(&[0xFE, 0xFF]),
        }
    })
}

/// The text of the file `path`; an error names the file, and the line of the first byte that
/// is not UTF-8 ([`BamudiError::Encoding`]).
///
/// ```
/// let path = std::env::temp_dir().join("bamudi_doc_read_text.toml");
/// std::fs::write(&path, b"a = 1\nb = \"\xb0F\"\n").unwrap();
/// let e = bamudi::data::read_text(&path).unwrap_err().to_string();
/// assert!(e.contains("line 2") && e.contains("0xB0"), "{e}");
/// ```
pub fn read_text(path: &Path) -> Result<String> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| BamudiError::Io {
        path: file.clone(),
        source,
    })?;
    String::from_utf8(bytes).map_err(|e| {
        let (line, reason) = match utf8(e.as_bytes()) {
            Err(bad) => (bad.line, bad.reason()),
            Ok(_) => (0, e.to_string()),
        };
        BamudiError::Encoding { file, line, reason }
    })
}

/// Writes `bytes` to `path` atomically: into a temporary file beside it, flushed to disk, then
/// renamed over `path`. A failure (full disk, killed process) leaves any previous `path`
/// untouched and no partial file under its name.
///
/// ```
/// let p = std::env::temp_dir().join("bamudi_doc_atomic.txt");
/// bamudi::data::write_atomic(&p, b"hello").unwrap();
/// assert_eq!(std::fs::read(&p).unwrap(), b"hello");
/// ```
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let io = |source| BamudiError::Io {
        path: path.display().to_string(),
        source,
    };
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map_or("out".into(), |n| n.to_string_lossy());
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = std::fs::File::create(&tmp)
        .and_then(|mut f| f.write_all(bytes).and_then(|_| f.sync_all()))
        .and_then(|_| std::fs::rename(&tmp, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}
