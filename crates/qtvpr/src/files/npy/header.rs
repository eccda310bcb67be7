//! The header of a `.npy` file, checked before npyz parses it (length, bracket
//! nesting, a shape no larger than an address space), and what it says.

use std::io::{self, Cursor, Read};
use std::path::Path;

use npyz::{DType, NpyFile, Order, TypeChar};

use super::open::{NPY_MAGIC, file_error, open_file};
use crate::error::{Error, Result};

/// The layout every 2-D input but descriptors and positions is told it must have.
pub(super) const MATRIX: &str = "a 2-D matrix";

/// What the header of a `.npy` file says, checked ([`inspect`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// The dtype as NumPy spells it, e.g. `<f8` or `|b1`.
    pub dtype: String,
    /// The shape; every dimension fits a `usize` and their product, in bytes, an
    /// address space.
    pub shape: Vec<usize>,
    /// Whether the data is in Fortran (column-major) order.
    pub fortran: bool,
}

/// The checked header of the `.npy` file at `path`, without reading its data: the
/// header goes through the same checks as every file this module reads (length,
/// bracket nesting, a shape no larger than an address space).
///
/// # Errors
/// [`Error::Io`] (missing file, a directory, ...) and [`Error::File`] (not `.npy`, a
/// hostile or corrupt header).
pub fn inspect(path: &Path) -> Result<Header> {
    super::guard::guarded(path, || inspect_unguarded(path))
}

fn inspect_unguarded(path: &Path) -> Result<Header> {
    let npy = parse(io::BufReader::new(open_file(path)?), path)?;
    let bytes = npy.dtype().num_bytes().unwrap_or(1) as u64;
    let mut total = Some(bytes);
    let mut shape = Vec::with_capacity(npy.shape().len());
    for &d in npy.shape() {
        total = total.and_then(|t| t.checked_mul(d));
        shape.push(usize::try_from(d).ok());
    }
    let shape: Option<Vec<usize>> = shape.into_iter().collect();
    match shape {
        Some(shape) if total.is_some_and(|t| t <= isize::MAX as u64) => Ok(Header {
            dtype: dtype_name(&npy),
            shape,
            fortran: npy.order() == Order::Fortran,
        }),
        _ => Err(too_large(path, npy.shape())),
    }
}

/// The 2-D shape of the `.npy` file at `path`, from its header alone.
///
/// # Errors
/// As [`inspect`], and [`Error::File`] for an array that is not 2-D.
pub fn matrix_shape(path: &Path) -> Result<(usize, usize)> {
    match inspect(path)?.shape[..] {
        [rows, cols] => Ok((rows, cols)),
        ref shape => Err(not_2d(path, shape, MATRIX)),
    }
}

pub(super) fn too_large(path: &Path, shape: &[u64]) -> Error {
    let shape: Vec<String> = shape.iter().map(u64::to_string).collect();
    file_error(
        path,
        format!("is corrupt: its shape {} is larger than any file", shape.join("x")),
    )
}

fn not_2d<D: std::fmt::Debug>(path: &Path, shape: &[D], layout: &str) -> Error {
    file_error(
        path,
        format!("holds a {}-D array of shape {shape:?}, expected {layout}", shape.len()),
    )
}

/// The longest header read: NumPy's own reader refuses more than 10000 bytes by default
/// (`max_header_size`), and a plain matrix needs under 128.
const MAX_HEADER: usize = 10_000;

/// The deepest bracket nesting a header may have: a plain matrix has 2 (`{... (r, c)}`),
/// a structured dtype a few more. npyz's header parser backtracks exponentially in the
/// nesting depth, so a 100-byte header of `[[[[...` would never finish.
const MAX_NESTING: usize = 6;

/// Parse a `.npy` header. The header is read and checked here first (magic, length,
/// nesting), then handed to npyz, followed by the rest of `reader`.
pub(super) fn parse<R: Read>(mut reader: R, path: &Path) -> Result<NpyFile<io::Chain<Cursor<Vec<u8>>, R>>> {
    let header = read_header(&mut reader, path)?;
    parse_header(header, reader, path)
}

