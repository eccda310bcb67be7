//! Writing the results of the `similarity` and `ground-truth` commands atomically (temp
//! file + rename), as `.npy` or as a VPR_Tutorial `.npz`.
//!
//! Reading is the core's ([`qtvpr::npy`]): every file the CLI opens goes through its
//! checked reader.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
use ndarray::ArrayView2;
use npyz::WriterBuilder;

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
