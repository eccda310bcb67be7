//! Where results go: stdout, or a file written atomically (temp file + rename), so an
//! error never leaves a half-written output behind.

use std::io::{self, Write};
use std::path::Path;

use anyhow::{Context, Result};

/// Output formats of `threshold`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// One JSON object (every key: the `qtvpr::report` docs); reject-all is `null`.
    Json,
    /// One CSV row per segment.
    Csv,
}

/// Write `text` to `path` atomically, or to stdout when `path` is `None`.
pub fn emit(text: &str, path: Option<&Path>) -> Result<()> {
    match path {
        None => {
            let mut out = io::stdout().lock();
            out.write_all(text.as_bytes())?;
            out.flush()?;
            Ok(())
        }
        Some(path) => {
            let dir = match path.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            let ctx = || format!("writing --output {}", path.display());
            let mut tmp = tempfile::NamedTempFile::new_in(dir).with_context(ctx)?;
            tmp.write_all(text.as_bytes()).with_context(ctx)?;
            tmp.persist(path).map_err(|e| e.error).with_context(ctx)?;
            Ok(())
        }
    }
}
