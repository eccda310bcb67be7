//! Zip archives for the tests, hostile ones among them: written with rawzip's writer
//! (which writes any method number, encryption flag or extra field it is told to, and
//! compresses nothing itself), then patched where a field must lie.
//!
//! The core's tests (the zip layer's own and the calibration file's) and the CLI's use
//! this one writer, so that every front end is tested on the same hostile set
//! ([`hostile`]).

use std::io::{Read, Write};

use rawzip::extra_fields::ExtraFieldId;
use rawzip::{CompressionMethod, Crc32Option, Header, ZipArchiveWriter};

/// A small traverse for the valid archive the hostile set is made from: a 3 x 4
/// similarity, its hard ground truth and its soft ground truth (query 0 has a soft-only
/// second match).
pub fn traverse() -> (ndarray::Array2<f64>, ndarray::Array2<bool>, ndarray::Array2<bool>) {
    use ndarray::array;
    let s = array![[0.9, 0.1, 0.3, 0.2], [0.2, 0.8, 0.1, 0.4], [0.1, 0.3, 0.7, 0.9]];
    let hard = array![
        [true, false, false, false],
        [false, true, false, false],
        [false, false, true, true]
    ];
    let mut soft = hard.clone();
    soft[[0, 1]] = true;
    (s, hard, soft)
}

/// One member to write.
#[derive(Clone)]
pub struct Member<'a> {
    /// Its name in the archive.
    pub name: &'a str,
    /// The uncompressed bytes.
    pub data: &'a [u8],
    /// The method number written to both headers.
    pub method: u16,
    /// Deflate the bytes (else they are written as they are, whatever `method` says).
    pub deflate: bool,
    /// Set the encryption flag (bit 0).
    pub encrypted: bool,
    /// An extra field in both headers.
    pub extra: Option<(u16, &'a [u8])>,
    /// A CRC-32 to write in place of the data's.
    pub crc: Option<u32>,
}

impl<'a> Member<'a> {
    /// A stored member.
    pub fn stored(name: &'a str, data: &'a [u8]) -> Self {
        Member {
            name,
            data,
            method: 0,
            deflate: false,
            encrypted: false,
            extra: None,
            crc: None,
        }
    }

    /// A deflated member.
    pub fn deflated(name: &'a str, data: &'a [u8]) -> Self {
        Member {
            method: 8,
            deflate: true,
            ..Member::stored(name, data)
        }
    }
}

