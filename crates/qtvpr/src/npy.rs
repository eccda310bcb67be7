//! Reading `.npy` / `.npz` files (feature `npy`): the I/O the CLI and the Python binding
//! share, so that both accept exactly the same files with exactly the same errors.
//!
//! Not a section of the semantics. Similarity matrices (float32/float64, little-endian, C or Fortran
//! order) are **memory-mapped** and viewed in place, so a matrix near the size of RAM
//! costs no copy and only the pages the computation touches; anything else (big-endian,
//! misaligned data, a file that cannot be mapped) is read into memory by npyz. Ground
//! truth (bool or integer 0/1) is read by npyz and turned into a [`GroundTruth`] at once;
//! an `.npz` in the VPR_Tutorial convention (`GThard`, optional `GTsoft`) is accepted.
//!
//! Writing ([`write_npy`], [`write_npz`], [`write_atomically`]) is atomic: a temporary
//! file next to the target is filled and renamed over it, so an error never leaves a
//! half-written file, and the file gets the mode a plain create would give it under the
//! user's umask (0644 under umask 022), not a temporary file's 0600.
//!
//! Every error names the file and says what is wrong with it. A header is checked before
//! npyz parses it (at most 10000 bytes, as NumPy's `max_header_size`, and brackets at
//! most 6 deep), and a shape is checked against the largest possible array, so that a
//! corrupt or hostile file can neither hang the parser nor make the reader panic.

use std::fs::File;
use std::io::{self, BufWriter, Cursor, Read, Seek, Write};
use std::path::{Path, PathBuf};

use memmap2::Mmap;
use ndarray::{ArrayView2, ShapeBuilder};
use npyz::npz::NpzArchive;
use npyz::{DType, NpyFile, Order, TypeChar, WriterBuilder};

use crate::error::{Error, Result};
use crate::input::{GroundTruth, ScoresView};

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

/// The layout every 2-D input but descriptors and positions is told it must have.
const MATRIX: &str = "a 2-D matrix";

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

fn too_large(path: &Path, shape: &[u64]) -> Error {
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

fn file_error(path: &Path, message: impl Into<String>) -> Error {
    Error::File {
        path: path.display().to_string(),
        message: message.into(),
    }
}

fn io_error(path: &Path, e: &io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        kind: e.kind(),
        message: e.to_string(),
    }
}

fn open_file(path: &Path) -> Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    // Never block in open(2): a FIFO without a writer would wait for one forever.
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NONBLOCK);
    let file = options.open(path).map_err(|e| io_error(path, &e))?;
    let kind = file.metadata().map_err(|e| io_error(path, &e))?.file_type();
    if kind.is_dir() {
        return Err(Error::Io {
            path: path.display().to_string(),
            kind: io::ErrorKind::IsADirectory,
            message: "is a directory, not a file".into(),
        });
    }
    #[cfg(unix)]
    {
        if std::os::unix::fs::FileTypeExt::is_fifo(&kind) && !has_writer(&file) {
            return Err(Error::Io {
                path: path.display().to_string(),
                kind: io::ErrorKind::BrokenPipe,
                message: "is a FIFO with no writer".into(),
            });
        }
        blocking(&file).map_err(|e| io_error(path, &e))?;
    }
    Ok(file)
}

/// Clear the `O_NONBLOCK` that [`open_file`] opened `file` with: a stream is then read
/// as it comes.
#[cfg(unix)]
fn blocking(file: &File) -> io::Result<()> {
    use std::os::fd::AsRawFd;
    let fd = file.as_raw_fd();
    // SAFETY: fcntl on a descriptor this function borrows; F_GETFL/F_SETFL touch no memory.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    if flags < 0 || unsafe { libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// Whether the FIFO `file` (opened with `O_NONBLOCK`) has a writer, or data left by one.
/// tee(2) copies without consuming: 0 bytes means end of stream (no writer and nothing
/// to read), EAGAIN an open writer that has not written yet. Linux only; elsewhere the
/// reader finds the end of stream itself.
#[cfg(unix)]
fn has_writer(file: &File) -> bool {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let mut pipe = [0; 2];
        // SAFETY: pipe2 writes two descriptors into `pipe`, which this function closes.
        if unsafe { libc::pipe2(pipe.as_mut_ptr(), libc::O_CLOEXEC | libc::O_NONBLOCK) } != 0 {
            return true;
        }
        // SAFETY: tee between two pipe descriptors; no memory is touched.
        let copied = unsafe { libc::tee(file.as_raw_fd(), pipe[1], 1, libc::SPLICE_F_NONBLOCK) };
        // SAFETY: the two descriptors pipe2 made, closed once.
        unsafe {
            libc::close(pipe[0]);
            libc::close(pipe[1]);
        }
        copied != 0
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = file;
        true
    }
}

