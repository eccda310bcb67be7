//! The zip layer of every `.npz` this library reads (calibration files and ground
//! truth): the archive's directory and every member's local header checked before a
//! byte is decompressed, and each member then read as a bounded, verified stream.
//!
//! [rawzip](https://crates.io/crates/rawzip) parses the archive and decompresses
//! nothing; the only decompressor built is flate2's deflate. So no AES, bzip2, zstd or
//! LZMA code is compiled at all, and a member that names one of them is refused by its
//! number and name, from its directory entry. What semantics §12 asks of an `.npz`,
//! checked for every member when the archive is opened:
//! - stored (0) or deflated (8), in the directory and the local header alike;
//! - not encrypted: no encryption flag (ZipCrypto), no strong encryption, no masked
//!   header, no AES extra field (WinZip AE-1/AE-2, method 99);
//! - one member per name (names compared as the bytes the archive holds: a name that is
//!   not UTF-8 is a name like any other, shown lossily in messages only);
//! - the local header agrees with the directory (name, method, CRC-32 and sizes; with a
//!   data descriptor, the descriptor does);
//! - a stored member's compressed and uncompressed sizes are equal;
//! - the directory lies where the end record declares it, or after bytes prepended to
//!   the archive (a self-extracting archive), which shift every local header alike.
//!
//! A member is then read through [`Member`]: never decompressed past the size the
//! directory declares, and its CRC-32 and size compared when its last byte is read.
//! A member no reader reads to its end (one the library does not use) is read into
//! nothing by [`Archive::check_unread_members`], so that its CRC-32 is checked too.

use std::cell::Cell;
use std::collections::HashSet;
use std::fs::File;
use std::io::{self, Read};
use std::path::{Path, PathBuf};

use rawzip::extra_fields::ExtraFieldId;
use rawzip::{CompressionMethod, EntryFlags, ReaderAt, ZipArchiveEntryWayfinder};

use super::open::{ZIP_LOCAL_HEADER, file_error, io_error, is_regular, open_file};
use crate::error::{Error, Result};

/// The most members an `.npz` may have here: a calibration file has at most 4, a
/// VPR_Tutorial ground truth 2. A directory that lists more is refused before its
/// entries are kept.
const MAX_MEMBERS: usize = 4096;

/// Where an archive is read from: a regular file, read where it lies, or the bytes of a
/// stream (a FIFO or a device), read whole, since a zip archive is read from its end.
pub(crate) enum Source {
    /// A regular file.
    File(rawzip::FileReader),
    /// A stream read to its end.
    Bytes(Vec<u8>),
}

impl ReaderAt for Source {
    fn read_at(&self, buf: &mut [u8], offset: u64) -> io::Result<usize> {
        match self {
            Source::File(f) => f.read_at(buf, offset),
            Source::Bytes(b) => b.read_at(buf, offset),
        }
    }
}

/// One member, as its directory entry declares it (checked against its local header).
struct Entry {
    /// Its name in the archive, e.g. `s.npy`, as the bytes the directory holds (not
    /// necessarily UTF-8).
    name: Vec<u8>,
    wayfinder: ZipArchiveEntryWayfinder,
    deflated: bool,
    /// Its uncompressed size.
    size: u64,
    crc: u32,
    /// Read to its end, its CRC-32 and size found right.
    verified: Cell<bool>,
}

/// An opened `.npz` archive whose every member has been checked (module docs).
pub(crate) struct Archive<R> {
    zip: rawzip::ZipArchive<R>,
    entries: Vec<Entry>,
    path: PathBuf,
}

/// `FILE (array NAME)` for a member `NAME.npy`, `FILE (member NAME)` for any other:
/// what every error about a member names.
pub(crate) fn member_label(path: &Path, member: &str) -> PathBuf {
    match member.strip_suffix(".npy") {
        Some(array) => PathBuf::from(format!("{} (array {array})", path.display())),
        None => PathBuf::from(format!("{} (member {member})", path.display())),
    }
}

/// [`member_label`] of a name as the archive holds it: bytes that are not UTF-8 are
/// shown as U+FFFD, in the message only.
fn entry_label(path: &Path, name: &[u8]) -> PathBuf {
    member_label(path, &String::from_utf8_lossy(name))
}

fn not_an_archive(path: &Path, e: impl std::fmt::Display) -> Error {
    file_error(path, format!("is not a valid .npz archive: {e}"))
}

