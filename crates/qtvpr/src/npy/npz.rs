//! The members of an `.npz` archive that a calibration file reads: each checked
//! against the zip directory before its data is decompressed, then read as a matrix
//! or a string.

use std::fs::File;
use std::io::{self, Cursor, Read, Seek};
use std::path::{Path, PathBuf};

use npyz::npz::NpzArchive;
use npyz::{NpyFile, TypeChar};

use super::header::{MATRIX, dtype_name, parse, plain_dtype, read_header, too_large};
use super::open::{ZIP_LOCAL_HEADER, file_error, io_error, is_regular, open_file};
use super::read::read_matrix;
use crate::error::{Error, Result};

/// The longest `meta` member a calibration file may have (its JSON is under 200 bytes).
const MAX_META_BYTES: u64 = 1 << 20;

/// What a calibration member's `.npy` header declares, read before any of its data.
pub(crate) struct MemberHeader {
    /// The array's shape.
    pub shape: Vec<u64>,
    /// The member's uncompressed size: header and data, as both the zip directory and
    /// the `.npy` header declare it.
    pub size: u64,
    /// `FILE (array NAME)`, for errors.
    pub label: PathBuf,
}

/// The zip member `NAME.npy` of `npz`, refused unless stored or deflated. The method
/// is read from the member's directory entry first (without a decompressor), so that
/// every other method, including one the zip reader does not know (LZMA, XZ, ...), is
/// refused by its name and number rather than with the reader's own words.
fn zip_member<'a, R: Read + Seek>(
    npz: &'a mut NpzArchive<R>,
    name: &str,
    label: &Path,
) -> Result<Option<npyz::zip::read::ZipFile<'a>>> {
    use npyz::zip::CompressionMethod;
    let zip = npz.zip_archive();
    let member = format!("{name}.npy");
    if !zip.file_names().any(|n| n == member) {
        return Ok(None);
    }
    let method = (0..zip.len()).find_map(|i| {
        let raw = zip.by_index_raw(i).ok()?;
        (raw.name() == member).then(|| raw.compression())
    });
    let unsupported = |method| {
        file_error(
            label,
            format!(
                "cannot be decompressed: compression method {} is not supported; \
                 a calibration file holds stored or deflated members",
                method_name(method)
            ),
        )
    };
    match method {
        None | Some(CompressionMethod::Stored | CompressionMethod::Deflated) => {}
        Some(method) => return Err(unsupported(method)),
    }
    let file = zip
        .by_name(&member)
        .map_err(|e| file_error(label, format!("cannot be read: {e}")))?;
    // The local header may disagree with the directory; the reader goes by the latter.
    match file.compression() {
        CompressionMethod::Stored | CompressionMethod::Deflated => Ok(Some(file)),
        method => Err(unsupported(method)),
    }
}

/// A zip compression method as the zip specification (APPNOTE 4.4.5) numbers and names
/// it, e.g. `12 (bzip2)`.
fn method_name(method: npyz::zip::CompressionMethod) -> String {
    #[allow(deprecated)] // the number, for methods the zip crate has no name for
    let number = method.to_u16();
    let name = match number {
        0 => "stored",
        8 => "deflate",
        9 => "deflate64",
        12 => "bzip2",
        14 => "LZMA",
        93 => "zstd",
        95 => "XZ",
        96 => "JPEG",
        97 => "WavPack",
        98 => "PPMd",
        99 => "AES encryption",
        _ => "unknown",
    };
    format!("{number} ({name})")
}