/// Whether `file` (from [`open_file`]) is a regular file, the only kind memory-mapped:
/// a device or a pipe is read as a stream.
fn is_regular(file: &File) -> bool {
    file.metadata().is_ok_and(|m| m.is_file())
}

/// Open input `path` for reading as [`open_file`] does (never blocking on a FIFO
/// without a writer; a directory is an error), and say whether it is a regular file
/// (seekable, mappable) rather than a stream.
///
/// # Errors
/// [`Error::Io`] naming `path`.
pub fn open_input(path: &Path) -> Result<(File, bool)> {
    let file = open_file(path)?;
    let regular = is_regular(&file);
    Ok((file, regular))
}

/// Whether `path` is a zip archive (an `.npz`, e.g. a calibration file) rather than a
/// `.npy`: by its bytes, whatever its name, as the zip reader of
/// [`crate::Calibration::load`] finds an archive. A file
/// that starts with a zip local header is one; so is a file that does not start as a
/// `.npy` and has a zip end-of-central-directory record in its last 64 KiB (a zip with
/// something prepended, such as a self-extracting archive, which the zip reader finds
/// from the end). A file that cannot be read is left to the reader that follows, which
/// names the problem; so is a stream (a pipe or a device), whose first bytes cannot be
/// read twice.
pub fn is_zip_archive(path: &Path) -> bool {
    match open_input(path) {
        Ok((file, true)) => has_zip_signature(file).unwrap_or(false),
        _ => false,
    }
}

/// The `.npy` magic string.
const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// The signature a zip archive starts with: its first local file header.
const ZIP_LOCAL_HEADER: &[u8] = b"PK\x03\x04";

/// How far from its end the zip reader looks for the end-of-central-directory record:
/// the record (22 bytes) and the longest comment (65535).
const EOCD_SEARCH: u64 = 22 + 65_535;

