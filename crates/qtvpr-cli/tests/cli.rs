//! End-to-end tests of `qtvpr-cli threshold`: a hand-computed run, and every bad input
//! of semantics §10 (exit 2, one `error:` line naming the file or argument, no panic,
//! no output file).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use tempfile::TempDir;

use crate::common::{assert_clean_failure, f64s, npy_bool, npy_f64, npy_header, npy_raw, run_in};

/// The `transfer.rs` unit-test example: |DB| = 3, two calibration, two deployment queries.
struct Case {
    dir: TempDir,
}

impl Case {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let case = Self { dir };
        npy_f64(&case.path("cal.npy"), &[&[3.0, 1.0], &[1.0, 4.0], &[2.0, 1.0]]);
        npy_bool(&case.path("gt.npy"), &[&[1, 1], &[0, 1], &[1, 0]]);
        npy_f64(&case.path("val.npy"), &[&[2.0, 2.0], &[6.0, 5.0], &[4.0, 2.0]]);
        case
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// Run `threshold` with the default files, each replaceable, plus extra arguments.
    fn run(&self, replace: &[(&str, PathBuf)], extra: &[&str]) -> Output {
        let mut files = vec![
            ("--cal", self.path("cal.npy")),
            ("--cal-gt", self.path("gt.npy")),
            ("--val", self.path("val.npy")),
        ];
        for (flag, path) in replace {
            files
                .iter_mut()
                .filter(|(f, _)| f == flag)
                .for_each(|(_, p)| *p = path.clone());
        }
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"));
        // A panic would print a backtrace: make sure that none does.
        cmd.env("RUST_BACKTRACE", "1").arg("threshold");
        for (flag, path) in files {
            cmd.arg(flag).arg(path);
        }
        cmd.args(["--output", self.path("out.json").to_str().unwrap()])
            .args(extra)
            .output()
            .unwrap()
    }

    /// Assert a clean failure whose one-line message contains every `needle`.
    fn fails(&self, replace: &[(&str, PathBuf)], extra: &[&str], needles: &[&str]) {
        let out = self.run(replace, extra);
        assert_clean_failure(&out, self.dir.path(), &[&self.path("out.json")], needles);
    }
}

