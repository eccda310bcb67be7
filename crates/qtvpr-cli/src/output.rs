//! Where results go: stdout, or a file written atomically (temp file + rename), so an
//! error never leaves a half-written output behind. Matrices (`similarity`,
//! `ground-truth`) are written by the core's atomic writers
//! ([`qtvpr::npy::write_npy`], [`qtvpr::npy::write_ground_truth`]) with the option that named the
//! file in their errors; every file the CLI reads goes through the core's checked reader.

use std::io::{self, Write};
use std::path::Path;

use anyhow::{Context, Result};
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

/// Standard output, locked, once it is known not to be closed.
///
/// A program started with descriptor 1 closed (`>&-`) finds `/dev/null` there: Rust's
/// runtime opens it, read-write, in place of a closed standard descriptor, so every
/// line would be lost and the command exit 0. A shell's `>/dev/null` opens it
/// write-only, so that the runtime's is told apart by its read-write mode (written by
/// hand, there being no crate for it; `libc` for `fstat` and `fcntl`).
pub fn stdout() -> Result<io::StdoutLock<'static>> {
    if replaces_a_closed_descriptor() {
        anyhow::bail!("{STDOUT}: is closed; redirect it to a file, or to /dev/null to discard the results");
    }
    Ok(io::stdout().lock())
}

#[cfg(unix)]
fn replaces_a_closed_descriptor() -> bool {
    use std::os::unix::fs::MetadataExt;
    let Ok(null) = std::fs::metadata("/dev/null") else {
        return false;
    };
    // SAFETY: fstat and fcntl on descriptor 1 read into a zeroed stat and return a flag word.
    let (stat, flags) = unsafe {
        let mut stat: libc::stat = std::mem::zeroed();
        (
            (libc::fstat(1, &raw mut stat) == 0).then_some(stat),
            libc::fcntl(1, libc::F_GETFL),
        )
    };
    stat.is_some_and(|s| (s.st_mode & libc::S_IFMT) == libc::S_IFCHR && s.st_rdev == null.rdev())
        && flags >= 0
        && flags & libc::O_ACCMODE == libc::O_RDWR
}

#[cfg(not(unix))]
fn replaces_a_closed_descriptor() -> bool {
    false
}

/// Write `text` to `path` atomically (with the mode a plain create gives), or to stdout
/// when `path` is `None`.
pub fn emit(text: &str, path: Option<&Path>) -> Result<()> {
    match path {
        None => {
            let mut out = stdout()?;
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
