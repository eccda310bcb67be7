//! semantics §12: the calibration file (`crates/qtvpr/src/files/calibration_file.rs`),
//! through the public API: a saved file loads with bit-identical results, its members
//! are NumPy's, and every bad file (a missing or corrupt member, a wrong dtype or shape,
//! a bad `meta`, a hostile archive) is refused with an error naming the file.
#![cfg(feature = "npy")]

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ndarray::{Array2, array};
use qtvpr::npy::{NpyArray, write_npz};
use qtvpr::{Calibration, Defaults, Error, Gate, GroundTruth, Matching, Online, OnlineParams, Params, SequenceParams};
use qtvpr_testkit::zip::{self as test_zip, Member};

/// A fixed LCG matrix with ties, and GT i == j % 6 with a soft neighbour row.
fn calibration(matching: Matching, f32: bool) -> Calibration {
    let mut x = 3u64;
    let s = Array2::from_shape_fn((6, 9), |_| {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((x >> 33) % 50) as f64 / 50.0 - 0.3
    });
    let gt = GroundTruth::new(Array2::from_shape_fn((6, 9), |(i, j)| i == j % 6).view())
        .unwrap()
        .with_soft(Array2::from_shape_fn((6, 9), |(i, j)| i == j % 6 || i == (j + 1) % 6).view())
        .unwrap();
    if f32 {
        Calibration::new(s.mapv(|v| v as f32).view(), &gt, matching).unwrap()
    } else {
        Calibration::new(s.t().to_owned().t(), &gt, matching).unwrap()
    }
}

fn deployment() -> Array2<f64> {
    let mut x = 11u64;
    Array2::from_shape_fn((6, 20), |_| {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((x >> 33) % 40) as f64 / 40.0 - 0.3
    })
}

fn dir() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

const DEFAULTS: Defaults = Defaults {
    k: 3,
    precision: 0.9,
    window: Some(4),
    gate: Gate::None,
    sequence_gate: SequenceParams::DEFAULT,
};

fn same_results(a: &Calibration, b: &Calibration) {
    let s = deployment();
    for segment_size in [None, Some(3)] {
        let p = Params {
            k: 3,
            precision: 0.9,
            segment_size,
            gate: Gate::None,
            sequence_gate: Default::default(),
        };
        assert_eq!(a.transfer(s.view(), &p).unwrap(), b.transfer(s.view(), &p).unwrap());
    }
    let p = OnlineParams {
        k: 3,
        precision: 0.9,
        window: 4,
        min_window: 2,
        gate: Gate::None,
        sequence_gate: Default::default(),
    };
    let run = |c: &Calibration| {
        let c = Arc::new(Calibration::from_bytes(&c.to_bytes(&DEFAULTS).unwrap(), "x").unwrap());
        Online::new(c, p).unwrap().push_many(s.view()).unwrap()
    };
    assert_eq!(run(a), run(b));
    assert_eq!(a.threshold(0.9).unwrap().to_bits(), b.threshold(0.9).unwrap().to_bits());
}

/// Member names of an archive, and each member's header text.
fn members(bytes: &[u8]) -> Vec<(String, String)> {
    test_zip::unzip(bytes)
        .into_iter()
        .map(|(name, data)| {
            let len = u16::from_le_bytes([data[8], data[9]]) as usize;
            (name, String::from_utf8(data[10..10 + len].to_vec()).unwrap())
        })
        .collect()
}

#[test]
fn saved_and_loaded_gives_identical_results() {
    let d = dir();
    for matching in [Matching::Single, Matching::Multi] {
        for f32 in [false, true] {
            let cal = calibration(matching, f32);
            let path = d.path().join("cal.npz");
            cal.save(&path, &DEFAULTS).unwrap();
            let loaded = Calibration::load(&path).unwrap();
            assert_eq!(loaded.defaults(), &DEFAULTS);
            assert_eq!(loaded.matching(), matching);
            assert_eq!((loaded.db_size(), loaded.len()), (6, 9));
            assert_eq!(loaded.scores(), cal.scores());
            assert_eq!(loaded.ground_truth(), cal.ground_truth());
            same_results(&cal, &loaded);
            let from_bytes = Calibration::from_bytes(&std::fs::read(&path).unwrap(), "cal.npz").unwrap();
            same_results(&cal, &from_bytes);
            assert_eq!(cal.to_bytes(&DEFAULTS).unwrap(), std::fs::read(&path).unwrap());
        }
    }
    assert_eq!(calibration(Matching::Single, false).defaults(), &Defaults::default());
}