/// Parse `header` (from [`read_header`]), followed by the rest of `reader`.
pub(super) fn parse_header<R: Read>(
    header: Vec<u8>,
    reader: R,
    path: &Path,
) -> Result<NpyFile<io::Chain<Cursor<Vec<u8>>, R>>> {
    NpyFile::new(Cursor::new(header).chain(reader)).map_err(|e| {
        // Header parse errors span several lines; the first says what is wrong.
        let e = e.to_string();
        file_error(
            path,
            format!(
                "is not a valid .npy file: {}",
                e.lines().next().unwrap_or_default().trim()
            ),
        )
    })
}

/// The bytes of a `.npy` header (magic, version, length, text), checked for length and
/// nesting.
pub(super) fn read_header<R: Read>(mut reader: R, path: &Path) -> Result<Vec<u8>> {
    let invalid = |what: &str| file_error(path, format!("is not a valid .npy file: {what}"));
    // A member of a corrupt archive says so (a bad CRC, a deflate stream that breaks).
    let cut_short = |e: io::Error, what: &str| match e.kind() {
        io::ErrorKind::InvalidData => file_error(path, format!("is corrupt: {e}")),
        _ => invalid(what),
    };
    let mut header = vec![0u8; 8];
    reader
        .read_exact(&mut header)
        .map_err(|e| cut_short(e, "it is shorter than the magic string"))?;
    if &header[..6] != NPY_MAGIC {
        return Err(invalid("it does not start with the magic string \\x93NUMPY"));
    }
    let len = match header[6] {
        1 => {
            let mut b = [0u8; 2];
            reader
                .read_exact(&mut b)
                .map_err(|e| cut_short(e, "its header is cut short"))?;
            header.extend(b);
            usize::from(u16::from_le_bytes(b))
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            reader
                .read_exact(&mut b)
                .map_err(|e| cut_short(e, "its header is cut short"))?;
            header.extend(b);
            u32::from_le_bytes(b) as usize
        }
        v => return Err(invalid(&format!("unknown format version {v}"))),
    };
    if len > MAX_HEADER {
        return Err(invalid(&format!(
            "its header of {len} bytes is longer than {MAX_HEADER}"
        )));
    }
    let start = header.len();
    header.resize(start + len, 0);
    reader
        .read_exact(&mut header[start..])
        .map_err(|e| cut_short(e, "its header is cut short"))?;
    let (mut depth, mut deepest) = (0usize, 0usize);
    for &b in &header[start..] {
        match b {
            b'[' | b'(' | b'{' => {
                depth += 1;
                deepest = deepest.max(depth);
            }
            b']' | b')' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    if deepest > MAX_NESTING {
        return Err(invalid(&format!("its header nests brackets {deepest} deep")));
    }
    Ok(header)
}

/// The header's plain dtype as (kind, size in bytes, little-endian or byte order
/// irrelevant); any other dtype is refused with `expected`.
pub(super) fn plain_dtype<R: Read>(
    npy: &NpyFile<R>,
    path: &Path,
    expected: &'static str,
) -> Result<(TypeChar, u64, bool)> {
    match npy.dtype() {
        DType::Plain(ts) => {
            let little = !matches!(ts.endianness(), npyz::Endianness::Big);
            Ok((ts.type_char(), ts.size_field(), little))
        }
        other => Err(Error::Dtype {
            path: path.display().to_string(),
            dtype: other.descr(),
            expected,
        }),
    }
}

/// The dtype as NumPy spells it, e.g. `<c16`.
pub(super) fn dtype_name<R: Read>(npy: &NpyFile<R>) -> String {
    match npy.dtype() {
        DType::Plain(ts) => ts.to_string().replace('\'', ""),
        other => other.descr(),
    }
}

/// The shape of a 2-D array; any other is refused with `layout` (what it must be).
pub(super) fn shape_2d<R: Read>(npy: &NpyFile<R>, path: &Path, layout: &str) -> Result<(usize, usize)> {
    match npy.shape() {
        &[rows, cols] => {
            // A corrupt header may claim more bytes than an address space holds; its
            // element count would wrap and pass a later length check.
            let bytes = rows
                .checked_mul(cols)
                .and_then(|n| n.checked_mul(npy.dtype().num_bytes().unwrap_or(1) as u64));
            match (usize::try_from(rows), usize::try_from(cols)) {
                (Ok(r), Ok(c)) if bytes.is_some_and(|b| b <= isize::MAX as u64) => Ok((r, c)),
                _ => Err(too_large(path, &[rows, cols])),
            }
        }
        shape => Err(not_2d(path, shape, layout)),
    }
}
