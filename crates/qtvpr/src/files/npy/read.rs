//! Reading a float32/float64 matrix (similarity, descriptors, positions):
//! memory-mapped where the file allows, else read into memory.

use std::fs::File;
use std::io::{self, Cursor, Read};
use std::path::{Path, PathBuf};

use memmap2::Mmap;
use ndarray::{ArrayView2, ShapeBuilder};
use npyz::{NpyFile, Order, TypeChar};

use super::header::{MATRIX, dtype_name, parse, plain_dtype, shape_2d};
use super::open::{file_error, io_error, is_regular, open_file};
use crate::error::{Error, Result};
use crate::input::ScoresView;

/// A float32 or float64 matrix (similarity, descriptors, positions) as read from a
/// `.npy` file: memory-mapped where the file allows, else read into memory.
pub enum MatrixFile {
    /// float32 scores.
    F32(Matrix<f32>),
    /// float64 scores.
    F64(Matrix<f64>),
}

impl MatrixFile {
    /// The matrix as stored in the file (rows x columns).
    pub fn view(&self) -> ScoresView<'_> {
        match self {
            MatrixFile::F32(m) => ScoresView::F32(m.view()),
            MatrixFile::F64(m) => ScoresView::F64(m.view()),
        }
    }

    /// Whether the data is memory-mapped rather than read into memory.
    pub fn is_mapped(&self) -> bool {
        match self {
            MatrixFile::F32(m) => m.is_mapped(),
            MatrixFile::F64(m) => m.is_mapped(),
        }
    }

    /// Check that a memory-mapped file still holds all its data. Reading a mapping
    /// past the end of a file that another process shrank is a bus error (SIGBUS), which
    /// no error handling catches; a reader that reads a mapping over a long time (a
    /// replay) calls this before each block, so the common case (the file truncated or
    /// rewritten in place) is an error instead. It cannot close the window between the
    /// check and the read: a mapped file must not be shrunk while it is read.
    ///
    /// # Errors
    /// [`Error::File`] naming the file when it is now shorter than its data.
    pub fn check_mapped_file(&self) -> Result<()> {
        match self {
            MatrixFile::F32(m) => m.check_mapped_file(),
            MatrixFile::F64(m) => m.check_mapped_file(),
        }
    }
}

/// What a float matrix read by [`read_float_matrix`] holds, for its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FloatMatrix {
    /// A similarity matrix (any 2-D shape).
    Similarity,
    /// Descriptors, one image per row.
    Descriptors,
    /// Positions, one per row: x, y or x, y, z.
    Positions,
}

impl FloatMatrix {
    /// What a file of another dtype is told, after `has dtype ...; `.
    fn dtype_rule(self) -> &'static str {
        match self {
            FloatMatrix::Similarity => "expected float32 or float64 similarity scores",
            FloatMatrix::Descriptors => "descriptors must be float32 or float64",
            FloatMatrix::Positions => "positions must be float32 or float64",
        }
    }

    /// What a file of another dimension is told, after `expected `.
    fn layout(self) -> &'static str {
        match self {
            FloatMatrix::Similarity => MATRIX,
            FloatMatrix::Descriptors => "an N x D descriptor matrix (one row per image)",
            FloatMatrix::Positions => "an N x 2 (x, y) or N x 3 (x, y, z) position matrix",
        }
    }
}

/// A 2-D matrix of `T`, owned or memory-mapped.
pub struct Matrix<T> {
    data: Data<T>,
    dim: (usize, usize),
    fortran: bool,
}

enum Data<T> {
    Owned(Vec<T>),
    /// The map, where the data starts in it, and the file mapped (its size is checked
    /// by [`MatrixFile::check_mapped_file`]) with its path for messages.
    Mapped {
        map: Mmap,
        offset: usize,
        file: File,
        path: PathBuf,
    },
}

impl<T> Matrix<T> {
    fn shape(&self) -> ndarray::StrideShape<ndarray::Ix2> {
        if self.fortran {
            self.dim.f().into()
        } else {
            self.dim.into()
        }
    }

    /// Whether the data is memory-mapped.
    pub fn is_mapped(&self) -> bool {
        matches!(self.data, Data::Mapped { .. })
    }
}

impl<T: bytemuck::Pod> Matrix<T> {
    /// [`MatrixFile::check_mapped_file`] of one matrix.
    fn check_mapped_file(&self) -> Result<()> {
        let Data::Mapped { offset, file, path, .. } = &self.data else {
            return Ok(());
        };
        let needed = (offset + self.dim.0 * self.dim.1 * size_of::<T>()) as u64;
        let len = file.metadata().map_err(|e| io_error(path, &e))?.len();
        if len < needed {
            return Err(file_error(
                path,
                format!(
                    "shrank to {len} bytes while it was read, from at least {needed} (a memory-mapped \
                     file must not be truncated or rewritten while in use)"
                ),
            ));
        }
        Ok(())
    }