#[test]
fn members_and_dtypes_are_numpys() {
    let cal = calibration(Matching::Multi, true);
    let bytes = cal.to_bytes(&Defaults::default()).unwrap();
    let m = members(&bytes);
    let names: Vec<&str> = m.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["s.npy", "gt.npy", "gt_soft.npy", "meta.npy"]);
    assert!(
        m[0].1.contains("'descr': '<f4'") && m[0].1.contains("'shape': (6, 9, )"),
        "{}",
        m[0].1
    );
    assert!(
        m[1].1.contains("'descr': '|b1'") && m[1].1.contains("'shape': (6, 9, )"),
        "{}",
        m[1].1
    );
    assert!(
        m[3].1.contains("'descr': '<U") && m[3].1.contains("'shape': ()"),
        "{}",
        m[3].1
    );
    let meta = format!(
        r#"{{"format":"qtvpr-calibration","version":1,"matching":"multi","params":{{"k":10,"precision":1.0,"window":null,"gate":"none"}},"qtvpr":"{}"}}"#,
        env!("CARGO_PKG_VERSION")
    );
    assert!(m[3].1.contains(&format!("'<U{}'", meta.len())), "{}", m[3].1);
    // The meta payload is UTF-32LE of the JSON.
    let data = test_zip::unzip(&bytes).pop().unwrap().1;
    let payload: Vec<u8> = meta.chars().flat_map(|c| u32::from(c).to_le_bytes()).collect();
    assert!(data.ends_with(&payload));
    // Hard GT only: no gt_soft member.
    let s = array![[0.9, 0.1], [0.2, 0.8]];
    let hard = GroundTruth::new(array![[true, false], [false, true]].view()).unwrap();
    let cal = Calibration::new(s.view(), &hard, Matching::Single).unwrap();
    let names: Vec<String> = members(&cal.to_bytes(&DEFAULTS).unwrap())
        .into_iter()
        .map(|m| m.0)
        .collect();
    assert_eq!(names, ["s.npy", "gt.npy", "meta.npy"]);
    assert!(members(&cal.to_bytes(&DEFAULTS).unwrap())[0].1.contains("'<f8'"));
}

#[cfg(unix)]
#[test]
fn a_saved_file_has_the_mode_of_a_plain_create() {
    use std::os::unix::fs::PermissionsExt;
    let d = dir();
    let plain = d.path().join("plain");
    std::fs::File::create(&plain).unwrap();
    let path = d.path().join("cal.npz");
    calibration(Matching::Single, false).save(&path, &DEFAULTS).unwrap();
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode(&path), mode(&plain));
    assert_ne!(mode(&path), 0o600, "a tempfile's mode");
    // Nothing else is left in the directory.
    assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 2);
}

#[test]
fn bad_defaults_are_refused_when_saving() {
    let cal = calibration(Matching::Single, false);
    let err = |d: Defaults| cal.to_bytes(&d).unwrap_err().to_string();
    assert_eq!(err(Defaults { k: 0, ..DEFAULTS }), "k must be >= 1, got 0");
    assert_eq!(
        err(Defaults {
            precision: 1.5,
            ..DEFAULTS
        }),
        "precision must be in (0, 1], got 1.5"
    );
    assert_eq!(
        err(Defaults {
            window: Some(0),
            ..DEFAULTS
        }),
        "window must be >= 1, got 0"
    );
    let d = dir();
    let err = cal.save(&d.path().join("no/such/dir/cal.npz"), &DEFAULTS).unwrap_err();
    assert!(err.to_string().starts_with("cannot write "), "{err}");
    assert!(err.to_string().contains("cal.npz"), "{err}");
    // A calibration that kept nothing to save says so, and writes no file.
    let s = Array2::from_shape_fn((6, 9), |(i, j)| (i * 9 + j) as f32);
    let gt = GroundTruth::new(Array2::from_shape_fn((6, 9), |(i, j)| i == j % 6).view()).unwrap();
    let lean = Calibration::for_transfer(s.view(), gt, Matching::Single).unwrap();
    let path = d.path().join("lean.npz");
    let err = lean.save(&path, &DEFAULTS).unwrap_err();
    assert_eq!(
        err.to_string(),
        "calibration was built by Calibration::for_transfer, which keeps neither its scores nor its \
         ground truth, so it cannot be saved: build it with Calibration::new"
    );
    assert_eq!(lean.to_bytes(&DEFAULTS).unwrap_err(), err);
    assert!(!path.exists());
}

