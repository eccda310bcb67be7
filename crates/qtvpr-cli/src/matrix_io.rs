//! `.npy` chores of the `similarity` and `ground-truth` commands: checking a descriptor
//! or position file's header before it is read (so that the message speaks of
//! descriptors, not scores), reading a matrix's shape alone (`--like`), and naming the
//! option of a file written (the writers are the core's [`qtvpr::npy`] ones: atomic,
//! `.npy` or a VPR_Tutorial `.npz`).
//!
//! Reading itself goes through [`qtvpr::npy::read_scores`], like every other matrix.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use ndarray::ArrayView2;
use npyz::{DType, NpyFile, TypeChar};

use qtvpr::npy::{NpyArray, Scores, read_scores};

fn header(path: &Path) -> Result<NpyFile<BufReader<File>>> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    if file.metadata().is_ok_and(|m| m.is_dir()) {
        bail!("{} is a directory, not a .npy file", path.display());
    }
    NpyFile::new(BufReader::new(file)).map_err(|e| {
        let e = e.to_string();
        anyhow!(
            "{} is not a valid .npy file: {}",
            path.display(),
            e.lines().next().unwrap_or_default().trim()
        )
    })
}

/// The 2-D shape of a `.npy` file, read from its header alone.
pub fn shape(path: &Path) -> Result<(usize, usize)> {
    let npy = header(path)?;
    match npy.shape() {
        &[rows, cols] => Ok((rows as usize, cols as usize)),
        other => bail!(
            "{} holds a {}-D array of shape {other:?}, expected a 2-D matrix",
            path.display(),
            other.len()
        ),
    }
}

/// Read a float32/float64 matrix of `kind` (e.g. `"descriptors"`, one per row): the
/// header is checked first so that a wrong dtype or dimension is named as such.
pub fn read_rows(path: &Path, kind: &str, layout: &str) -> Result<Scores> {
    let npy = header(path)?;
    let dtype = npy.dtype();
    let is_float = matches!(&dtype, DType::Plain(ts) if ts.type_char() == TypeChar::Float
        && matches!(ts.size_field(), 4 | 8));
    if !is_float {
        let name = match &dtype {
            DType::Plain(ts) => ts.to_string().replace('\'', ""),
            other => other.descr(),
        };
        bail!("{} has dtype {name}; {kind} must be float32 or float64", path.display());
    }
    let shape = npy.shape();
    if shape.len() != 2 {
        bail!(
            "{} holds a {}-D array of shape {shape:?}, expected {layout}",
            path.display(),
            shape.len()
        );
    }
    drop(npy);
    Ok(read_scores(path)?)
}

/// Write `m` as a C-order `.npy` file (`<f4`, `<f8` or `|b1`), atomically
/// ([`qtvpr::npy::write_npy`]); `flag` names the option in errors.
pub fn write_npy<'a>(path: &Path, flag: &str, m: impl Into<NpyArray<'a>>) -> Result<()> {
    qtvpr::npy::write_npy(path, m).with_context(|| flag.to_string())
}

/// Write bool matrices into one `.npz` archive, atomically ([`qtvpr::npy::write_npz`]).
pub fn write_npz(path: &Path, flag: &str, arrays: &[(&str, ArrayView2<'_, bool>)]) -> Result<()> {
    let arrays: Vec<(&str, NpyArray<'_>)> = arrays.iter().map(|&(n, m)| (n, NpyArray::Bool(m))).collect();
    qtvpr::npy::write_npz(path, &arrays).with_context(|| flag.to_string())
}

/// Attach to a core error the option and file of the matrix it is about: `sources`
/// maps the core's matrix names (e.g. [`qtvpr::similarity::DB_DESCRIPTORS`]) to
/// `--option FILE`. Errors about no particular matrix are returned as they are.
pub fn blame(err: qtvpr::Error, sources: &[(&str, String)]) -> anyhow::Error {
    use qtvpr::Error;
    let about: Vec<&str> = match &err {
        Error::Empty { what, .. }
        | Error::NotFiniteValue { what, .. }
        | Error::ZeroNorm { what, .. }
        | Error::PositionColumns { what, .. } => vec![what],
        Error::ColumnMismatch { what, other, .. } => vec![what, other],
        _ => vec![],
    };
    let context: Vec<&str> = about
        .iter()
        .filter_map(|w| sources.iter().find(|(name, _)| name == w))
        .map(|(_, source)| source.as_str())
        .collect();
    if context.is_empty() {
        err.into()
    } else {
        anyhow::Error::new(err).context(context.join(" / "))
    }
}