/// An archive of `members`, in order.
pub fn zip(members: &[Member<'_>]) -> Vec<u8> {
    let mut zip = ZipArchiveWriter::new(Vec::new());
    for m in members {
        let mut file = zip
            .new_file(m.name)
            .compression_method(CompressionMethod::from(m.method))
            .encrypted(m.encrypted);
        if let Some((id, data)) = m.extra {
            file = file
                .extra_field(ExtraFieldId::new(id), data, Header::LOCAL | Header::CENTRAL)
                .unwrap();
        }
        if let Some(crc) = m.crc {
            file = file.crc32(Crc32Option::Custom(crc));
        }
        let (mut entry, config) = file.start().unwrap();
        let descriptor = if m.deflate {
            let encoder = flate2::write::DeflateEncoder::new(&mut entry, flate2::Compression::best());
            let mut w = config.wrap(encoder);
            w.write_all(m.data).unwrap();
            let (encoder, descriptor) = w.finish().unwrap();
            encoder.finish().unwrap();
            descriptor
        } else {
            let mut w = config.wrap(&mut entry);
            w.write_all(m.data).unwrap();
            w.finish().unwrap().1
        };
        entry.finish(descriptor).unwrap();
    }
    zip.finish().unwrap()
}

/// Offsets of member `name` in `bytes`: its central directory record, its local header
/// and its data descriptor (a member written by [`zip`] has one).
pub struct Offsets {
    /// Its central directory record.
    pub central: usize,
    /// Its local header.
    pub local: usize,
    /// Its data descriptor.
    pub descriptor: usize,
}

fn u16_at(b: &[u8], at: usize) -> usize {
    usize::from(u16::from_le_bytes([b[at], b[at + 1]]))
}

fn u32_at(b: &[u8], at: usize) -> usize {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize
}

/// Where member `name` of `bytes` (not zip64) lies.
pub fn offsets(bytes: &[u8], name: &str) -> Offsets {
    let mut at = 0;
    loop {
        let central = at + bytes[at..].windows(4).position(|w| w == b"PK\x01\x02").unwrap();
        let n = u16_at(bytes, central + 28);
        if &bytes[central + 46..central + 46 + n] == name.as_bytes() {
            let local = u32_at(bytes, central + 42);
            let data = local + 30 + u16_at(bytes, local + 26) + u16_at(bytes, local + 28);
            let descriptor = data + u32_at(bytes, central + 20);
            assert_eq!(&bytes[descriptor..descriptor + 4], b"PK\x07\x08");
            return Offsets {
                central,
                local,
                descriptor,
            };
        }
        at = central + 4;
    }
}

/// Member `name` made to declare `size` uncompressed bytes, in its directory record and
/// its data descriptor alike (so the archive is consistent, and lies).
pub fn declare_size(bytes: &mut [u8], name: &str, size: u32) {
    let o = offsets(bytes, name);
    bytes[o.central + 24..o.central + 28].copy_from_slice(&size.to_le_bytes());
    bytes[o.descriptor + 12..o.descriptor + 16].copy_from_slice(&size.to_le_bytes());
}

/// An archive's members: each one's name and uncompressed bytes, in order.
pub type Members = Vec<(String, Vec<u8>)>;

/// The names of the members of `bytes`, in order, and each one's uncompressed bytes
/// (their CRC-32 verified by rawzip).
pub fn unzip(bytes: &[u8]) -> Members {
    let mut buffer = vec![0u8; rawzip::MAX_CENTRAL_DIRECTORY_RECORD_SIZE];
    let archive = rawzip::ZipLocator::new()
        .locate_in_reader(bytes, &mut buffer, bytes.len() as u64)
        .map_err(|(_, e)| e)
        .unwrap();
    let mut records = archive.entries(&mut buffer);
    let mut found = Vec::new();
    while let Some(record) = records.next_entry().unwrap() {
        let name = String::from_utf8(record.file_path().as_ref().to_vec()).unwrap();
        found.push((name, record.wayfinder(), record.compression_method()));
    }
    found
        .into_iter()
        .map(|(name, wayfinder, method)| {
            let entry = archive.get_entry(wayfinder).unwrap();
            let mut data = Vec::new();
            if method == CompressionMethod::DEFLATE {
                let inflate = flate2::read::DeflateDecoder::new(entry.reader());
                entry.verifying_reader(inflate).read_to_end(&mut data).unwrap();
            } else {
                entry.verifying_reader(entry.reader()).read_to_end(&mut data).unwrap();
            }
            (name, data)
        })
        .collect()
}

/// A `.npy` header of `descr` and `shape` (its Python spelling, e.g. `(2, 3)`), padded
/// as NumPy pads it.
pub fn npy_header(descr: &str, shape: &str) -> Vec<u8> {
    let mut h = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (h.len() + 11) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((h.len() as u16).to_le_bytes());
    b.extend(h.as_bytes());
    b
}

/// One file of the hostile set: what it is, its bytes, and a part of the one error it
/// must get.
pub struct Hostile {
    /// What it is.
    pub case: String,
    /// Its bytes.
    pub bytes: Vec<u8>,
    /// A part of the one error a reader must give it.
    pub error: String,
}

/// The hostile set of issue 35, made from a valid archive's `members` (name and
/// `.npy` bytes, in order): its first member, a `rows` x `cols` matrix of `descr`, is
/// the one made hostile (encrypted, compressed with an unsupported method, duplicated,
/// given a bad CRC, made a bomb, given another rank); every other member stays valid.
/// Two more keep every member valid and add a bad one, or move the directory.
/// `other_methods` is how many of the unsupported method numbers to try (all 65,534
/// is cheap in the core, not as one process each).
pub fn hostile(members: &[(&str, &[u8])], descr: &str, (rows, cols): (u64, u64), other_methods: usize) -> Vec<Hostile> {
    let (victim, data) = members[0];
    let array = victim.trim_end_matches(".npy");
    let rest: Vec<Member<'_>> = members[1..].iter().map(|(n, d)| Member::stored(n, d)).collect();
    let with = |first: Member<'_>| {
        let mut all = vec![first];
        all.extend(rest.iter().cloned());
        zip(&all)
    };
    let mut set = Vec::new();
    let mut add = |case: &str, bytes: Vec<u8>, error: String| {
        set.push(Hostile {
            case: case.into(),
            bytes,
            error,
        });
    };
    let method = |n: u16, name: &str| {
        format!("(array {array}) cannot be decompressed: compression method {n} ({name}) is not supported")
    };
    let encrypted = |how: &str| format!("(array {array}) is encrypted ({how})");
    const AE: [u8; 7] = [2, 0, b'A', b'E', 3, 8, 0];
    const AE1: [u8; 7] = [1, 0, b'A', b'E', 3, 8, 0];
    let aes = Member {
        method: 99,
        extra: Some((0x9901, &AE)),
        ..Member::stored(victim, data)
    };
    add(
        "AES without the encryption flag",
        with(aes.clone()),
        method(99, "AES encryption"),
    );
    add(
        "AES with the encryption flag",
        with(Member {
            encrypted: true,
            ..aes.clone()
        }),
        method(99, "AES encryption"),
    );
    add(
        "an AE-1 extra field on a deflated member",
        with(Member {
            extra: Some((0x9901, &AE1)),
            ..Member::deflated(victim, data)
        }),
        encrypted("WinZip AE-1"),
    );
    add(
        "an AE-2 extra field on a stored member",
        with(Member {
            extra: Some((0x9901, &AE)),
            ..Member::stored(victim, data)
        }),
        encrypted("WinZip AE-2"),
    );
    add(
        "ZipCrypto (the encryption flag)",
        with(Member {
            encrypted: true,
            ..Member::stored(victim, data)
        }),
        encrypted("its encryption flag is set: ZipCrypto or AES"),
    );
    for (bits, how) in [(1u16 | 1 << 6, "strong encryption"), (1 << 13, "a masked local header")] {
        let mut b = with(Member::stored(victim, data));
        let o = offsets(&b, victim);
        for at in [o.local + 6, o.central + 8] {
            let flags = u16::from_le_bytes([b[at], b[at + 1]]) | bits;
            b[at..at + 2].copy_from_slice(&flags.to_le_bytes());
        }
        add(&format!("flags {bits:#06x}"), b, encrypted(how));
    }
    let names = [
        (1, "unknown"),
        (9, "deflate64"),
        (12, "bzip2"),
        (14, "LZMA"),
        (93, "zstd"),
        (95, "XZ"),
        (98, "PPMd"),
        (u16::MAX, "unknown"),
    ];
    let others = (1..=u16::MAX).filter(|&n| n != 8 && n != 99);
    for n in names
        .iter()
        .map(|&(n, _)| n)
        .chain(others.filter(|n| names.iter().all(|m| m.0 != *n)))
        .take(other_methods.max(names.len()))
    {
        let name = names.iter().find(|m| m.0 == n).map_or("unknown", |m| m.1);
        let name = match n {
            96 => "JPEG",
            97 => "WavPack",
            _ => name,
        };
        add(
            &format!("method {n}"),
            with(Member {
                method: n,
                ..Member::stored(victim, data)
            }),
            method(n, name),
        );
    }
    let mut twice = vec![Member::stored(victim, data)];
    twice.extend(rest.iter().cloned());
    twice.push(Member::stored(victim, data));
    add(
        "a member twice",
        zip(&twice),
        format!("(array {array}) is in the archive twice"),
    );
    add(
        "a bad CRC-32",
        with(Member {
            crc: Some(0x1234_5678),
            ..Member::deflated(victim, data)
        }),
        format!("(array {array}) is corrupt: its CRC-32 does not match its data"),
    );
    let mut b = with(Member::stored(victim, data));
    let o = offsets(&b, victim);
    b[o.central + 16] ^= 1;
    add(
        "a CRC-32 changed in the directory only",
        b,
        format!("(array {array}) is corrupt: its local header and the zip directory disagree on its CRC-32"),
    );
    // A bomb with its true size: 40 MB of zeros in a few kB, of a shape that cannot be
    // this archive's (refused from the headers, nothing decompressed).
    let item: u64 = descr[2..].parse().unwrap();
    let big_rows = 40_000_000 / item / cols.max(1);
    let mut bomb = npy_header(descr, &format!("({big_rows}, {cols})"));
    bomb.resize(bomb.len() + (big_rows * cols * item) as usize, 0);
    add(
        "a deflate bomb with its true size",
        with(Member::deflated(victim, &bomb)),
        format!("shape {big_rows}x{cols}"),
    );
    // A bomb whose directory and header agree on the right size, and whose deflate
    // stream goes on for 40 MB past it.
    let mut long = data.to_vec();
    long.resize(data.len() + 40_000_000, 0);
    let mut b = with(Member::deflated(victim, &long));
    declare_size(&mut b, victim, data.len() as u32);
    add(
        "a deflate bomb past its declared size",
        b,
        format!(
            "(array {array}) is corrupt: it decompresses past its declared {} bytes",
            data.len()
        ),
    );
    let mut one = npy_header(descr, &format!("({},)", rows * cols));
    one.extend_from_slice(&data[data.len() - (rows * cols * item) as usize..]);
    add(
        "a 1-D array",
        with(Member::stored(victim, &one)),
        format!("(array {array}) holds a 1-D array"),
    );
    let three = npy_header(descr, "(1000, 100000, 100000)");
    add(
        "a 3-D array of 10^13 values",
        with(Member::deflated(victim, &three)),
        format!("(array {array}) holds a 3-D array"),
    );
    // Issue 49: two that np.load and unzip -t reject. A member no reader uses, with a
    // bad CRC-32 (its first member stays valid here).
    let mut extra = vec![Member::stored(victim, data)];
    extra.extend(rest.iter().cloned());
    extra.push(Member {
        crc: Some(0x1234_5678),
        ..Member::deflated("notes.txt", b"not an array")
    });
    add(
        "an extra member with a bad CRC-32",
        zip(&extra),
        "(member notes.txt) is corrupt: its CRC-32 does not match its data".into(),
    );
    // An end record that puts the directory 10 bytes after where it starts.
    let mut b = with(Member::stored(victim, data));
    let end = b.windows(4).rposition(|w| w == b"PK\x05\x06").unwrap();
    let at = u32_at(&b, end + 16);
    b[end + 16..end + 20].copy_from_slice(&(at as u32 + 10).to_le_bytes());
    add(
        "a directory offset 10 bytes off",
        b,
        format!(
            "is not a valid .npz archive: its end record puts the zip directory at byte {}, but it starts at byte {at}",
            at + 10
        ),
    );
    set
}
