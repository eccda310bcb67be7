//! Writing `.npy` files and `.npz` archives, atomically: a temporary file next to the
//! target is filled and renamed over it.

use std::fs::File;
use std::io::{self, BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

use ndarray::ArrayView2;
use npyz::{DType, WriterBuilder};

use crate::error::{Error, Result};
use crate::input::ScoresView;

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
    /// The array as one `.npy` stream: header, then data in C order.
    ///
    /// # Errors
    /// What writing to `w` returns.
    pub fn write_to(&self, w: &mut impl Write) -> io::Result<()> {
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
///
/// rawzip writes each member's CRC-32 and sizes in a data descriptor after its data
/// (so `w` need not seek), with no time stamp, so that the same arrays give the same
/// bytes and a calibration file is reproducible; zip64 records where a member needs them.
pub(crate) fn write_npz_to<W: Write>(w: W, arrays: &[(&str, NpyArray<'_>)]) -> io::Result<()> {
    fn zip_error(e: rawzip::Error) -> io::Error {
        match e.into_kind() {
            rawzip::ErrorKind::IO(e) => e,
            kind => io::Error::other(rawzip::Error::from(kind)),
        }
    }
    let mut zip = rawzip::ZipArchiveWriter::new(w);
    for (name, array) in arrays {
        let member = format!("{name}.npy");
        let (mut entry, config) = zip
            .new_file(member.as_str())
            .compression_method(rawzip::CompressionMethod::STORE)
            .start()
            .map_err(zip_error)?;
        let mut data = config.wrap(&mut entry);
        array.write_to(&mut data)?;
        let (_, descriptor) = data.finish().map_err(zip_error)?;
        entry.finish(descriptor).map_err(zip_error)?;
    }
    zip.finish().map_err(zip_error)?;
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
        // content is made in an anonymous temporary file first, then streamed, so that
        // a failure to make it sends nothing.
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
    keep_owner_and_mode(&target, tmp.as_file()).map_err(|e| write_error(path, &e))?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file_mut());
        write(&mut w)
            .and_then(|()| w.flush())
            .map_err(|e| write_error(path, &e))?;
    }
    tmp.persist(&target).map_err(|e| write_error(path, &e.error))?;
    Ok(())
}

/// Give `tmp`, about to replace the regular file `target`, that file's owner, group and
/// mode, so that overwriting a private (0600) file or one shared with a group keeps it
/// so. A new file keeps the plain-create mode. Where the owner cannot be given (a user
/// other than root overwriting another user's file in a directory it may write), the
/// file becomes the writer's, as any replaced file does; its mode is kept all the same.
fn keep_owner_and_mode(target: &Path, tmp: &File) -> io::Result<()> {
    let Ok(existing) = std::fs::metadata(target) else {
        return Ok(());
    };
    if !existing.is_file() {
        return Ok(());
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        // Before the mode: a change of owner clears the set-user-ID and set-group-ID bits.
        match std::os::unix::fs::fchown(tmp, Some(existing.uid()), Some(existing.gid())) {
            Err(e) if e.kind() != io::ErrorKind::PermissionDenied => return Err(e),
            _ => {}
        }
    }
    tmp.set_permissions(existing.permissions())
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