fn meta(format: &str, version: &str, matching: &str, params: &str) -> String {
    format!(
        r#"{{"format": "{format}", "version": {version}, "matching": "{matching}", "params": {params}, "qtvpr": "0.1.0"}}"#
    )
}

const PARAMS: &str = r#"{"k": 10, "precision": 1.0, "window": null}"#;

/// Write an archive of `arrays` to `name` in `dir`, and the error of loading it.
fn load_error(dir: &Path, name: &str, arrays: &[(&str, NpyArray<'_>)]) -> String {
    let path: PathBuf = dir.join(name);
    write_npz(&path, arrays).unwrap();
    let from_file = Calibration::load(&path).err().expect("a bad file").to_string();
    let from_bytes = Calibration::from_bytes(&std::fs::read(&path).unwrap(), &path.display().to_string())
        .err()
        .expect("a bad file")
        .to_string();
    assert_eq!(from_file, from_bytes);
    assert!(from_file.contains(&path.display().to_string()), "{from_file}");
    from_file
}

#[test]
fn every_bad_file_is_named() {
    let d = dir();
    let p = d.path();
    let s = array![[0.9, 0.1], [0.2, 0.8]];
    let gt = array![[true, false], [false, true]];
    let good = meta("qtvpr-calibration", "1", "single", PARAMS);
    let f = |name: &str| p.join(name).display().to_string();
    let (sv, gv) = (NpyArray::F64(s.view()), NpyArray::Bool(gt.view()));
    let m = |text: &str| NpyArray::Str(Box::leak(text.to_string().into_boxed_str()));

    // The good file loads.
    write_npz(&p.join("good.npz"), &[("s", sv), ("gt", gv), ("meta", m(&good))]).unwrap();
    assert!(Calibration::load(&p.join("good.npz")).is_ok());

    type Case<'a> = (&'a str, Vec<(&'a str, NpyArray<'a>)>, String);
    let cases: Vec<Case<'_>> = vec![
        (
            "no_meta.npz",
            vec![("s", sv), ("gt", gv)],
            "has no array meta: it is not a qtvpr calibration file".into(),
        ),
        (
            "no_s.npz",
            vec![("gt", gv), ("meta", m(&good))],
            "has no array s; a calibration file holds s, gt and meta (and optionally gt_soft)".into(),
        ),
        (
            "no_gt.npz",
            vec![("s", sv), ("meta", m(&good))],
            "has no array gt;".into(),
        ),
        (
            "shape.npz",
            vec![
                ("s", sv),
                ("gt", NpyArray::Bool(gt.slice(ndarray::s![.., ..1]))),
                ("meta", m(&good)),
            ],
            ": ground truth shape 2x1 does not match calibration similarity shape 2x2".into(),
        ),
        (
            "soft_shape.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                ("gt_soft", NpyArray::Bool(gt.slice(ndarray::s![..1, ..]))),
                ("meta", m(&good)),
            ],
            ": soft ground truth shape 1x2 does not match ground truth shape 2x2".into(),
        ),
        (
            "format.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                ("meta", m(&meta("other", "1", "single", PARAMS))),
            ],
            "is not a qtvpr calibration file: its meta format is 'other', expected 'qtvpr-calibration'".into(),
        ),
        (
            "version.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                ("meta", m(&meta("qtvpr-calibration", "2", "single", PARAMS))),
            ],
            format!(
                "has calibration file version 2; this qtvpr ({}) reads version 1",
                env!("CARGO_PKG_VERSION")
            ),
        ),
        (
            "json.npz",
            vec![("s", sv), ("gt", gv), ("meta", m("{not json"))],
            "has a meta that is not JSON: ".into(),
        ),
        (
            "keys.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                ("meta", m(r#"{"format": "qtvpr-calibration", "version": 1}"#)),
            ],
            "has a malformed meta: missing field `matching`".into(),
        ),
        (
            "matching.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                ("meta", m(&meta("qtvpr-calibration", "1", "best", PARAMS))),
            ],
            "has meta matching 'best'; expected 'single' or 'multi'".into(),
        ),
        (
            "k.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                (
                    "meta",
                    m(&meta(
                        "qtvpr-calibration",
                        "1",
                        "single",
                        r#"{"k": 0, "precision": 1.0, "window": null}"#,
                    )),
                ),
            ],
            "has bad meta params: k must be >= 1, got 0".into(),
        ),
        (
            "precision.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                (
                    "meta",
                    m(&meta(
                        "qtvpr-calibration",
                        "1",
                        "single",
                        r#"{"k": 1, "precision": 1.5, "window": 3}"#,
                    )),
                ),
            ],
            "has bad meta params: precision must be in (0, 1], got 1.5".into(),
        ),
        (
            "window.npz",
            vec![
                ("s", sv),
                ("gt", gv),
                (
                    "meta",
                    m(&meta(
                        "qtvpr-calibration",
                        "1",
                        "single",
                        r#"{"k": 1, "precision": 1.0, "window": 0}"#,
                    )),
                ),
            ],
            "has bad meta params: window must be >= 1, got 0".into(),
        ),
        (
            "meta_matrix.npz",
            vec![("s", sv), ("gt", gv), ("meta", sv)],
            "(array meta) holds an array of dtype <f8 and shape [2, 2], expected a 0-d unicode string".into(),
        ),
        (
            "s_bool.npz",
            vec![("s", gv), ("gt", gv), ("meta", m(&good))],
            "(array s) has dtype |b1; expected float32 or float64 similarity scores".into(),
        ),
        (
            "gt_float.npz",
            vec![("s", sv), ("gt", sv), ("meta", m(&good))],
            "(array gt) has dtype <f8; expected bool".into(),
        ),
    ];
    for (name, arrays, needle) in cases {
        let e = load_error(p, name, &arrays);
        assert!(e.starts_with(&f(name)), "{name}: {e}");
        assert!(e.contains(&needle), "{name}: {e}\n  expected {needle}");
    }

    // NaN in s.
    let nan = array![[0.9, f64::NAN], [0.2, 0.8]];
    let e = load_error(
        p,
        "nan.npz",
        &[("s", NpyArray::F64(nan.view())), ("gt", gv), ("meta", m(&good))],
    );
    assert_eq!(
        e,
        format!(
            "{}: calibration similarity contains NaN at row 0, column 1; scores must be finite",
            f("nan.npz")
        )
    );

    // Ground truth of uint8 (0/1 is fine as input, but the file format says bool).
    let path = p.join("gt_u8.npz");
    {
        use npyz::WriterBuilder;
        let (mut s_npy, mut gt_npy, mut meta_npy) = (Vec::new(), Vec::new(), Vec::new());
        sv.write_to(&mut s_npy).unwrap();
        let mut w = npyz::WriteOptions::<u8>::new()
            .default_dtype()
            .shape(&[2, 2])
            .writer(&mut gt_npy)
            .begin_nd()
            .unwrap();
        w.extend([1u8, 0, 0, 1]).unwrap();
        w.finish().unwrap();
        m(&good).write_to(&mut meta_npy).unwrap();
        let members = [
            Member::stored("s.npy", &s_npy),
            Member::stored("gt.npy", &gt_npy),
            Member::stored("meta.npy", &meta_npy),
        ];
        std::fs::write(&path, test_zip::zip(&members)).unwrap();
    }
    let e = Calibration::load(&path).err().unwrap().to_string();
    assert_eq!(e, format!("{} (array gt) has dtype |u1; expected bool", f("gt_u8.npz")));

    // Not a zip at all, a truncated one, and a missing file.
    std::fs::write(p.join("junk.npz"), b"PK\x03\x04 this is not a zip").unwrap();
    let e = Calibration::load(&p.join("junk.npz")).err().unwrap().to_string();
    assert!(
        e.starts_with(&format!("{} is not a valid .npz archive", f("junk.npz"))),
        "{e}"
    );
    let whole = std::fs::read(p.join("good.npz")).unwrap();
    for cut in [whole.len() / 2, whole.len() - 10] {
        std::fs::write(p.join("cut.npz"), &whole[..cut]).unwrap();
        let e = Calibration::load(&p.join("cut.npz")).err().unwrap().to_string();
        assert!(e.starts_with(&f("cut.npz")), "{e}");
    }
    let e = Calibration::load(&p.join("missing.npz")).err().unwrap();
    assert!(
        matches!(
            e,
            Error::Io {
                kind: std::io::ErrorKind::NotFound,
                ..
            }
        ),
        "{e}"
    );
}

