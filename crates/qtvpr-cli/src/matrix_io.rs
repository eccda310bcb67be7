//! `.npy` chores of the `similarity` and `ground-truth` commands: checking a descriptor
//! or position file's header before it is read (so that the message speaks of
//! descriptors, not scores), reading a matrix's shape alone (`--like`), and writing
//! results atomically (temp file + rename), as `.npy` or as a VPR_Tutorial `.npz`.
//!
//! Reading itself goes through [`qtvpr::npy::read_scores`], like every other matrix.

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use ndarray::ArrayView2;
use npyz::{DType, NpyFile, TypeChar, WriterBuilder};

use qtvpr::npy::{Scores, read_scores};

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

/// Write a file atomically: `write` fills a temporary file next to
/// `path`, which then replaces `path`. On any error nothing is left behind.
fn atomically(path: &Path, flag: &str, write: impl FnOnce(&mut BufWriter<&mut File>) -> Result<()>) -> Result<()> {
    let ctx = || format!("writing {flag} {}", path.display());
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir).with_context(ctx)?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file_mut());
        write(&mut w).with_context(ctx)?;
        w.flush().with_context(ctx)?;
    }
    tmp.persist(path).map_err(|e| e.error).with_context(ctx)?;
    Ok(())
}

/// A matrix element written as raw little-endian bytes after an `.npy` header.
pub trait NpyElement: Copy + npyz::AutoSerialize {
    /// Append the element's bytes.
    fn put(self, out: &mut Vec<u8>);
}

impl NpyElement for f32 {
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElement for bool {
    fn put(self, out: &mut Vec<u8>) {
        out.push(u8::from(self));
    }
}

fn write_body<T: NpyElement>(w: &mut impl Write, m: ArrayView2<'_, T>) -> Result<()> {
    let mut buf = Vec::new();
    for row in m.rows() {
        buf.clear();
        row.iter().for_each(|v| v.put(&mut buf));
        w.write_all(&buf)?;
    }
    Ok(())
}

fn npy_shape<T>(m: ArrayView2<'_, T>) -> [u64; 2] {
    [m.nrows() as u64, m.ncols() as u64]
}

/// Write `m` as a C-order `.npy` file (`<f4` or `|b1`), atomically.
pub fn write_npy<T: NpyElement>(path: &Path, flag: &str, m: ArrayView2<'_, T>) -> Result<()> {
    atomically(path, flag, |w| {
        let w = npyz::WriteOptions::<T>::new()
            .default_dtype()
            .shape(&npy_shape(m))
            .writer(w)
            .write_header_only()?;
        write_body(w, m)
    })
}

/// Write bool matrices into one `.npz` archive (uncompressed, as `numpy.savez`), atomically.
pub fn write_npz(path: &Path, flag: &str, arrays: &[(&str, ArrayView2<'_, bool>)]) -> Result<()> {
    atomically(path, flag, |w| {
        let mut zip = npyz::zip::ZipWriter::new(w);
        for (name, m) in arrays {
            let options = npyz::zip::write::FileOptions::default()
                .compression_method(npyz::zip::CompressionMethod::Stored)
                .large_file(m.len() as u64 >= u64::from(u32::MAX) / 2);
            zip.start_file(npyz::npz::file_name_from_array_name(name), options)?;
            npyz::WriteOptions::<bool>::new()
                .default_dtype()
                .shape(&npy_shape(*m))
                .writer(&mut zip)
                .write_header_only()?;
            write_body(&mut zip, *m)?;
        }
        zip.finish()?;
        Ok(())
    })
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