/// Open the `.npz` archive `path` (a regular file, or a stream read whole) and check it.
///
/// # Errors
/// [`Error::Io`] for a file that cannot be opened, [`Error::File`] naming the file, or
/// the member, for anything the module docs list.
pub(crate) fn open_npz_file(path: &Path) -> Result<Archive<Source>> {
    let file = open_file(path)?;
    let (source, end) = if is_regular(&file) {
        let end = file.metadata().map_err(|e| io_error(path, &e))?.len();
        (Source::File(rawzip::FileReader::from(file)), end)
    } else {
        let bytes = read_stream(file, path)?;
        let end = bytes.len() as u64;
        (Source::Bytes(bytes), end)
    };
    Archive::new(source, end, path)
}

impl<R: ReaderAt> Archive<R> {
    /// Locate the directory of the archive in the first `end` bytes of `reader` (`path`
    /// names it) and check every member (module docs).
    pub(crate) fn new(reader: R, end: u64, path: &Path) -> Result<Self> {
        let mut buffer = vec![0u8; rawzip::MAX_CENTRAL_DIRECTORY_RECORD_SIZE];
        let zip = rawzip::ZipLocator::new()
            .locate_in_reader(reader, &mut buffer, end)
            .map_err(|(_, e)| not_an_archive(path, e))?;
        check_directory_offset(&zip, path)?;
        let mut entries: Vec<Entry> = Vec::new();
        // The names seen, as bytes: two names that differ only in bytes that are not
        // UTF-8 are two members, though their messages show them alike.
        let mut names: HashSet<Vec<u8>> = HashSet::new();
        let mut records = zip.entries(&mut buffer);
        while let Some(record) = records.next_entry().map_err(|e| not_an_archive(path, e))? {
            if entries.len() == MAX_MEMBERS {
                return Err(not_an_archive(path, format!("it has more than {MAX_MEMBERS} members")));
            }
            let name: Vec<u8> = record.file_path().as_ref().to_vec();
            let label = entry_label(path, &name);
            if !names.insert(name.clone()) {
                return Err(file_error(&label, "is in the archive twice"));
            }
            check_method(record.compression_method(), &label)?;
            check_flags(record.flags(), &label)?;
            check_extra_fields(record.extra_fields(), &label)?;
            let deflated = record.compression_method() == CompressionMethod::DEFLATE;
            let (size, compressed) = (record.uncompressed_size_hint(), record.compressed_size_hint());
            if !deflated && size != compressed {
                return Err(corrupt(
                    &label,
                    format!(
                        "it is stored, yet the zip directory gives it {compressed} bytes compressed and {size} uncompressed"
                    ),
                ));
            }
            entries.push(Entry {
                name,
                wayfinder: record.wayfinder(),
                deflated,
                size,
                crc: record.crc32(),
                verified: Cell::new(false),
            });
        }
        if entries.len() as u64 != zip.entries_hint() {
            return Err(not_an_archive(
                path,
                format!(
                    "its end record counts {} members, its directory lists {}",
                    zip.entries_hint(),
                    entries.len()
                ),
            ));
        }
        let archive = Archive {
            zip,
            entries,
            path: path.to_path_buf(),
        };
        // A local header holds a name and an extra field of at most 64 KiB each.
        let mut local = vec![0u8; 2 * usize::from(u16::MAX)];
        for entry in &archive.entries {
            archive.check_local_header(entry, &mut local)?;
        }
        Ok(archive)
    }

    /// The local header of `entry` (and its data descriptor, if it has one) against its
    /// directory entry.
    fn check_local_header(&self, entry: &Entry, buffer: &mut [u8]) -> Result<()> {
        let label = entry_label(&self.path, &entry.name);
        let zip_error = |e: rawzip::Error| corrupt(&label, format!("its local header cannot be read: {e}"));
        let data = self.zip.get_entry(entry.wayfinder).map_err(zip_error)?;
        let local = data.local_header(buffer).map_err(zip_error)?;
        let disagree = |what: &str| {
            corrupt(
                &label,
                format!("its local header and the zip directory disagree on its {what}"),
            )
        };
        if local.file_path().as_ref() != entry.name.as_slice() {
            return Err(disagree("name"));
        }
        check_method(local.compression_method(), &label)?;
        if (local.compression_method() == CompressionMethod::DEFLATE) != entry.deflated {
            return Err(disagree("compression method"));
        }
        check_flags(local.flags(), &label)?;
        check_extra_fields(local.extra_fields(), &label)?;
        let compressed = entry.wayfinder.compressed_size_hint();
        let (crc, size, compressed_size) = if local.flags().has_data_descriptor() {
            // The local header's fields are zero; the descriptor after the data has them.
            match data.reader().data_descriptor().map_err(zip_error)? {
                Some(d) => (d.crc32(), d.uncompressed_size(), d.compressed_size()),
                None => return Err(disagree("data descriptor")),
            }
        } else {
            (
                local.crc32(),
                local.uncompressed_size_hint(),
                local.compressed_size_hint(),
            )
        };
        if crc != entry.crc {
            return Err(disagree("CRC-32"));
        }
        if size != entry.size || compressed_size != compressed {
            return Err(disagree("size"));
        }
        Ok(())
    }