/// Every single-bit flip of a small calibration file is an error naming the file, or
/// loads a calibration that decides bit-identically (a flip in a field the reader
/// does not use, such as a local header's copy of the name).
#[test]
fn every_bit_flip_is_an_error_or_changes_nothing() {
    let cal = calibration(Matching::Single, false);
    let bytes = cal.to_bytes(&DEFAULTS).unwrap();
    let (mut refused, mut loaded) = (0, 0);
    for i in 0..bytes.len() {
        for bit in 0..8 {
            let mut b = bytes.clone();
            b[i] ^= 1 << bit;
            match Calibration::from_bytes(&b, "flipped.npz") {
                Err(e) => {
                    assert!(e.to_string().contains("flipped.npz"), "byte {i} bit {bit}: {e}");
                    refused += 1;
                }
                Ok(c) => {
                    assert_eq!(c.defaults(), &DEFAULTS, "byte {i} bit {bit}");
                    assert_eq!(c.matching(), Matching::Single, "byte {i} bit {bit}");
                    same_results(&cal, &c);
                    loaded += 1;
                }
            }
        }
    }
    // Most fields are covered by a CRC or a size check; what loads is a flip in a field
    // the reader never uses (times, versions, a local header's copy of a name).
    assert!(refused > 8 * bytes.len() * 3 / 4, "{refused} refused, {loaded} loaded");
}