    /// The matrix, viewed where it lies.
    pub fn view(&self) -> ArrayView2<'_, T> {
        let data: &[T] = match &self.data {
            Data::Owned(v) => v,
            Data::Mapped { map, offset, .. } => {
                let bytes = &map[*offset..*offset + self.dim.0 * self.dim.1 * size_of::<T>()];
                bytemuck::cast_slice(bytes) // alignment and length were checked when mapping
            }
        };
        ArrayView2::from_shape(self.shape(), data).expect("length checked when reading")
    }
}

/// Read a whole matrix into memory; a shape other than 2-D is refused with `layout`.
///
/// The header's claim decides no allocation by itself: the buffer grows (fallibly, at
/// most doubling) with the values actually read, so a small file whose header claims
/// terabytes is "truncated" after reading what it holds, and memory that cannot be
/// allocated is an error, never an abort (npyz's `into_vec` reserves the claim
/// infallibly, hence this loop).
pub(super) fn read_matrix<T: npyz::Deserialize, R: Read>(
    npy: NpyFile<R>,
    path: &Path,
    layout: &str,
) -> Result<Matrix<T>> {
    /// Values reserved before the first read: 8 MiB of f64.
    const FIRST: usize = 1 << 20;
    let dim = shape_2d(&npy, path, layout)?;
    let fortran = npy.order() == Order::Fortran;
    let n = dim.0 * dim.1;
    let item = npy.dtype().num_bytes().unwrap_or(1);
    let truncated = |read: usize| {
        file_error(
            path,
            format!(
                "is truncated: shape {}x{} needs {} bytes of data, it holds {}",
                dim.0,
                dim.1,
                n as u128 * item as u128,
                read * item
            ),
        )
    };
    let mut data: Vec<T> = Vec::new();
    let values = npy
        .data::<T>()
        .map_err(|e| file_error(path, format!("is corrupt: {e}")))?;
    for value in values {
        if data.len() == data.capacity() {
            let more = (n - data.len()).min(data.capacity().max(FIRST));
            data.try_reserve_exact(more).map_err(|_| Error::Allocation {
                bytes: (data.len() + more) as u128 * size_of::<T>() as u128,
                what: format!("{} (a {}x{} matrix)", path.display(), dim.0, dim.1),
            })?;
        }
        match value {
            Ok(v) => data.push(v),
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Err(truncated(data.len())),
            Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                return Err(file_error(path, format!("is corrupt: {e}")));
            }
            Err(e) => return Err(file_error(path, format!("cannot be read: {e}"))),
        }
    }
    if data.len() != n {
        return Err(truncated(data.len()));
    }
    Ok(Matrix {
        data: Data::Owned(data),
        dim,
        fortran,
    })
}

impl<T> Matrix<T> {
    /// An owned matrix as an array (mapped data is never of a label type).
    pub(super) fn into_array(self) -> ndarray::Array2<T> {
        let shape = self.shape();
        match self.data {
            Data::Owned(values) => ndarray::Array2::from_shape_vec(shape, values).expect("length checked when reading"),
            Data::Mapped { .. } => unreachable!("only float scores are mapped"),
        }
    }
}

/// Read a float32/float64 similarity matrix, memory-mapped where possible:
/// [`read_float_matrix`] of a [`FloatMatrix::Similarity`].
///
/// # Errors
/// As [`read_float_matrix`].
pub fn read_scores(path: &Path) -> Result<MatrixFile> {
    read_float_matrix(path, FloatMatrix::Similarity)
}

/// Read a float32/float64 matrix of `what` (similarity scores, descriptors,
/// positions), memory-mapped where possible; the errors say what it must be.
///
/// # Errors
/// [`Error::Io`] (missing file, a directory, ...), [`Error::File`] (not `.npy`,
/// truncated, not 2-D), [`Error::Dtype`] (not float32/float64).
pub fn read_float_matrix(path: &Path, what: FloatMatrix) -> Result<MatrixFile> {
    super::guard::guarded(path, || read_float_matrix_unguarded(path, what))
}

