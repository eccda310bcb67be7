//! Opening an input: a file, a FIFO or a device, never blocking on a FIFO without a
//! writer; telling a zip archive from a `.npy` by its bytes; the errors that name a file.

use std::fs::File;
use std::io::{self, Read, Seek};
use std::path::Path;

use crate::error::{Error, Result};

pub(super) fn file_error(path: &Path, message: impl Into<String>) -> Error {
    Error::File {
        path: path.display().to_string(),
        message: message.into(),
    }
}

pub(super) fn io_error(path: &Path, e: &io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        kind: e.kind(),
        message: e.to_string(),
    }
}

pub(super) fn open_file(path: &Path) -> Result<File> {
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
pub(super) fn is_regular(file: &File) -> bool {
    file.metadata().is_ok_and(|m| m.is_file())
}

/// Open input `path` for reading as `open_file` does (never blocking on a FIFO
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
/// [`Calibration::load`](crate::operations::calibration::Calibration::load) finds an archive. A file
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
pub(super) const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// The signature a zip archive starts with: its first local file header.
pub(super) const ZIP_LOCAL_HEADER: &[u8] = b"PK\x03\x04";

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