/// A calibration archive of `s.npy` (its raw bytes, deflated or not), a 1x1 `gt` and
/// a good `meta`.
fn archive(s: &[u8], deflate: bool) -> Vec<u8> {
    let mut gt = Vec::new();
    NpyArray::Bool(array![[true]].view()).write_to(&mut gt).unwrap();
    let meta = r#"{"format": "qtvpr-calibration", "version": 1, "matching": "single", "params": {"k": 1, "precision": 1.0, "window": null}}"#;
    let mut m = Vec::new();
    NpyArray::Str(meta).write_to(&mut m).unwrap();
    let s = if deflate {
        Member::deflated("s.npy", s)
    } else {
        Member::stored("s.npy", s)
    };
    test_zip::zip(&[s, Member::stored("gt.npy", &gt), Member::stored("meta.npy", &m)])
}

/// A `.npy` header for a float64 matrix of `shape`, followed by `zeros` zero bytes.
fn npy_bytes(shape: (u64, u64), zeros: usize) -> Vec<u8> {
    let mut b = test_zip::npy_header("<f8", &format!("({}, {})", shape.0, shape.1));
    b.resize(b.len() + zeros, 0);
    b
}

#[test]
fn members_other_than_stored_or_deflated_are_refused() {
    let s = npy_bytes((1, 1), 8);
    let refused = |bytes: &[u8], name: &str| {
        let e = Calibration::from_bytes(bytes, "c.npz").err().unwrap().to_string();
        assert_eq!(
            e,
            format!(
                "c.npz (array s) cannot be decompressed: compression method {name} is not supported; \
                 an .npz holds stored or deflated members"
            )
        );
    };
    // Members marked with another method in the local header and the directory.
    for (method, name) in [
        (12u16, "12 (bzip2)"),
        (93, "93 (zstd)"),
        (14, "14 (LZMA)"),
        (95, "95 (XZ)"),
    ] {
        let mut b = archive(&s, false);
        let o = test_zip::offsets(&b, "s.npy");
        b[o.local + 8..o.local + 10].copy_from_slice(&method.to_le_bytes());
        b[o.central + 10..o.central + 12].copy_from_slice(&method.to_le_bytes());
        refused(&b, name);
    }
    // Deflated is read.
    let e = Calibration::from_bytes(&archive(&s, true), "c.npz");
    assert!(e.is_ok(), "{:?}", e.err().map(|e| e.to_string()));
}