/// The `.npy` header of member `name` of a calibration archive, checked against the
/// member's uncompressed size in the zip directory; no array data is decompressed.
pub(crate) fn npz_member_header<R: Read + Seek>(
    npz: &mut NpzArchive<R>,
    name: &str,
    path: &Path,
) -> Result<Option<MemberHeader>> {
    let label = PathBuf::from(format!("{} (array {name})", path.display()));
    let Some(mut file) = zip_member(npz, name, &label)? else {
        return Ok(None);
    };
    let size = file.size();
    let header = read_header(&mut file, &label)?;
    let header_len = header.len() as u64;
    let npy = parse(Cursor::new(header), &label)?;
    let shape = npy.shape().to_vec();
    let claim = npy.dtype().num_bytes().and_then(|item| {
        shape
            .iter()
            .try_fold(item as u64, |n, &d| n.checked_mul(d))
            .and_then(|n| n.checked_add(header_len))
    });
    match claim {
        Some(claim) if claim == size => {}
        Some(claim) => {
            return Err(file_error(
                &label,
                format!(
                    "is corrupt: the zip directory says it holds {size} bytes, its .npy header \
                     declares {claim}"
                ),
            ));
        }
        None => return Err(too_large(&label, &shape)),
    }
    if name == "meta" && size > MAX_META_BYTES {
        return Err(file_error(
            &label,
            format!("is {size} bytes; a calibration's meta is under {MAX_META_BYTES}"),
        ));
    }
    Ok(Some(MemberHeader { shape, size, label }))
}

/// Member `header` of a calibration archive read whole: never past its declared size,
/// to its end, so that the zip reader checks its CRC-32; then parsed.
pub(crate) fn npz_member_data<R: Read + Seek>(
    npz: &mut NpzArchive<R>,
    name: &str,
    header: &MemberHeader,
) -> Result<NpyFile<impl Read>> {
    let label = &header.label;
    let file = zip_member(npz, name, label)?.ok_or_else(|| file_error(label, "is missing"))?;
    let size = usize::try_from(header.size).map_err(|_| too_large(label, &header.shape))?;
    let mut bytes = Vec::new();
    bytes.try_reserve_exact(size).map_err(|_| {
        file_error(
            label,
            format!("declares {size} bytes, more memory than can be allocated"),
        )
    })?;
    // One byte more than declared, to tell a member that expands further.
    file.take(header.size + 1).read_to_end(&mut bytes).map_err(|e| {
        if e.to_string().contains("Invalid checksum") {
            file_error(label, "is corrupt: its CRC-32 does not match its data")
        } else {
            file_error(label, format!("is corrupt: {e}"))
        }
    })?;
    match bytes.len().cmp(&size) {
        std::cmp::Ordering::Less => Err(file_error(
            label,
            format!("is truncated: it holds {} of its {size} bytes", bytes.len()),
        )),
        std::cmp::Ordering::Greater => Err(file_error(
            label,
            format!("is corrupt: it decompresses past its declared {size} bytes"),
        )),
        std::cmp::Ordering::Equal => parse(Cursor::new(bytes), label),
    }
}

/// Open an `.npz` archive, naming `path` if it is not one.
pub(crate) fn open_npz<R: Read + Seek>(reader: R, path: &Path) -> Result<NpzArchive<R>> {
    NpzArchive::new(reader).map_err(|e| file_error(path, format!("is not a valid .npz archive: {e}")))
}

/// Open the `.npz` archive `path`: a regular file is read where it lies; a stream (a
/// FIFO with a writer, a pipe, a device) is read whole into memory first, since a zip
/// archive is read from its end.
pub(crate) fn open_npz_file(path: &Path) -> Result<NpzArchive<NpzInput>> {
    let file = open_file(path)?;
    let input = if is_regular(&file) {
        NpzInput::File(io::BufReader::new(file))
    } else {
        NpzInput::Stream(Cursor::new(read_stream(file, path)?))
    };
    open_npz(input, path)
}

/// Where an `.npz` archive is read from: a seekable file, or the bytes of a stream.
pub(crate) enum NpzInput {
    /// A regular file.
    File(io::BufReader<File>),
    /// A stream read to its end.
    Stream(Cursor<Vec<u8>>),
}

impl Read for NpzInput {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self {
            NpzInput::File(f) => f.read(buf),
            NpzInput::Stream(c) => c.read(buf),
        }
    }
}

