//! Where results go: stdout, or a file written atomically (temp file + rename), so an
//! error never leaves a half-written output behind. Matrices (`similarity`,
//! `ground-truth`) are written by the core's atomic writers
//! ([`qtvpr::npy::write_npy`], [`qtvpr::npy::write_npz`]) with the option that named the
//! file in their errors; every file the CLI reads goes through the core's checked reader.

use std::io::{self, Write};
use std::path::Path;

use anyhow::{Context, Result};
use ndarray::ArrayView2;
use qtvpr::npy::NpyArray;

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

/// Write `m` as a C-order `.npy` file (`<f4`, `<f8` or `|b1`), atomically; `flag`
/// names the option in errors.
pub fn write_npy<'a>(path: &Path, flag: &str, m: impl Into<NpyArray<'a>>) -> Result<()> {
    qtvpr::npy::write_npy(path, m).with_context(|| flag.to_string())
}

/// Write bool matrices into one `.npz` archive (a VPR_Tutorial `GThard`/`GTsoft` file),
/// atomically.
pub fn write_npz(path: &Path, flag: &str, arrays: &[(&str, ArrayView2<'_, bool>)]) -> Result<()> {
    let arrays: Vec<(&str, NpyArray<'_>)> = arrays.iter().map(|&(n, m)| (n, NpyArray::Bool(m))).collect();
    qtvpr::npy::write_npz(path, &arrays).with_context(|| flag.to_string())
}