    /// The archive's path, as its errors name it.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// Member `name` as a stream of its uncompressed bytes, and the size the directory
    /// declares for it; `None` when there is no such member.
    ///
    /// # Errors
    /// [`Error::File`] naming the member when its data cannot be found.
    pub(crate) fn member(&self, name: &str) -> Result<Option<(Member<'_, R>, u64)>> {
        let Some(entry) = self.entries.iter().find(|e| e.name == name.as_bytes()) else {
            return Ok(None);
        };
        self.open(entry).map(Some)
    }

    /// The stream of `entry`'s uncompressed bytes, and its declared size ([`Archive::member`]).
    fn open<'a>(&'a self, entry: &'a Entry) -> Result<(Member<'a, R>, u64)> {
        let label = entry_label(&self.path, &entry.name);
        let data = self
            .zip
            .get_entry(entry.wayfinder)
            .map_err(|e| corrupt(&label, format!("its data cannot be found: {e}")))?;
        let compressed = data.reader();
        let decoder = if entry.deflated {
            Decoder::Deflated(flate2::read::DeflateDecoder::new(compressed))
        } else {
            Decoder::Stored(compressed)
        };
        let member = Member {
            decoder,
            crc: rawzip::Crc32::new(),
            read: 0,
            size: entry.size,
            expected_crc: entry.crc,
            verified: &entry.verified,
        };
        Ok((member, entry.size))
    }

    /// `entry` read to its end into nothing, a block at a time (its CRC-32 and size
    /// checked); the bytes read.
    fn read_to_end(&self, entry: &Entry) -> Result<u64> {
        let (mut member, _) = self.open(entry)?;
        io::copy(&mut member, &mut io::sink()).map_err(|e| corrupt(&entry_label(&self.path, &entry.name), e))
    }

    /// Every member not yet read to its end (one the library does not use, or whose
    /// header alone was read) read into nothing, so that its CRC-32 and size are
    /// checked as a read member's are: an archive that `np.load` or `unzip -t` rejects
    /// is an error here too (semantics §12). Call it after the members that are used
    /// have been read.
    ///
    /// # Errors
    /// [`Error::File`] naming the first such member that is corrupt.
    pub(crate) fn check_unread_members(&self) -> Result<()> {
        for entry in self.entries.iter().filter(|e| !e.verified.get()) {
            self.read_to_end(entry)?;
        }
        Ok(())
    }
}

/// The directory `zip` located (`path` names it) against the offset its end record
/// declares. rawzip finds a directory that is not at its declared offset where it must
/// end (before the end record) and takes the difference as bytes prepended to the
/// archive, shifting every local header by as much (checked when they are read); but a
/// directory found *before* its declared offset is no such archive (`np.load` and
/// `unzip -t` reject it), and rawzip would read its local headers unshifted. A zip64
/// archive's directory is at its declared offset (rawzip moves none).
fn check_directory_offset<R: ReaderAt>(zip: &rawzip::ZipArchive<R>, path: &Path) -> Result<()> {
    // The end record: its signature, four 2-byte counts, the directory's size, then its
    // offset (APPNOTE 4.3.16).
    let mut field = [0u8; 4];
    zip.get_ref()
        .read_exact_at(&mut field, zip.eocd_offset() + 16)
        .map_err(|e| not_an_archive(path, e))?;
    let declared = u32::from_le_bytes(field);
    if declared != u32::MAX && u64::from(declared) > zip.directory_offset() {
        return Err(not_an_archive(
            path,
            format!(
                "its end record puts the zip directory at byte {declared}, but it starts at byte {}",
                zip.directory_offset()
            ),
        ));
    }
    Ok(())
}

/// The zip layer alone on `bytes`, for the fuzz target `npz_archive` and the fixed
/// fuzzing budget of the tests: the archive checked and every member read to its end
/// (its CRC-32 and size checked). Not guarded ([`guarded`](super::guarded)): a panic
/// here is a finding. Returns the bytes read.
///
/// # Errors
/// As the archive's and the members' reads.
#[doc(hidden)]
pub fn read_every_member(bytes: &[u8]) -> Result<u64> {
    let path = Path::new("fuzz.npz");
    let archive = Archive::new(bytes, bytes.len() as u64, path)?;
    let mut total = 0;
    for entry in &archive.entries {
        total += archive.read_to_end(entry)?;
    }
    Ok(total)
}