/// See [`is_zip_archive`].
fn has_zip_signature(mut file: File) -> io::Result<bool> {
    use io::SeekFrom;
    let mut head = [0u8; 6];
    let n = file.read(&mut head)?;
    if head[..n].starts_with(ZIP_LOCAL_HEADER) {
        return Ok(true);
    }
    if n == NPY_MAGIC.len() && head[..] == *NPY_MAGIC {
        return Ok(false);
    }
    let len = file.seek(SeekFrom::End(0))?;
    file.seek(SeekFrom::Start(len.saturating_sub(EOCD_SEARCH)))?;
    let mut tail = Vec::new();
    file.take(EOCD_SEARCH).read_to_end(&mut tail)?;
    Ok(tail.windows(4).any(|w| w == b"PK\x05\x06"))
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
fn parse<R: Read>(mut reader: R, path: &Path) -> Result<NpyFile<io::Chain<Cursor<Vec<u8>>, R>>> {
    let header = read_header(&mut reader, path)?;
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
fn read_header<R: Read>(mut reader: R, path: &Path) -> Result<Vec<u8>> {
    let invalid = |what: &str| file_error(path, format!("is not a valid .npy file: {what}"));
    let mut header = vec![0u8; 8];
    reader
        .read_exact(&mut header)
        .map_err(|_| invalid("it is shorter than the magic string"))?;
    if &header[..6] != NPY_MAGIC {
        return Err(invalid("it does not start with the magic string \\x93NUMPY"));
    }
    let len = match header[6] {
        1 => {
            let mut b = [0u8; 2];
            reader
                .read_exact(&mut b)
                .map_err(|_| invalid("its header is cut short"))?;
            header.extend(b);
            usize::from(u16::from_le_bytes(b))
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            reader
                .read_exact(&mut b)
                .map_err(|_| invalid("its header is cut short"))?;
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
        .map_err(|_| invalid("its header is cut short"))?;
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

/// Array `name` of an `.npz` archive, if it has one, read through [`parse`].
fn npz_array<'a, R: Read + io::Seek>(
    npz: &'a mut NpzArchive<R>,
    name: &str,
    path: &Path,
) -> Result<Option<NpyFile<impl Read + 'a>>> {
    let zip = npz.zip_archive();
    let member = format!("{name}.npy");
    if !zip.file_names().any(|n| n == member) {
        return Ok(None);
    }
    let file = zip
        .by_name(&member)
        .map_err(|e| file_error(path, format!("cannot read {name}: {e}")))?;
    parse(file, path).map(Some)
}

/// The header's plain dtype as (kind, size in bytes, little-endian or byte order
/// irrelevant); any other dtype is refused with `expected`.
fn plain_dtype<R: Read>(npy: &NpyFile<R>, path: &Path, expected: &'static str) -> Result<(TypeChar, u64, bool)> {
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
fn dtype_name<R: Read>(npy: &NpyFile<R>) -> String {
    match npy.dtype() {
        DType::Plain(ts) => ts.to_string().replace('\'', ""),
        other => other.descr(),
    }
}

/// The shape of a 2-D array; any other is refused with `layout` (what it must be).
fn shape_2d<R: Read>(npy: &NpyFile<R>, path: &Path, layout: &str) -> Result<(usize, usize)> {
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

/// Read a whole matrix into memory; a shape other than 2-D is refused with `layout`.
///
/// The header's claim decides no allocation by itself: the buffer grows (fallibly, at
/// most doubling) with the values actually read, so a small file whose header claims
/// terabytes is "truncated" after reading what it holds, and memory that cannot be
/// allocated is an error, never an abort (npyz's `into_vec` reserves the claim
/// infallibly, hence this loop).
fn read_matrix<T: npyz::Deserialize, R: Read>(npy: NpyFile<R>, path: &Path, layout: &str) -> Result<Matrix<T>> {
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
            data.try_reserve_exact(more).map_err(|_| {
                file_error(
                    path,
                    format!(
                        "declares a {}x{} matrix, more memory than can be allocated",
                        dim.0, dim.1
                    ),
                )
            })?;
        }
        match value {
            Ok(v) => data.push(v),
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Err(truncated(data.len())),
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
    fn into_array(self) -> ndarray::Array2<T> {
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
    read_unmapped(bytes, Path::new(name), FloatMatrix::Similarity)
}

/// Read hard ground truth from the bytes of a `.npy` file, as [`scores_from_bytes`].
///
/// # Errors
/// As [`read_hard_ground_truth`].
pub fn ground_truth_from_bytes(bytes: &[u8], name: &str) -> Result<GroundTruth> {
    let path = Path::new(name);
    ground_truth_of(parse(bytes, path)?, path, None)
}

/// Labels of one ground-truth array, added to `hard` as soft ground truth if given.
fn ground_truth_of<R: Read>(npy: NpyFile<R>, path: &Path, hard: Option<GroundTruth>) -> Result<GroundTruth> {
    macro_rules! labels {
        ($t:ty) => {{
            let m = read_matrix::<$t, R>(npy, path, MATRIX)?.into_array();
            match hard {
                None => GroundTruth::new(m.view()),
                Some(hard) => hard.with_soft(m.view()),
            }
        }};
    }
    const RULE: &str = "expected bool or integer 0/1 ground truth";
    let gt = match plain_dtype(&npy, path, RULE)? {
        (TypeChar::Bool, _, _) => labels!(bool),
        (TypeChar::Uint, 1, _) => labels!(u8),
        (TypeChar::Uint, 2, _) => labels!(u16),
        (TypeChar::Uint, 4, _) => labels!(u32),
        (TypeChar::Uint, 8, _) => labels!(u64),
        (TypeChar::Int, 1, _) => labels!(i8),
        (TypeChar::Int, 2, _) => labels!(i16),
        (TypeChar::Int, 4, _) => labels!(i32),
        (TypeChar::Int, 8, _) => labels!(i64),
        _ => {
            return Err(Error::Dtype {
                path: path.display().to_string(),
                dtype: dtype_name(&npy),
                expected: RULE,
            });
        }
    };
    gt.map_err(|e| Error::InFile {
        path: path.display().to_string(),
        error: Box::new(e),
    })
}

/// Read hard ground truth, and soft ground truth if given, into one [`GroundTruth`].
///
/// `hard` may be an `.npy` file or an `.npz` archive in the VPR_Tutorial convention
/// (`GThard`, optional `GTsoft`); an explicit `soft` file takes precedence over `GTsoft`.
/// The result is in the files' orientation, as are the positions in its errors.
///
/// # Errors
/// As [`read_scores`] (with bool/integer in place of float), an `.npz` without
/// `GThard`, and [`Error::InFile`] around [`Error::BadLabel`] / [`Error::ShapeMismatch`]
/// for the labels.
pub fn read_ground_truth(hard: &Path, soft: Option<&Path>) -> Result<GroundTruth> {
    let gt = if is_npz(hard) {
        let (gt, mut npz) = read_gthard(hard)?;
        if soft.is_none()
            && let Some(npy) = npz_array(&mut npz, "GTsoft", hard)?
        {
            return ground_truth_of(npy, hard, Some(gt));
        }
        gt
    } else {
        read_hard_ground_truth(hard)?
    };
    match soft {
        Some(path) => add_soft_ground_truth(gt, path),
        None => Ok(gt),
    }
}

/// Read hard ground truth only: an `.npy` file, or `GThard` of an `.npz` archive (its
/// `GTsoft`, if any, is not read). For a caller that has the soft ground truth elsewhere.
///
/// # Errors
/// As [`read_ground_truth`].
pub fn read_hard_ground_truth(path: &Path) -> Result<GroundTruth> {
    if is_npz(path) {
        Ok(read_gthard(path)?.0)
    } else {
        ground_truth_of(parse(io::BufReader::new(open_file(path)?), path)?, path, None)
    }
}

/// Add the soft ground truth of `.npy` file `path` to `hard` (entries soft but not hard
/// become ignored).
///
/// # Errors
/// As [`read_ground_truth`]; a shape other than `hard`'s is an [`Error::InFile`] around
/// [`Error::ShapeMismatch`].
pub fn add_soft_ground_truth(hard: GroundTruth, path: &Path) -> Result<GroundTruth> {
    ground_truth_of(parse(io::BufReader::new(open_file(path)?), path)?, path, Some(hard))
}

fn is_npz(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"))
}

/// `GThard` of an `.npz` archive, and the archive (for its `GTsoft`).
fn read_gthard(path: &Path) -> Result<(GroundTruth, NpzArchive<NpzInput>)> {
    let mut npz = open_npz_file(path)?;
    let npy = npz_array(&mut npz, "GThard", path)?
        .ok_or_else(|| file_error(path, "has no array GThard (VPR_Tutorial convention: GThard, GTsoft)"))?;
    let gt = ground_truth_of(npy, path, None)?;
    Ok((gt, npz))
}

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

/// An array to write: a matrix of float32, float64 or bool, or a 0-d unicode string
/// (NumPy dtype `<U{n}`, UTF-32LE, shape `()`; `np.load(...)["meta"][()]` gives the
/// `str` back).
#[derive(Debug, Clone, Copy)]
pub enum NpyArray<'a> {
    /// float32 matrix (`<f4`).
    F32(ArrayView2<'a, f32>),
    /// float64 matrix (`<f8`).
    F64(ArrayView2<'a, f64>),
    /// bool matrix (`|b1`).
    Bool(ArrayView2<'a, bool>),
    /// 0-d unicode string.
    Str(&'a str),
}

impl<'a> From<ArrayView2<'a, f32>> for NpyArray<'a> {
    fn from(m: ArrayView2<'a, f32>) -> Self {
        NpyArray::F32(m)
    }
}

impl<'a> From<ArrayView2<'a, f64>> for NpyArray<'a> {
    fn from(m: ArrayView2<'a, f64>) -> Self {
        NpyArray::F64(m)
    }
}

impl<'a> From<ArrayView2<'a, bool>> for NpyArray<'a> {
    fn from(m: ArrayView2<'a, bool>) -> Self {
        NpyArray::Bool(m)
    }
}

impl<'a> From<&'a str> for NpyArray<'a> {
    fn from(s: &'a str) -> Self {
        NpyArray::Str(s)
    }
}

impl<'a> From<ScoresView<'a>> for NpyArray<'a> {
    fn from(s: ScoresView<'a>) -> Self {
        match s {
            ScoresView::F32(m) => NpyArray::F32(m),
            ScoresView::F64(m) => NpyArray::F64(m),
        }
    }
}

impl NpyArray<'_> {
    /// Bytes of data (for the zip64 decision).
    fn data_bytes(&self) -> u64 {
        match self {
            NpyArray::F32(m) => 4 * m.len() as u64,
            NpyArray::F64(m) => 8 * m.len() as u64,
            NpyArray::Bool(m) => m.len() as u64,
            NpyArray::Str(s) => 4 * s.chars().count() as u64,
        }
    }

    /// The array as one `.npy` stream: header, then data in C order.
    pub(crate) fn write_to(&self, w: &mut impl Write) -> io::Result<()> {
        match *self {
            NpyArray::F32(m) => write_matrix(w, m),
            NpyArray::F64(m) => write_matrix(w, m),
            NpyArray::Bool(m) => write_matrix(w, m),
            NpyArray::Str(s) => {
                let n = s.chars().count().max(1);
                let dtype = DType::new_scalar(format!("<U{n}").parse().expect("a valid unicode type string"));
                npyz::WriteOptions::new_header_only()
                    .dtype(dtype)
                    .shape(&[])
                    .writer(&mut *w)
                    .write_header_only()?;
                let mut data: Vec<u8> = s.chars().flat_map(|c| u32::from(c).to_le_bytes()).collect();
                data.resize(4 * n, 0);
                w.write_all(&data)
            }
        }
    }
}

/// A matrix element written as raw little-endian bytes after an `.npy` header.
trait NpyElement: Copy + npyz::AutoSerialize {
    /// Append the element's bytes.
    fn put(self, out: &mut Vec<u8>);
}

impl NpyElement for f32 {
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElement for f64 {
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElement for bool {
    fn put(self, out: &mut Vec<u8>) {
        out.push(u8::from(self));
    }
}

/// A C-order `.npy` stream of `m`, any strides, a row at a time.
fn write_matrix<T: NpyElement>(w: &mut impl Write, m: ArrayView2<'_, T>) -> io::Result<()> {
    npyz::WriteOptions::<T>::new()
        .default_dtype()
        .shape(&[m.nrows() as u64, m.ncols() as u64])
        .writer(&mut *w)
        .write_header_only()?;
    let mut buf = Vec::new();
    for row in m.rows() {
        buf.clear();
        row.iter().for_each(|v| v.put(&mut buf));
        w.write_all(&buf)?;
    }
    Ok(())
}

/// An uncompressed `.npz` archive of `arrays` (as `numpy.savez` writes) into `w`.
pub(crate) fn write_npz_to<W: Write + Seek>(w: W, arrays: &[(&str, NpyArray<'_>)]) -> io::Result<()> {
    let mut zip = npyz::zip::ZipWriter::new(w);
    for (name, array) in arrays {
        // A fixed time stamp (zip's earliest, 1980-01-01), not the clock's: the same
        // arrays give the same bytes, so a calibration file is reproducible.
        let options = npyz::zip::write::FileOptions::default()
            .last_modified_time(npyz::zip::DateTime::default())
            .compression_method(npyz::zip::CompressionMethod::Stored)
            .large_file(array.data_bytes() >= u64::from(u32::MAX) / 2);
        zip.start_file(npyz::npz::file_name_from_array_name(name), options)?;
        array.write_to(&mut zip)?;
    }
    zip.finish()?;
    Ok(())
}

fn write_error(path: &Path, e: &io::Error) -> Error {
    Error::Write {
        path: path.display().to_string(),
        kind: e.kind(),
        message: e.to_string(),
    }
}

/// Write `path` atomically: `write` fills a temporary file next to it (buffered), which
/// then replaces `path`. On any error nothing is left behind and `path` is untouched.
/// The file gets the mode a plain create gives (`0666` less the umask), not a
/// temporary file's `0600`.
///
/// # Errors
/// [`Error::Write`] naming `path`.
pub fn write_atomically(path: &Path, write: impl FnOnce(&mut BufWriter<&mut File>) -> io::Result<()>) -> Result<()> {
    let target = resolve_output(path)?;
    if let Some(mut file) = open_in_place(path, &target)? {
        // A device or FIFO: written in place, never replaced by a regular file. The
        // content is made in an anonymous temporary file first (the `.npz` writer
        // seeks, a FIFO cannot), then streamed; a failure to make it sends nothing.
        let mut tmp = tempfile::tempfile().map_err(|e| write_error(path, &e))?;
        {
            let mut w = BufWriter::with_capacity(1 << 20, &mut tmp);
            write(&mut w)
                .and_then(|()| w.flush())
                .map_err(|e| write_error(path, &e))?;
        }
        return tmp
            .rewind()
            .and_then(|()| io::copy(&mut tmp, &mut file))
            .and_then(|_| file.flush())
            .map_err(|e| write_error(path, &e));
    }
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // open(2) applies the umask to this mode, exactly as for a plain create.
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(|e| write_error(path, &e))?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file_mut());
        write(&mut w)
            .and_then(|()| w.flush())
            .map_err(|e| write_error(path, &e))?;
    }
    tmp.persist(&target).map_err(|e| write_error(path, &e.error))?;
    Ok(())
}

/// Follow `path` through any chain of symbolic links to the file really written: the
/// link itself stays a link. A dangling link resolves to its (missing) target, which is
/// then created.
fn resolve_output(path: &Path) -> Result<PathBuf> {
    let mut current = path.to_path_buf();
    // The kernel's own limit on nested links (ELOOP past it).
    for _ in 0..40 {
        match std::fs::symlink_metadata(&current) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = std::fs::read_link(&current).map_err(|e| write_error(path, &e))?;
                current = match current.parent() {
                    Some(dir) if link.is_relative() => dir.join(link),
                    _ => link,
                };
            }
            _ => return Ok(current),
        }
    }
    Err(write_error(
        path,
        &io::Error::other("too many levels of symbolic links"),
    ))
}

/// Open `target` for writing in place when it exists and is not a regular file (a
/// device, FIFO or socket); `None` for a regular or missing file. A directory is an
/// error, and so is a FIFO that nobody reads: opening it never waits.
fn open_in_place(path: &Path, target: &Path) -> Result<Option<File>> {
    let meta = match std::fs::metadata(target) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(write_error(path, &e)),
    };
    if meta.is_file() {
        return Ok(None);
    }
    if meta.is_dir() {
        return Err(write_error(path, &io::Error::other("is a directory")));
    }
    let mut options = std::fs::OpenOptions::new();
    options.write(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(target).map_err(|e| {
        #[cfg(unix)]
        if e.raw_os_error() == Some(libc::ENXIO) {
            return write_error(path, &io::Error::other("is a FIFO that nobody reads"));
        }
        write_error(path, &e)
    })?;
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        // Writes block as usual once open: a slow reader is waited for, not an error.
        let fd = file.as_raw_fd();
        // SAFETY: fcntl on a descriptor this function owns, with integer arguments only.
        let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
        if flags < 0 || unsafe { libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) } < 0 {
            return Err(write_error(path, &io::Error::last_os_error()));
        }
    }
    Ok(Some(file))
}

/// Write one array as an `.npy` file (C order), atomically.
///
/// # Errors
/// [`Error::Write`] naming `path`.
pub fn write_npy<'a>(path: &Path, array: impl Into<NpyArray<'a>>) -> Result<()> {
    let array = array.into();
    write_atomically(path, |w| array.write_to(w))
}

/// Write arrays into one uncompressed `.npz` archive (as `numpy.savez`), atomically;
/// `np.load` reads it without pickle.
///
/// # Errors
/// [`Error::Write`] naming `path`.
pub fn write_npz(path: &Path, arrays: &[(&str, NpyArray<'_>)]) -> Result<()> {
    write_atomically(path, |w| write_npz_to(w, arrays))
}

#[cfg(test)]
mod tests {
    use super::*;

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