#[test]
fn hand_computed_thresholds() {
    // See crates/qtvpr/src/operations/transfer.rs: with k = 1 and segments of one query the
    // quantiles are 0.5 and 1 and the thresholds 4 and the next f64 above 5.
    let case = Case::new();
    let out = case.run(&[], &["--k", "1", "--matching", "multi", "--segment-size", "1"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.path("out.json")).unwrap()).unwrap();
    assert_eq!(json["method"], "quantile-transfer");
    assert_eq!(
        json["params"],
        serde_json::json!({"k": 1, "precision": 1.0, "matching": "multi", "segment_size": 1, "gate": "none"})
    );
    let segs = json["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 2);
    assert_eq!(
        segs[0],
        serde_json::json!({"start": 0, "end": 1, "quantile": 0.5, "threshold": 4.0})
    );
    assert_eq!((segs[1]["start"].as_u64(), segs[1]["end"].as_u64()), (Some(1), Some(2)));
    assert_eq!(segs[1]["quantile"], 1.0);
    assert_eq!(segs[1]["threshold"].as_f64().unwrap(), 5.0f64.next_up());
}

#[test]
fn fortran_float32_and_integer_ground_truth_read_the_same() {
    let case = Case::new();
    // cal [[3, 1], [1, 4], [2, 1]] in Fortran order is the column-major payload 3,1,2,1,4,1.
    let cal: Vec<u8> = [3.0f32, 1.0, 2.0, 1.0, 4.0, 1.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    npy_raw(&case.path("cal_f.npy"), "<f4", true, &[3, 2], &cal);
    let gt: Vec<u8> = [1i64, 1, 0, 1, 1, 0].iter().flat_map(|x| x.to_le_bytes()).collect();
    npy_raw(&case.path("gt_i.npy"), "<i8", false, &[3, 2], &gt);
    let extra = ["--k", "1", "--matching", "multi", "--format", "csv"];
    case.run(&[], &extra);
    let a = std::fs::read_to_string(case.path("out.json")).unwrap();
    let b = case.run(
        &[("--cal", case.path("cal_f.npy")), ("--cal-gt", case.path("gt_i.npy"))],
        &extra,
    );
    assert!(b.status.success(), "{}", String::from_utf8_lossy(&b.stderr));
    let b = std::fs::read_to_string(case.path("out.json")).unwrap();
    // One batch: q = 0.5, threshold 3 (crates/qtvpr/src/operations/transfer.rs, one_neighbour_each).
    assert_eq!(a, "start,end,quantile,threshold\n0,2,0.5,3\n");
    assert_eq!(a, b);
}

#[test]
fn big_endian_files_are_read_too() {
    // Big-endian data cannot be viewed in place; it is read and converted instead.
    let case = Case::new();
    let cal: Vec<u8> = [3.0f64, 1.0, 1.0, 4.0, 2.0, 1.0]
        .iter()
        .flat_map(|x| x.to_be_bytes())
        .collect();
    npy_raw(&case.path("cal_be.npy"), ">f8", false, &[3, 2], &cal);
    let out = case.run(
        &[("--cal", case.path("cal_be.npy"))],
        &["--k", "1", "--matching", "multi", "--format", "csv"],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(case.path("out.json")).unwrap(),
        "start,end,quantile,threshold\n0,2,0.5,3\n"
    );
}

#[test]
fn query_major_transposes_every_matrix() {
    let case = Case::new();
    npy_f64(&case.path("cal_t.npy"), &[&[3.0, 1.0, 2.0], &[1.0, 4.0, 1.0]]);
    npy_bool(&case.path("gt_t.npy"), &[&[1, 0, 1], &[1, 1, 0]]);
    npy_f64(&case.path("val_t.npy"), &[&[2.0, 6.0, 4.0], &[2.0, 5.0, 2.0]]);
    let files = [
        ("--cal", case.path("cal_t.npy")),
        ("--cal-gt", case.path("gt_t.npy")),
        ("--val", case.path("val_t.npy")),
    ];
    let out = case.run(
        &files,
        &["--query-major", "--k", "1", "--matching", "multi", "--format", "csv"],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(case.path("out.json")).unwrap(),
        "start,end,quantile,threshold\n0,2,0.5,3\n"
    );
}

#[test]
fn bad_parameters() {
    let case = Case::new();
    case.fails(&[], &["--k", "0"], &["k must be >= 1, got 0"]);
    for tau in ["0", "1.5", "NaN", "-1"] {
        case.fails(&[], &["--precision", tau], &["precision must be in (0, 1]"]);
    }
    case.fails(
        &[],
        &["--segment-size", "0"],
        &["segment size must be between 1 and the number of deployment queries (2), got 0"],
    );
    case.fails(&[], &["--segment-size", "3"], &["got 3"]);
    // The pool size is the core's to check, named by the option.
    let out = run_in(case.dir.path(), &["--threads", "0", "evaluate"]);
    assert_clean_failure(&out, case.dir.path(), &[], &["--threads: threads must be >= 1, got 0"]);
    // clap's own usage errors also exit 2.
    let out = case.run(&[], &["--matching", "best"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn more_threads_than_the_cap_exit_2() {
    // Issue 49: --threads 1000000 used to start up to 65,535 threads one by one, for
    // minutes. The cap is 1024 (qtvpr::MAX_THREADS); refused before any thread starts.
    let case = Case::new();
    for n in ["1025", "1000000"] {
        let out = run_in(case.dir.path(), &["--threads", n, "evaluate"]);
        let want = format!("--threads: threads must be at most 1024, got {n}");
        assert_clean_failure(&out, case.dir.path(), &[], &[&want]);
    }
}

#[test]
fn shape_mismatches() {
    let case = Case::new();
    npy_bool(&case.path("gt_wide.npy"), &[&[1, 1, 0], &[0, 1, 0], &[1, 0, 0]]);
    case.fails(
        &[("--cal-gt", case.path("gt_wide.npy"))],
        &[],
        &[
            "--cal",
            "ground truth shape 3x3 does not match calibration similarity shape 3x2",
        ],
    );
    npy_f64(&case.path("val_short.npy"), &[&[2.0, 2.0], &[6.0, 5.0]]);
    case.fails(
        &[("--val", case.path("val_short.npy"))],
        &[],
        &[
            "--val",
            "val_short.npy",
            "deployment similarity has 2 database images but calibration similarity has 3",
        ],
    );
}

#[test]
fn non_finite_and_empty_scores() {
    let case = Case::new();
    for (value, name) in [(f64::NAN, "NaN"), (f64::INFINITY, "inf"), (f64::NEG_INFINITY, "-inf")] {
        npy_f64(&case.path("val_bad.npy"), &[&[2.0, 2.0], &[6.0, 5.0], &[4.0, value]]);
        case.fails(
            &[("--val", case.path("val_bad.npy"))],
            &[],
            &[
                "--val",
                &format!("deployment similarity contains {name} at row 2, column 1"),
            ],
        );
    }
    npy_raw(&case.path("empty_rows.npy"), "<f8", false, &[0, 2], &[]);
    case.fails(
        &[("--val", case.path("empty_rows.npy"))],
        &[],
        &["deployment similarity is empty (shape 0x2)"],
    );
    npy_raw(&case.path("empty_cols.npy"), "<f8", false, &[3, 0], &[]);
    case.fails(
        &[("--cal", case.path("empty_cols.npy"))],
        &[],
        &["--cal", "calibration similarity is empty (shape 3x0)"],
    );
}

#[test]
fn wrong_dimensions_and_dtypes() {
    let case = Case::new();
    npy_raw(&case.path("one_d.npy"), "<f8", false, &[3], &f64s(&[1.0, 2.0, 3.0]));
    case.fails(
        &[("--val", case.path("one_d.npy"))],
        &[],
        &["--val", "one_d.npy holds a 1-D array", "expected a 2-D matrix"],
    );
    npy_raw(&case.path("three_d.npy"), "<f8", false, &[1, 1, 2], &f64s(&[1.0, 2.0]));
    case.fails(
        &[("--cal", case.path("three_d.npy"))],
        &[],
        &["three_d.npy holds a 3-D array"],
    );
    for (descr, size) in [("<c16", 16), ("<U3", 12), ("<f2", 2), ("<i8", 8)] {
        npy_raw(&case.path("dtype.npy"), descr, false, &[3, 2], &vec![0u8; 6 * size]);
        case.fails(
            &[("--val", case.path("dtype.npy"))],
            &[],
            &[
                "--val",
                &format!("dtype.npy has dtype {descr}; expected float32 or float64 similarity scores"),
            ],
        );
    }
    npy_raw(&case.path("object.npy"), "|O", false, &[3, 2], &[0u8; 48]);
    case.fails(
        &[("--cal", case.path("object.npy"))],
        &[],
        &["--cal", "object.npy has dtype |O"],
    );
    npy_raw(
        &case.path("gt_float.npy"),
        "<f8",
        false,
        &[3, 2],
        &f64s(&[1.0, 1.0, 0.0, 1.0, 1.0, 0.0]),
    );
    case.fails(
        &[("--cal-gt", case.path("gt_float.npy"))],
        &[],
        &["--cal-gt", "expected bool or integer 0/1 ground truth"],
    );
}

#[test]
fn ground_truth_values_must_be_zero_or_one() {
    let case = Case::new();
    for (value, shown) in [(2i64, "2"), (-1, "-1")] {
        let gt: Vec<u8> = [1i64, 1, 0, 1, value, 0].iter().flat_map(|x| x.to_le_bytes()).collect();
        npy_raw(&case.path("gt_bad.npy"), "<i8", false, &[3, 2], &gt);
        case.fails(
            &[("--cal-gt", case.path("gt_bad.npy"))],
            &[],
            &[
                "--cal-gt",
                "gt_bad.npy",
                &format!("ground truth has value {shown} at row 2, column 0"),
            ],
        );
    }
}

#[test]
fn broken_files() {
    let case = Case::new();
    let good = std::fs::read(case.path("val.npy")).unwrap();
    std::fs::write(case.path("truncated.npy"), &good[..good.len() - 5]).unwrap();
    case.fails(
        &[("--val", case.path("truncated.npy"))],
        &[],
        &["--val", "truncated.npy is truncated"],
    );
    std::fs::write(case.path("cut_header.npy"), &good[..30]).unwrap();
    case.fails(
        &[("--cal", case.path("cut_header.npy"))],
        &[],
        &["--cal", "cut_header.npy is not a valid .npy file"],
    );
    let mut corrupt = good.clone();
    corrupt[12..20].copy_from_slice(b"garbage!");
    std::fs::write(case.path("corrupt.npy"), corrupt).unwrap();
    case.fails(
        &[("--val", case.path("corrupt.npy"))],
        &[],
        &["--val", "corrupt.npy is not a valid .npy file"],
    );
    std::fs::write(case.path("text.npy"), "these are not the scores you are looking for").unwrap();
    case.fails(
        &[("--cal", case.path("text.npy"))],
        &[],
        &["--cal", "text.npy is not a valid .npy file"],
    );
    case.fails(
        &[("--cal", case.path("missing.npy"))],
        &[],
        &["--cal", "cannot read", "missing.npy"],
    );
    std::fs::create_dir(case.path("dir.npy")).unwrap();
    case.fails(
        &[("--val", case.path("dir.npy"))],
        &[],
        &["--val", "dir.npy: is a directory"],
    );
}

#[test]
fn a_missing_cal_without_ground_truth_is_named_missing() {
    // Issue 49: `threshold --cal missing.npz` without --cal-gt called it "a similarity
    // matrix, which needs its ground truth". A file that cannot be opened says why.
    let case = Case::new();
    std::fs::create_dir(case.path("dir.npz")).unwrap();
    for (cal, why) in [
        (
            "missing.npz",
            "--cal: cannot read missing.npz: No such file or directory",
        ),
        ("dir.npz", "--cal: cannot read dir.npz: is a directory"),
    ] {
        let out = run_in(case.dir.path(), &["threshold", "--cal", cal, "--val", "val.npy"]);
        assert_clean_failure(&out, case.dir.path(), &[], &[why]);
        assert!(!String::from_utf8_lossy(&out.stderr).contains("similarity matrix"));
    }
    // A file that is there is still a matrix that needs its ground truth.
    let out = run_in(case.dir.path(), &["threshold", "--cal", "cal.npy", "--val", "val.npy"]);
    assert_clean_failure(
        &out,
        case.dir.path(),
        &[],
        &["--cal cal.npy is a similarity matrix, which needs its ground truth"],
    );
}

#[test]
fn npz_ground_truth() {
    let case = Case::new();
    let write_npz = |path: &Path, names: &[&str]| {
        let labels = ndarray::array![[true, true], [false, true], [true, false]];
        let arrays: Vec<_> = names
            .iter()
            .map(|&n| (n, qtvpr::npy::NpyArray::Bool(labels.view())))
            .collect();
        qtvpr::npy::write_npz(path, &arrays).unwrap();
    };
    write_npz(&case.path("gt.npz"), &["GThard", "GTsoft"]);
    let out = case.run(
        &[("--cal-gt", case.path("gt.npz"))],
        &["--k", "1", "--matching", "multi", "--format", "csv"],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::remove_file(case.path("out.json")).unwrap();
    write_npz(&case.path("nohard.npz"), &["GTsoft"]);
    case.fails(
        &[("--cal-gt", case.path("nohard.npz"))],
        &[],
        &["--cal-gt", "nohard.npz has no array GThard"],
    );
    std::fs::write(case.path("bad.npz"), "not a zip").unwrap();
    case.fails(
        &[("--cal-gt", case.path("bad.npz"))],
        &[],
        &["--cal-gt", "bad.npz is not a valid .npz archive"],
    );
}

#[test]
fn query_major_errors_use_the_files_orientation() {
    // Query-major files are |Q| x |DB|: positions and shapes in messages are the files'.
    let case = Case::new();
    npy_f64(&case.path("cal_t.npy"), &[&[3.0, 1.0, 2.0], &[1.0, 4.0, 1.0]]);
    npy_bool(&case.path("gt_t.npy"), &[&[1, 0, 1], &[1, 1, 0]]);
    // NaN at the file's row 1, column 2 (the core sees row 2, column 1).
    npy_f64(&case.path("val_t.npy"), &[&[2.0, 6.0, 4.0], &[2.0, 5.0, f64::NAN]]);
    let files = [
        ("--cal", case.path("cal_t.npy")),
        ("--cal-gt", case.path("gt_t.npy")),
        ("--val", case.path("val_t.npy")),
    ];
    case.fails(
        &files,
        &["--query-major"],
        &["--val", "deployment similarity contains NaN at row 1, column 2"],
    );
    // Ground truth of 3 queries x 3 database images against 2 x 3 calibration scores.
    npy_bool(&case.path("gt_tall.npy"), &[&[1, 0, 1], &[1, 1, 0], &[0, 0, 0]]);
    case.fails(
        &[
            ("--cal", case.path("cal_t.npy")),
            ("--cal-gt", case.path("gt_tall.npy")),
            ("--val", case.path("cal_t.npy")),
        ],
        &["--query-major"],
        &["ground truth shape 3x3 does not match calibration similarity shape 2x3"],
    );
    // A bad label is reported where it is in the file, query-major or not.
    let gt: Vec<u8> = [1i16, 0, 1, 1, 1, 2].iter().flat_map(|x| x.to_le_bytes()).collect();
    npy_raw(&case.path("gt_bad_t.npy"), "<i2", false, &[2, 3], &gt);
    case.fails(
        &[
            ("--cal", case.path("cal_t.npy")),
            ("--cal-gt", case.path("gt_bad_t.npy")),
            ("--val", case.path("cal_t.npy")),
        ],
        &["--query-major"],
        &["gt_bad_t.npy: ground truth has value 2 at row 1, column 2"],
    );
    // An empty query-major matrix: 0 queries x 3 database images.
    npy_raw(&case.path("val_empty_t.npy"), "<f8", false, &[0, 3], &[]);
    case.fails(
        &[
            ("--cal", case.path("cal_t.npy")),
            ("--cal-gt", case.path("gt_t.npy")),
            ("--val", case.path("val_empty_t.npy")),
        ],
        &["--query-major"],
        &["deployment similarity is empty (shape 0x3)"],
    );
}

#[test]
fn headers_claiming_impossible_shapes() {
    // Regression: a shape whose element count overflows 64 bits wraps to 0 in npyz (it
    // multiplies unchecked), passed the reader's length check, and the reader panicked
    // building the array (debug builds panicked inside npyz). Found reading npyz for
    // the fuzz/npy_read target.
    let case = Case::new();
    let huge = 1usize << 32;
    for (flag, descr) in [
        ("--cal-gt", "|b1"),
        ("--cal", "<f8"),
        ("--val", ">f8"),
        ("--cal-gt", "<i8"),
    ] {
        npy_raw(&case.path("huge.npy"), descr, false, &[huge, huge], &[0u8; 16]);
        case.fails(
            &[(flag, case.path("huge.npy"))],
            &[],
            &[
                flag,
                "huge.npy is corrupt: its shape 4294967296x4294967296 is larger than any file",
            ],
        );
    }
    // 2^63 bytes: more than isize::MAX, which no array can hold.
    npy_raw(&case.path("large.npy"), "|b1", false, &[1 << 40, 1 << 23], &[1u8; 16]);
    case.fails(
        &[("--cal-gt", case.path("large.npy"))],
        &[],
        &[
            "--cal-gt",
            "large.npy is corrupt: its shape 1099511627776x8388608 is larger than any file",
        ],
    );
    // Large but possible: simply truncated.
    npy_raw(&case.path("large.npy"), "|b1", false, &[1 << 30, 1 << 20], &[1u8; 16]);
    case.fails(
        &[("--cal-gt", case.path("large.npy"))],
        &[],
        &["--cal-gt", "large.npy is truncated"],
    );
}

#[test]
fn deeply_nested_headers_fail_fast() {
    // Regression: npyz's header parser backtracks exponentially in bracket nesting; a
    // 100-byte header of `[[[[...` never finished. Found by fuzz/npy_read (a hang).
    let case = Case::new();
    let nested = |depth: usize| {
        npy_header(&format!(
            "{{'descr': '|b1', 'shape': {}{}",
            "[".repeat(depth),
            "('fortran'".repeat(3)
        ))
    };
    std::fs::write(case.path("nested.npy"), nested(100)).unwrap();
    case.fails(
        &[("--cal-gt", case.path("nested.npy"))],
        &[],
        &[
            "--cal-gt",
            "nested.npy is not a valid .npy file: its header nests brackets 104 deep",
        ],
    );
    case.fails(
        &[("--val", case.path("nested.npy"))],
        &[],
        &[
            "--val",
            "nested.npy is not a valid .npy file: its header nests brackets 104 deep",
        ],
    );
    // At the deepest nesting allowed (6) the parser still answers at once.
    std::fs::write(case.path("nested.npy"), nested(2)).unwrap();
    let start = std::time::Instant::now();
    case.fails(
        &[("--val", case.path("nested.npy"))],
        &[],
        &["--val", "is not a valid .npy file"],
    );
    assert!(start.elapsed().as_secs() < 10);
}

#[test]
fn one_matrix_split_by_the_core() {
    // The hand-computed case as one matrix: columns 0-1 are `cal.npy`, 2-3 `val.npy`,
    // and the ground truth labels all four (its last two columns are not used).
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name);
    let case = Case::new();
    let cal_val = [
        "--k",
        "1",
        "--matching",
        "multi",
        "--segment-size",
        "1",
        "--format",
        "csv",
    ];
    let want = case.run(&[], &cal_val);
    assert!(want.status.success(), "{}", String::from_utf8_lossy(&want.stderr));
    let want = std::fs::read_to_string(case.path("out.json")).unwrap();
    npy_f64(
        &path("S.npy"),
        &[&[3.0, 1.0, 2.0, 2.0], &[1.0, 4.0, 6.0, 5.0], &[2.0, 1.0, 4.0, 2.0]],
    );
    npy_bool(&path("GT.npy"), &[&[1, 1, 0, 1], &[0, 1, 1, 0], &[1, 0, 0, 0]]);
    npy_bool(&path("GT_cal.npy"), &[&[1, 1], &[0, 1], &[1, 0]]);
    let threshold = |extra: &[&str]| {
        let base = ["threshold", "--similarity", "S.npy", "--cal-gt"];
        run_in(dir.path(), &[&base[..], extra, &cal_val[..]].concat())
    };
    // floor(0.5 x 4) = 2: the same split as --cal-queries 2, and as --cal / --val.
    for split in [["--cal-queries", "2"], ["--cal-fraction", "0.5"]] {
        let out = threshold(&[&["GT.npy"][..], &split[..]].concat());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        assert_eq!(String::from_utf8(out.stdout).unwrap(), want);
    }
    let fails = |extra: &[&str], message: &str| {
        let out = threshold(extra);
        assert_clean_failure(&out, dir.path(), &[], &[]);
        assert_eq!(String::from_utf8_lossy(&out.stderr), format!("error: {message}\n"));
    };
    fails(
        &["GT.npy", "--cal-queries", "0"],
        "--cal-queries: cal queries must be >= 1, got 0",
    );
    fails(
        &["GT.npy", "--cal-queries", "4"],
        "--cal-queries of --similarity S.npy: the calibration set must have between 1 and 3 of the 4 \
         queries, got 4",
    );
    fails(
        &["GT.npy", "--cal-fraction", "1"],
        "--cal-fraction: cal fraction must be in (0, 1), got 1",
    );
    fails(
        &["GT.npy", "--cal-fraction", "0.2"],
        "--cal-fraction of --similarity S.npy: the calibration set must have between 1 and 3 of the 4 \
         queries, got 0",
    );
    fails(
        &["GT_cal.npy", "--cal-queries", "2"],
        "--similarity S.npy / --cal-gt GT_cal.npy: ground truth shape 3x2 does not match similarity \
         shape 3x4; the ground truth of a split labels every query, of which the first 2 calibrate",
    );
    // A NaN in deployment query 1 is column 2 + 1 = 3 of the matrix.
    npy_f64(
        &path("S.npy"),
        &[&[3.0, 1.0, 2.0, 2.0], &[1.0, 4.0, 6.0, f64::NAN], &[2.0, 1.0, 4.0, 2.0]],
    );
    fails(
        &["GT.npy", "--cal-queries", "2"],
        "--similarity S.npy: deployment similarity contains NaN at row 1, column 3; scores must be finite",
    );
}
