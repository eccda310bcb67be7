//! Where results go: stdout, or a file written atomically (temp file + rename), so an
//! error never leaves a half-written output behind.

use std::io::{self, Write};
use std::path::Path;

use anyhow::{Context, Result};

/// Output formats of `threshold`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// One JSON object (keys: docs/cli.md and semantics §9); reject-all is `null`.
    Json,
    /// One CSV row per segment.
    Csv,
}

/// How errors name standard output, the output when no `--output` is given.
pub const STDOUT: &str = "standard output";

/// Write `text` to `path` atomically (with the mode a plain create gives), or to stdout
/// when `path` is `None`.
pub fn emit(text: &str, path: Option<&Path>) -> Result<()> {
    match path {
        None => {
            let mut out = io::stdout().lock();
            out.write_all(text.as_bytes())
                .and_then(|()| out.flush())
                .context(STDOUT)
        }
        Some(path) => {
            qtvpr::npy::write_atomically(path, |w| w.write_all(text.as_bytes()))?;
            Ok(())
        }
    }
}