fn corrupt(label: &Path, why: impl std::fmt::Display) -> Error {
    file_error(label, format!("is corrupt: {why}"))
}

/// Stored or deflated, or an error naming the method by its APPNOTE (4.4.5) number.
fn check_method(method: CompressionMethod, label: &Path) -> Result<()> {
    if method == CompressionMethod::STORE || method == CompressionMethod::DEFLATE {
        return Ok(());
    }
    let name = match method.as_u16() {
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
    Err(file_error(
        label,
        format!(
            "cannot be decompressed: compression method {} ({name}) is not supported; \
             an .npz holds stored or deflated members",
            method.as_u16()
        ),
    ))
}

fn encrypted(label: &Path, how: &str) -> Error {
    file_error(
        label,
        format!("is encrypted ({how}); an .npz holds no encrypted member"),
    )
}

/// No encryption of any kind in the general purpose flags (APPNOTE 4.4.4).
fn check_flags(flags: EntryFlags, label: &Path) -> Result<()> {
    /// Bit 13: the local header's values are masked (central directory encryption).
    const MASKED: u16 = 1 << 13;
    if flags.has_strong_encryption() {
        Err(encrypted(label, "strong encryption"))
    } else if flags.bits() & MASKED != 0 {
        Err(encrypted(label, "a masked local header"))
    } else if flags.is_encrypted() {
        Err(encrypted(label, "its encryption flag is set: ZipCrypto or AES"))
    } else {
        Ok(())
    }
}

/// No extra field that encrypts: WinZip AES (0x9901, AE-1 or AE-2 by its vendor
/// version) and PKWARE's strong encryption header (0x0017).
fn check_extra_fields(fields: rawzip::extra_fields::ExtraFields<'_>, label: &Path) -> Result<()> {
    for (id, data) in fields {
        if id == ExtraFieldId::AES {
            let version = match data.get(..2) {
                Some([1, 0]) => "WinZip AE-1",
                Some([2, 0]) => "WinZip AE-2",
                _ => "WinZip AES",
            };
            return Err(encrypted(label, version));
        }
        if id == ExtraFieldId::STRONG_ENCRYPTION_HEADER {
            return Err(encrypted(label, "strong encryption"));
        }
    }
    Ok(())
}

/// The decompressor of a member.
enum Decoder<Z> {
    Stored(Z),
    Deflated(flate2::read::DeflateDecoder<Z>),
}

/// A member's uncompressed bytes: never more than its declared size, and its CRC-32 and
/// size compared with the directory's when the last byte is read (rawzip's own
/// verifying reader does the same, but its errors do not say which of the two differs
/// in words an error message can use).
pub(crate) struct Member<'a, R> {
    decoder: Decoder<rawzip::ZipReader<&'a R>>,
    crc: rawzip::Crc32,
    read: u64,
    size: u64,
    expected_crc: u32,
    /// Its entry's flag, set once its CRC-32 and size are found right.
    verified: &'a Cell<bool>,
}