impl Seek for NpzInput {
    fn seek(&mut self, pos: io::SeekFrom) -> io::Result<u64> {
        match self {
            NpzInput::File(f) => f.seek(pos),
            NpzInput::Stream(c) => c.seek(pos),
        }
    }
}

/// The whole of stream `file` (`path` names it): it must start as a zip archive does
/// (so that `/dev/zero` or a `.npy` is refused at once, not read forever), and memory
/// for it is reserved fallibly, so that an endless stream is an error when memory runs
/// out, never an abort.
fn read_stream(mut file: File, path: &Path) -> Result<Vec<u8>> {
    const CHUNK: usize = 1 << 16;
    let mut bytes = Vec::new();
    let mut chunk = vec![0u8; CHUNK];
    loop {
        let n = match file.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(io_error(path, &e)),
        };
        bytes.try_reserve(n).map_err(|_| {
            file_error(
                path,
                format!(
                    "is a stream of more than {} bytes, more memory than can be allocated",
                    bytes.len()
                ),
            )
        })?;
        bytes.extend_from_slice(&chunk[..n]);
        if bytes.len() >= ZIP_LOCAL_HEADER.len() && !bytes.starts_with(ZIP_LOCAL_HEADER) {
            return Err(file_error(
                path,
                "is not a valid .npz archive: a stream must start with a zip local header (PK\\x03\\x04)",
            ));
        }
    }
    Ok(bytes)
}

/// A float32/float64 matrix read into memory from `npy` (`path` names it).
pub(crate) fn read_owned_scores<R: Read>(npy: NpyFile<R>, path: &Path) -> Result<crate::input::ScoreMatrix> {
    use crate::input::ScoreMatrix;
    const RULE: &str = "expected float32 or float64 similarity scores";
    match plain_dtype(&npy, path, RULE)? {
        (TypeChar::Float, 4, _) => Ok(ScoreMatrix::F32(read_matrix(npy, path, MATRIX)?.into_array())),
        (TypeChar::Float, 8, _) => Ok(ScoreMatrix::F64(read_matrix(npy, path, MATRIX)?.into_array())),
        _ => Err(Error::Dtype {
            path: path.display().to_string(),
            dtype: dtype_name(&npy),
            expected: RULE,
        }),
    }
}

/// A bool matrix read from `npy` (`path` names it); other dtypes are refused.
pub(crate) fn read_bool_matrix<R: Read>(npy: NpyFile<R>, path: &Path) -> Result<ndarray::Array2<bool>> {
    const RULE: &str = "expected bool";
    match plain_dtype(&npy, path, RULE)? {
        (TypeChar::Bool, 1, _) => Ok(read_matrix(npy, path, MATRIX)?.into_array()),
        _ => Err(Error::Dtype {
            path: path.display().to_string(),
            dtype: dtype_name(&npy),
            expected: RULE,
        }),
    }
}

/// A 0-d unicode string (`<U{n}`, shape `()`) read from `npy` (`path` names it).
pub(crate) fn read_string<R: Read>(npy: NpyFile<R>, path: &Path) -> Result<String> {
    let (kind, _, _) = plain_dtype(&npy, path, "expected a string").map_err(|_| not_a_string(&npy, path))?;
    if kind != TypeChar::UnicodeStr || !npy.shape().is_empty() {
        return Err(not_a_string(&npy, path));
    }
    let mut values: Vec<String> = npy
        .into_vec()
        .map_err(|e| file_error(path, format!("is truncated or corrupt: {e}")))?;
    match values.len() {
        1 => Ok(values.pop().expect("one value")),
        _ => Err(file_error(path, "is truncated or corrupt: a 0-d array holds one value")),
    }
}

fn not_a_string<R: Read>(npy: &NpyFile<R>, path: &Path) -> Error {
    file_error(
        path,
        format!(
            "holds an array of dtype {} and shape {:?}, expected a 0-d unicode string",
            dtype_name(npy),
            npy.shape()
        ),
    )
}
