//! Data in and out: CSV tables ([`Table`], one error policy), the experiments of a calibration
//! ([`Experiments`]), and atomic file writes.

mod experiments;
mod table;

pub use experiments::Experiments;
pub use table::{Empty, Table};

use crate::error::{BamudiError, Result};
use std::io::Write;
use std::path::Path;

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