fn read_float_matrix_unguarded(path: &Path, what: FloatMatrix) -> Result<MatrixFile> {
    let file = open_file(path)?;
    if !is_regular(&file) {
        // A device or a pipe: read as a stream, never mapped (/dev/zero maps as empty).
        return read_unmapped(io::BufReader::new(file), path, what);
    }
    // SAFETY: the map is read-only; like NumPy's mmap_mode="r", it assumes no other
    // process truncates the file while it is in use (a truncated mapping is SIGBUS).
    let Ok(map) = (unsafe { Mmap::map(&file) }) else {
        return read_unmapped(io::BufReader::new(file), path, what);
    };
    let mut cursor = Cursor::new(&map[..]);
    let npy = parse(&mut cursor, path)?;
    let (kind, size, little) = plain_dtype(&npy, path, what.dtype_rule())?;
    if kind != TypeChar::Float || !(size == 4 || size == 8) {
        return Err(Error::Dtype {
            path: path.display().to_string(),
            dtype: dtype_name(&npy),
            expected: what.dtype_rule(),
        });
    }
    let dim = shape_2d(&npy, path, what.layout())?;
    let fortran = npy.order() == Order::Fortran;
    let offset = cursor.position() as usize;
    let available = map.len() - offset;
    let needed = dim
        .0
        .checked_mul(dim.1)
        .and_then(|n| n.checked_mul(size as usize))
        .unwrap_or(usize::MAX);
    if needed > available {
        return Err(file_error(
            path,
            format!(
                "is truncated: shape {}x{} needs {needed} bytes of data, the file has {available}",
                dim.0, dim.1
            ),
        ));
    }
    let aligned = (map.as_ptr() as usize + offset).is_multiple_of(size as usize);
    if !(little && cfg!(target_endian = "little") && aligned) {
        return read_unmapped(io::BufReader::new(open_file(path)?), path, what);
    }
    fn mapped<T>(map: Mmap, offset: usize, file: File, path: &Path, dim: (usize, usize), fortran: bool) -> Matrix<T> {
        let path = path.to_path_buf();
        let data = Data::Mapped {
            map,
            offset,
            file,
            path,
        };
        Matrix { data, dim, fortran }
    }
    Ok(if size == 4 {
        MatrixFile::F32(mapped(map, offset, file, path, dim, fortran))
    } else {
        MatrixFile::F64(mapped(map, offset, file, path, dim, fortran))
    })
}

fn read_unmapped<R: Read>(reader: R, path: &Path, what: FloatMatrix) -> Result<MatrixFile> {
    let npy = parse(reader, path)?;
    let rule = what.dtype_rule();
    match plain_dtype(&npy, path, rule)? {
        (TypeChar::Float, 4, _) => Ok(MatrixFile::F32(read_matrix(npy, path, what.layout())?)),
        (TypeChar::Float, 8, _) => Ok(MatrixFile::F64(read_matrix(npy, path, what.layout())?)),
        _ => Err(Error::Dtype {
            path: path.display().to_string(),
            dtype: dtype_name(&npy),
            expected: rule,
        }),
    }
}

/// Read a float32/float64 similarity matrix from the bytes of a `.npy` file (e.g. data
/// compiled into a program), through the same checks as a file; `name` stands for
/// the file name in errors.
///
/// # Errors
/// As [`read_scores`].
pub fn scores_from_bytes(bytes: &[u8], name: &str) -> Result<MatrixFile> {
    let path = Path::new(name);
    super::guard::guarded(path, || read_unmapped(bytes, path, FloatMatrix::Similarity))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::files::npy::write::write_npy;

    #[test]
    fn a_mapped_file_shrunk_while_read_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.npy");
        let m = ndarray::Array2::from_shape_fn((64, 8), |(i, j)| (i * 8 + j) as f32);
        write_npy(&path, m.view()).unwrap();
        let scores = read_scores(&path).unwrap();
        assert!(scores.is_mapped());
        scores.check_mapped_file().unwrap();
        let len = std::fs::metadata(&path).unwrap().len();
        // Another process truncates it: reading the mapping's last page would be SIGBUS.
        File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_len(len - 4)
            .unwrap();
        assert_eq!(
            scores.check_mapped_file().unwrap_err().to_string(),
            format!(
                "{} shrank to {} bytes while it was read, from at least {len} (a memory-mapped \
                 file must not be truncated or rewritten while in use)",
                path.display(),
                len - 4
            )
        );
        // Grown back (rewritten in place): whole again.
        File::options().write(true).open(&path).unwrap().set_len(len).unwrap();
        scores.check_mapped_file().unwrap();
        // What was read into memory has nothing to check.
        let bytes = std::fs::read(&path).unwrap();
        let owned = scores_from_bytes(&bytes, "s.npy").unwrap();
        assert!(!owned.is_mapped());
        owned.check_mapped_file().unwrap();
    }
}