/// A deflate bomb (40 MB of zeros in a few kB) whose shape disagrees with `gt` is
/// refused before it is decompressed; one whose header claims more than the zip
/// directory says is refused before it is read.
#[test]
fn bombs_are_refused_before_decompressing() {
    let s = npy_bytes((5000, 1000), 5000 * 1000 * 8);
    let bomb = archive(&s, true);
    assert!(bomb.len() < 200_000, "{}", bomb.len());
    let start = std::time::Instant::now();
    let e = Calibration::from_bytes(&bomb, "bomb.npz").err().unwrap().to_string();
    assert_eq!(
        e,
        "bomb.npz: ground truth shape 1x1 does not match calibration similarity shape 5000x1000"
    );
    assert!(
        start.elapsed() < std::time::Duration::from_millis(500),
        "{:?}",
        start.elapsed()
    );
    // A header claiming 80 GB over 8 bytes of data.
    let mut claim = npy_bytes((100_000, 100_000), 8);
    let e = Calibration::from_bytes(&archive(&claim, true), "c.npz")
        .err()
        .unwrap()
        .to_string();
    assert_eq!(
        e,
        "c.npz (array s) is corrupt: the zip directory says it holds 136 bytes, its .npy header \
         declares 80000000128"
    );
    claim = npy_bytes((1, 2), 8);
    let e = Calibration::from_bytes(&archive(&claim, true), "c.npz")
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.starts_with(
            "c.npz (array s) is corrupt: the zip directory says it holds 136 bytes, its .npy header declares 144"
        ),
        "{e}"
    );
}

/// A FIFO made in `dir`.
#[cfg(unix)]
fn fifo(dir: &Path, name: &str) -> PathBuf {
    use std::os::unix::ffi::OsStrExt;
    let path = dir.join(name);
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: mkfifo reads a NUL-terminated path that outlives the call.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    path
}

/// Open `path` without blocking (`write`: for writing, else for reading); for
/// writing, the descriptor is then made blocking again.
#[cfg(unix)]
fn open_nonblocking(path: &Path, write: bool) -> std::fs::File {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::OpenOptionsExt;
    let file = std::fs::OpenOptions::new()
        .read(!write)
        .write(write)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .unwrap();
    // SAFETY: fcntl on a descriptor this function owns, with integer arguments only.
    unsafe {
        let flags = libc::fcntl(file.as_raw_fd(), libc::F_GETFL);
        assert_eq!(
            libc::fcntl(file.as_raw_fd(), libc::F_SETFL, flags & !libc::O_NONBLOCK),
            0
        );
    }
    file
}