impl<R: ReaderAt> Read for Member<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let invalid = |message: String| io::Error::new(io::ErrorKind::InvalidData, message);
        let past = |size: u64| invalid(format!("it decompresses past its declared {size} bytes"));
        // Once past the declared size (the error below), every further read is the same
        // error: the stream is not read on, and `read` stays above `size`.
        if self.read > self.size {
            return Err(past(self.size));
        }
        if buf.is_empty() {
            return Ok(0);
        }
        // One byte past the declared size, to tell a member that expands further
        // (`read <= size` here).
        let room = (self.size - self.read).saturating_add(1);
        let want = buf.len().min(usize::try_from(room).unwrap_or(usize::MAX));
        let n = match &mut self.decoder {
            Decoder::Stored(r) => r.read(&mut buf[..want]),
            Decoder::Deflated(r) => r.read(&mut buf[..want]),
        }
        .map_err(|e| match e.kind() {
            io::ErrorKind::UnexpectedEof => e,
            _ => invalid(format!("its data cannot be decompressed: {e}")),
        })?;
        let n = n.min(want);
        self.read += n as u64;
        if self.read > self.size {
            return Err(past(self.size));
        }
        self.crc.update(&buf[..n]);
        if n == 0 && self.read < self.size {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                format!("it holds {} of its {} bytes", self.read, self.size),
            ));
        }
        if self.read == self.size && (n > 0 || self.size == 0) {
            if self.crc.checksum() != self.expected_crc {
                return Err(invalid("its CRC-32 does not match its data".into()));
            }
            self.verified.set(true);
        }
        Ok(n)
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
        bytes.try_reserve(n).map_err(|_| Error::Allocation {
            bytes: (bytes.len() + n) as u128,
            what: format!("{} (a stream read whole)", path.display()),
        })?;
        bytes.extend_from_slice(&chunk[..n]);
        if bytes.len() >= ZIP_LOCAL_HEADER.len() && !bytes.starts_with(ZIP_LOCAL_HEADER) {
            return Err(not_an_archive(
                path,
                "a stream must start with a zip local header (PK\\x03\\x04)",
            ));
        }
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {

    use std::io::Read;
    use std::path::Path;

    use super::{Archive, read_every_member};
    use crate::files::npy::{NpyArray, ground_truth_from_bytes, read_ground_truth, write_npz_to};
    use crate::input::GroundTruth;
    use crate::input::params::Defaults;
    use crate::operations::calibration::Calibration;
    use crate::rules::decisions::Matching;
    use qtvpr_testkit::zip::{self as test_zip, Members, hostile, unzip};

    /// A valid 3x4 calibration file's members, and a VPR_Tutorial ground truth's.
    fn valid() -> (Members, Members) {
        let (s, hard, soft) = test_zip::traverse();
        let gt = GroundTruth::new(hard.view()).unwrap().with_soft(soft.view()).unwrap();
        let cal = Calibration::new(s.view(), &gt, Matching::Single).unwrap();
        let mut tutorial = Vec::new();
        write_npz_to(
            &mut tutorial,
            &[
                ("GThard", NpyArray::Bool(hard.view())),
                ("GTsoft", NpyArray::Bool(soft.view())),
            ],
        )
        .unwrap();
        (unzip(&cal.to_bytes(&Defaults::default()).unwrap()), unzip(&tutorial))
    }

    /// `bytes` (an archive of [`test_zip::zip`], not zip64) with every member named
    /// `from` renamed `to` (as long), in its directory record and its local header, or
    /// in its local header alone: how a name that is not UTF-8 is written, since the
    /// writer takes a `&str`.
    fn rename(mut bytes: Vec<u8>, from: &[u8], to: &[u8], local_only: bool) -> Vec<u8> {
        assert_eq!(from.len(), to.len());
        let u16_at = |b: &[u8], at: usize| usize::from(u16::from_le_bytes([b[at], b[at + 1]]));
        let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize;
        // The end record: the directory's entry count (offset 10) and start (16).
        let end = bytes.windows(4).rposition(|w| w == b"PK\x05\x06").unwrap();
        let (count, mut at) = (u16_at(&bytes, end + 10), u32_at(&bytes, end + 16));
        let mut renamed = 0;
        for _ in 0..count {
            assert_eq!(&bytes[at..at + 4], b"PK\x01\x02");
            let n = u16_at(&bytes, at + 28);
            let record = 46 + n + u16_at(&bytes, at + 30) + u16_at(&bytes, at + 32);
            if bytes[at + 46..at + 46 + n] == *from {
                let local = u32_at(&bytes, at + 42);
                assert_eq!(&bytes[local..local + 4], b"PK\x03\x04");
                bytes[local + 30..local + 30 + n].copy_from_slice(to);
                if !local_only {
                    bytes[at + 46..at + 46 + n].copy_from_slice(to);
                }
                renamed += 1;
            }
            at += record;
        }
        assert!(renamed > 0, "no member {}", String::from_utf8_lossy(from));
        bytes
    }

    #[test]
    fn two_names_that_differ_only_in_bytes_that_are_not_utf8_are_two_members() {
        // 0xFF and 0xFE are not UTF-8: both names show as "\u{FFFD}x.npy", yet they
        // are two members, each read to its end: 5 + 7 = 12 bytes.
        let b = test_zip::zip(&[
            test_zip::Member::stored("ax.npy", b"first"),
            test_zip::Member::deflated("bx.npy", b"second!"),
        ]);
        let b = rename(
            rename(b, b"ax.npy", b"\xFFx.npy", false),
            b"bx.npy",
            b"\xFEx.npy",
            false,
        );
        assert_eq!(read_every_member(&b), Ok(12));
    }

    #[test]
    fn the_same_name_that_is_not_utf8_twice_is_a_duplicate() {
        let b = test_zip::zip(&[
            test_zip::Member::stored("ax.npy", b"first"),
            test_zip::Member::stored("ax.npy", b"second!"),
        ]);
        let b = rename(b, b"ax.npy", b"\xFFx.npy", false);
        let e = Archive::new(b.as_slice(), b.len() as u64, Path::new("n.npz"))
            .err()
            .unwrap();
        assert_eq!(e.to_string(), "n.npz (array \u{FFFD}x) is in the archive twice");
    }

    #[test]
    fn a_name_that_is_not_utf8_agrees_with_itself_in_both_headers() {
        let b = test_zip::zip(&[test_zip::Member::deflated("ax.npy", b"first")]);
        let same = rename(b, b"ax.npy", b"\xFFx.npy", false);
        let archive = Archive::new(same.as_slice(), same.len() as u64, Path::new("n.npz")).unwrap();
        // Found by its bytes only: its name as shown is not its name.
        assert!(archive.member("\u{FFFD}x.npy").unwrap().is_none());
        assert_eq!(read_every_member(&same), Ok(5));
        // 0xFF in the directory, 0xFE in the local header: shown alike, yet two names.
        let other = rename(same, b"\xFFx.npy", b"\xFEx.npy", true);
        let e = Archive::new(other.as_slice(), other.len() as u64, Path::new("n.npz"))
            .err()
            .unwrap();
        assert_eq!(
            e.to_string(),
            "n.npz (array \u{FFFD}x) is corrupt: its local header and the zip directory disagree on its name"
        );
    }

    #[test]
    fn every_read_after_a_member_decompresses_past_its_size_is_the_same_error() {
        // 100 bytes deflated, declared as 10: the reads stop at byte 11 of them.
        let data: Vec<u8> = (0..100).collect();
        let mut b = test_zip::zip(&[test_zip::Member::deflated("m.npy", &data)]);
        test_zip::declare_size(&mut b, "m.npy", 10);
        let archive = Archive::new(b.as_slice(), b.len() as u64, Path::new("n.npz")).unwrap();
        let (mut member, size) = archive.member("m.npy").unwrap().unwrap();
        assert_eq!(size, 10);
        let mut buf = [0u8; 64];
        let mut got = 0;
        let first = loop {
            match member.read(&mut buf) {
                Ok(n) => {
                    assert!(n > 0 && got + n <= 10, "{got} + {n}");
                    got += n;
                }
                Err(e) => break e,
            }
        };
        let expected = "it decompresses past its declared 10 bytes";
        assert_eq!(
            (first.kind(), first.to_string().as_str()),
            (std::io::ErrorKind::InvalidData, expected)
        );
        for len in [64, 1, 0, 64] {
            let e = member.read(&mut buf[..len]).unwrap_err();
            assert_eq!(
                (e.kind(), e.to_string().as_str()),
                (std::io::ErrorKind::InvalidData, expected),
                "{len}"
            );
        }
    }

    #[test]
    fn the_directory_is_where_its_end_record_puts_it_or_after_bytes_prepended() {
        // One stored member: local header 30 bytes, name 5, data 5, data descriptor 16,
        // so the directory starts at byte 56.
        let b = test_zip::zip(&[test_zip::Member::stored("a.npy", b"first")]);
        let end = b.windows(4).rposition(|w| w == b"PK\x05\x06").unwrap();
        assert_eq!(b[end + 16..end + 20], 56u32.to_le_bytes());
        let declare = |at: u32| {
            let mut b = b.clone();
            b[end + 16..end + 20].copy_from_slice(&at.to_le_bytes());
            b
        };
        // 10 bytes after it: np.load and unzip -t reject it, and so does this reader.
        let e = read_every_member(&declare(66)).unwrap_err().to_string();
        let want = "its end record puts the zip directory at byte 66, but it starts at byte 56";
        assert_eq!(e, format!("fuzz.npz is not a valid .npz archive: {want}"));
        // 10 bytes before it: read as 10 bytes prepended, so the local header is looked
        // for at byte 10, where it is not.
        let e = read_every_member(&declare(46)).unwrap_err().to_string();
        assert!(
            e.starts_with("fuzz.npz (array a) is corrupt: its local header cannot be read"),
            "{e}"
        );
        // 10 bytes really prepended: the directory and the local header 10 bytes on.
        let mut prepended = vec![b'#'; 10];
        prepended.extend_from_slice(&b);
        assert_eq!(read_every_member(&prepended), Ok(5));
    }

    #[test]
    fn every_member_is_read_to_its_end_once() {
        use rawzip::ReaderAt;
        /// The bytes read from a slice, counted.
        struct Counted<'a>(&'a [u8], &'a std::cell::Cell<u64>);
        impl ReaderAt for Counted<'_> {
            fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<usize> {
                let n = self.0.read_at(buf, offset)?;
                self.1.set(self.1.get() + n as u64);
                Ok(n)
            }
        }
        // a.npy read whole by its reader, b.npy by none, c.npy only its first 10 bytes.
        let (a, b, c) = (vec![1u8; 1000], vec![2u8; 3000], vec![3u8; 5000]);
        let bytes = test_zip::zip(&[
            test_zip::Member::stored("a.npy", &a),
            test_zip::Member::stored("b.npy", &b),
            test_zip::Member::stored("c.npy", &c),
        ]);
        let count = std::cell::Cell::new(0);
        let archive = Archive::new(Counted(&bytes, &count), bytes.len() as u64, Path::new("n.npz")).unwrap();
        let (mut member, _) = archive.member("a.npy").unwrap().unwrap();
        std::io::copy(&mut member, &mut std::io::sink()).unwrap();
        let (mut member, _) = archive.member("c.npy").unwrap().unwrap();
        member.read_exact(&mut [0u8; 10]).unwrap();
        let before = count.get();
        archive.check_unread_members().unwrap();
        // b and c whole, each after its local header's 30 fixed bytes (the name after
        // them is skipped): 30 + 3000 + 30 + 5000 = 8060 bytes; a not again.
        assert_eq!(count.get() - before, 8060);
        // Now every member is checked: nothing more is read.
        archive.check_unread_members().unwrap();
        assert_eq!(count.get() - before, 8060);
    }

    #[test]
    fn a_member_no_reader_uses_is_checked_as_calibration_and_as_ground_truth() {
        // A calibration file and a VPR_Tutorial ground truth, each with an extra member
        // whose CRC-32 is wrong, and a ground truth whose GTsoft is wrong while only
        // GThard is used (a soft ground truth given apart).
        let (cal, tutorial) = valid();
        let bad = test_zip::Member {
            crc: Some(0x1234_5678),
            ..test_zip::Member::deflated("notes.txt", b"not an array")
        };
        let with_bad = |members: &Members| {
            let mut all: Vec<_> = members.iter().map(|(n, d)| test_zip::Member::stored(n, d)).collect();
            all.push(bad.clone());
            test_zip::zip(&all)
        };
        let want = "h.npz (member notes.txt) is corrupt: its CRC-32 does not match its data";
        let e = Calibration::from_bytes(&with_bad(&cal), "h.npz").err().unwrap();
        assert_eq!(e.to_string(), want);
        let e = ground_truth_from_bytes(&with_bad(&tutorial), "h.npz").err().unwrap();
        assert_eq!(e.to_string(), want);
        let dir = tempfile::tempdir().unwrap();
        let (hard, soft) = (dir.path().join("hard.npz"), dir.path().join("soft.npy"));
        let gt_soft = &tutorial[1].1;
        let members = [
            test_zip::Member::stored("GThard.npy", &tutorial[0].1),
            test_zip::Member {
                crc: Some(0x1234_5678),
                ..test_zip::Member::stored("GTsoft.npy", gt_soft)
            },
        ];
        std::fs::write(&hard, test_zip::zip(&members)).unwrap();
        std::fs::write(&soft, gt_soft).unwrap();
        let e = read_ground_truth(&hard, Some(&soft)).err().unwrap().to_string();
        assert!(
            e.ends_with("(array GTsoft) is corrupt: its CRC-32 does not match its data"),
            "{e}"
        );
    }

    /// A fixed fuzzing budget on the zip layer ([`super::read_every_member`]), the
    /// calibration reader and the ground-truth reader: valid archives and the hostile
    /// set, each mutated many times (bytes flipped or set to 0x00/0xFF, u16/u32 fields
    /// overwritten with edge values, cuts, a slice repeated), most mutations aimed at
    /// the directory, the local headers and the extra fields. Every input must give a
    /// value or an error naming the file; a panic fails. The budget is
    /// `QTVPR_FUZZ_ITERATIONS` per seed (default 300; scripts/test.sh's fuzz step runs
    /// 5000).
    #[test]
    fn the_zip_layer_survives_a_fixed_fuzzing_budget() {
        let iterations: usize = std::env::var("QTVPR_FUZZ_ITERATIONS")
            .ok()
            .and_then(|n| n.parse().ok())
            .unwrap_or(300);
        let (cal, tutorial) = valid();
        let zip = |m: &[(String, Vec<u8>)]| {
            let members: Vec<_> = m.iter().map(|(n, d)| test_zip::Member::stored(n, d)).collect();
            test_zip::zip(&members)
        };
        let mut seeds = vec![zip(&cal), zip(&tutorial)];
        for (members, descr) in [(&cal, "<f8"), (&tutorial, "|b1")] {
            let members: Vec<(&str, &[u8])> = members.iter().map(|(n, d)| (n.as_str(), d.as_slice())).collect();
            seeds.extend(
                hostile(&members, descr, (3, 4), 0)
                    .into_iter()
                    .filter(|h| h.bytes.len() < 100_000)
                    .map(|h| h.bytes),
            );
        }
        // xorshift64*: deterministic, and enough for mutations.
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = move |n: usize| {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as usize % n.max(1)
        };
        const EDGES: [u32; 6] = [0, 1, 0xFF, 0xFFFF, 0xFFFF_FFFF, 0x8000_0000];
        let mut runs = 0;
        for seed in &seeds {
            // Where the headers are: the directory's records and the local headers.
            let marks: Vec<usize> = seed
                .windows(4)
                .enumerate()
                .filter(|(_, w)| w[..2] == *b"PK" && matches!(w[2..], [1, 2] | [3, 4] | [5, 6] | [7, 8]))
                .map(|(i, _)| i)
                .collect();
            for _ in 0..iterations {
                let mut b = seed.clone();
                for _ in 0..1 + next(3) {
                    let at = match marks.len() {
                        0 => next(b.len()),
                        _ if next(4) == 0 => next(b.len()),
                        m => marks[next(m)] + next(64),
                    }
                    .min(b.len().saturating_sub(1));
                    match next(6) {
                        0 => b[at] ^= 1 << next(8),
                        1 => b[at] = [0, 0xFF][next(2)],
                        2 if at + 2 <= b.len() => {
                            b[at..at + 2].copy_from_slice(&(EDGES[next(6)] as u16).to_le_bytes());
                        }
                        3 if at + 4 <= b.len() => b[at..at + 4].copy_from_slice(&EDGES[next(6)].to_le_bytes()),
                        4 => b.truncate(at),
                        _ => {
                            let end = (at + next(32)).min(b.len());
                            let slice = b[at..end].to_vec();
                            b.splice(at..at, slice);
                        }
                    }
                    if b.is_empty() {
                        break;
                    }
                }
                let _ = super::read_every_member(&b);
                if let Err(e) = Calibration::from_bytes(&b, "m.npz") {
                    assert!(e.to_string().starts_with("m.npz"), "{e}");
                }
                if let Err(e) = ground_truth_from_bytes(&b, "m.npz") {
                    assert!(e.to_string().starts_with("m.npz"), "{e}");
                }
                runs += 1;
            }
        }
        assert_eq!(runs, seeds.len() * iterations);
    }

    /// Every file of the hostile set, as a calibration file and as a ground truth, from
    /// bytes and from a file: one error, naming the file and the member; no panic.
    #[test]
    fn every_hostile_file_is_refused_as_calibration_and_as_ground_truth() {
        let (cal, tutorial) = valid();
        let dir = tempfile::tempdir().unwrap();
        let mut cases = 0;
        for (members, descr, load) in [(&cal, "<f8", "calibration"), (&tutorial, "|b1", "ground truth")] {
            let members: Vec<(&str, &[u8])> = members.iter().map(|(n, d)| (n.as_str(), d.as_slice())).collect();
            for (i, h) in hostile(&members, descr, (3, 4), usize::MAX).into_iter().enumerate() {
                let from_bytes = match load {
                    "calibration" => Calibration::from_bytes(&h.bytes, "h.npz").err(),
                    _ => ground_truth_from_bytes(&h.bytes, "h.npz").err(),
                };
                let mut errors = vec![(from_bytes, "h.npz".to_string())];
                // From a file too (another reader under the archive), for all but most
                // of the 65,000 method numbers.
                if i < 300 {
                    let path = dir.path().join("h.npz");
                    std::fs::write(&path, &h.bytes).unwrap();
                    let from_file = match load {
                        "calibration" => Calibration::load(&path).err(),
                        _ => read_ground_truth(&path, None).err(),
                    };
                    errors.push((from_file, path.display().to_string()));
                }
                for (e, name) in errors {
                    let e = e.unwrap_or_else(|| panic!("{load}, {}: loaded", h.case)).to_string();
                    assert!(e.starts_with(&name) && e.contains(&h.error), "{load}, {}: {e}", h.case);
                }
                cases += 1;
            }
        }
        assert!(cases > 2 * 65_000, "{cases}");
    }
}