/// A FIFO input with no writer is an error at once; one with a writer is read as a
/// stream (a zip is read from its end, so it is read whole first), here larger than
/// a pipe's buffer so that the writer blocks until it is read.
#[cfg(unix)]
#[test]
fn a_fifo_input_is_an_error_without_a_writer_and_a_stream_with_one() {
    let d = dir();
    let path = fifo(d.path(), "cal.fifo");
    let start = std::time::Instant::now();
    let e = Calibration::load(&path).err().unwrap();
    assert!(
        start.elapsed() < std::time::Duration::from_secs(2),
        "{:?}",
        start.elapsed()
    );
    assert_eq!(
        e.to_string(),
        format!("cannot read {}: is a FIFO with no writer", path.display())
    );

    let mut x = 5u64;
    let s = Array2::from_shape_fn((100, 120), |_| {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((x >> 33) % 1000) as f64 / 1000.0
    });
    let gt = GroundTruth::new(Array2::from_shape_fn((100, 120), |(i, j)| i == j % 100).view()).unwrap();
    let cal = Calibration::new(s.view(), &gt, Matching::Single).unwrap();
    let bytes = cal.to_bytes(&DEFAULTS).unwrap();
    assert!(bytes.len() > 1 << 16, "{}", bytes.len());
    // A reader held open first, so that the writer opens without waiting (and is a
    // writer before the load looks for one); it never reads.
    let _holder = open_nonblocking(&path, false);
    let mut writer = open_nonblocking(&path, true);
    let sent = bytes.clone();
    let thread = std::thread::spawn(move || std::io::Write::write_all(&mut writer, &sent));
    let loaded = Calibration::load(&path).unwrap();
    thread.join().unwrap().unwrap();
    assert_eq!(loaded.defaults(), &DEFAULTS);
    // The same arrays and meta, so the same decisions (same_results is for |DB| = 6).
    assert_eq!(loaded.to_bytes(&DEFAULTS).unwrap(), bytes);
    assert_eq!(
        loaded.threshold(0.9).unwrap().to_bits(),
        cal.threshold(0.9).unwrap().to_bits()
    );

    // A stream that is not a zip archive is refused at its first bytes.
    let mut writer = open_nonblocking(&path, true);
    std::io::Write::write_all(&mut writer, b"\x93NUMPY not an archive").unwrap();
    drop(writer);
    let e = Calibration::load(&path).err().unwrap().to_string();
    assert_eq!(
        e,
        format!(
            "{} is not a valid .npz archive: a stream must start with a zip local header (PK\\x03\\x04)",
            path.display()
        )
    );
}

/// Saving through a symbolic link replaces its target and leaves the link; saving
/// to a FIFO with a reader sends the whole file; to one with none is an error.
#[cfg(unix)]
#[test]
fn save_follows_links_and_writes_fifos_in_place() {
    let d = dir();
    let cal = calibration(Matching::Multi, true);
    let target = d.path().join("target.npz");
    std::fs::write(&target, b"old").unwrap();
    let link = d.path().join("link.npz");
    std::os::unix::fs::symlink("target.npz", &link).unwrap();
    cal.save(&link, &DEFAULTS).unwrap();
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(&target).unwrap(), cal.to_bytes(&DEFAULTS).unwrap());

    let path = fifo(d.path(), "out.fifo");
    let e = cal.save(&path, &DEFAULTS).err().unwrap().to_string();
    assert!(
        e.contains(&path.display().to_string()) && e.contains("is a FIFO that nobody reads"),
        "{e}"
    );
    let mut reader = open_nonblocking(&path, false);
    // Until the writer opens, a read finds no writer and returns 0 at once: read
    // until something came and then the end.
    let thread = std::thread::spawn(move || {
        let (mut got, mut chunk) = (Vec::new(), [0u8; 4096]);
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while std::time::Instant::now() < deadline {
            match reader.read(&mut chunk).unwrap() {
                0 if got.is_empty() => std::thread::sleep(std::time::Duration::from_millis(1)),
                0 => break,
                n => got.extend_from_slice(&chunk[..n]),
            }
        }
        got
    });
    cal.save(&path, &DEFAULTS).unwrap();
    let got = thread.join().unwrap();
    assert_eq!(got, cal.to_bytes(&DEFAULTS).unwrap());
    let kind = std::fs::metadata(&path).unwrap().file_type();
    assert!(std::os::unix::fs::FileTypeExt::is_fifo(&kind));
}

#[test]
fn a_truncated_member_is_named() {
    let cal = calibration(Matching::Single, false);
    let bytes = cal.to_bytes(&DEFAULTS).unwrap();
    // Shrink s.npy's size in the directory and its data descriptor by 8: its .npy
    // header then claims more than the directory.
    let size = test_zip::unzip(&bytes)[0].1.len() as u32;
    let mut b = bytes.clone();
    test_zip::declare_size(&mut b, "s.npy", size - 8);
    let e = Calibration::from_bytes(&b, "t.npz").err().unwrap().to_string();
    assert!(
        e.starts_with("t.npz (array s) is corrupt: it is stored, yet the zip directory gives it"),
        "{e}"
    );
}
