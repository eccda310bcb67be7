//! `threshold`, `evaluate` and `calibrate` from descriptor files on real Nordland HOG
//! descriptors (`../shared/data`): the same bytes as `similarity` followed by the matrix
//! path, one matrix split as the same matrix sliced first, and every bad input a clean
//! exit 2 naming the file (and the row).

use ndarray::{Array2, s};
use qtvpr::ScoresView;
use qtvpr::npy::{read_scores, write_npy};
use tempfile::TempDir;

use crate::common::{assert_clean_failure, ok_in, run_in};
use qtvpr_testkit::data;

/// Queries of the test: the first 600 summer frames (137 calibrate, not a multiple of
/// the kernel's tile of 16).
const N_Q: usize = 600;
const N_CAL: usize = 137;

/// A directory with `db.npy` (3576 x 756 winter descriptors), `q.npy` (the first 600
/// summer descriptors), their similarity `S.npy` written by `similarity`, its halves
/// `S_cal.npy` / `S_val.npy`, `q_val.npy` (queries 137..600), and ground truth for all
/// queries (`gt.npy`, |i - j| <= 1) and for the calibration ones (`gt_cal.npy`).
fn case() -> Option<(TempDir, Array2<f32>)> {
    let (db, q) = data::nordland(N_Q)?;
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    write_npy(&p("db.npy"), db.view()).unwrap();
    write_npy(&p("q.npy"), q.view()).unwrap();
    write_npy(&p("q_val.npy"), q.slice(s![N_CAL.., ..])).unwrap();
    ok_in(
        dir.path(),
        &[
            "similarity",
            "--db",
            "db.npy",
            "--queries",
            "q.npy",
            "-o",
            "S.npy",
            "-q",
        ],
    );
    let s = match read_scores(&p("S.npy")).unwrap().view() {
        ScoresView::F32(v) => v.to_owned(),
        ScoresView::F64(_) => panic!("similarity writes float32"),
    };
    write_npy(&p("S_cal.npy"), s.slice(s![.., ..N_CAL])).unwrap();
    write_npy(&p("S_val.npy"), s.slice(s![.., N_CAL..])).unwrap();
    let gt = Array2::from_shape_fn((3576, N_Q), |(i, j)| i.abs_diff(j) <= 1);
    write_npy(&p("gt.npy"), gt.view()).unwrap();
    write_npy(&p("gt_cal.npy"), gt.slice(s![.., ..N_CAL])).unwrap();
    Some((dir, q))
}

const DESCRIPTORS: [&str; 4] = ["--db-descriptors", "db.npy", "--query-descriptors", "q.npy"];

fn args<'a>(a: &[&'a str], b: &[&'a str]) -> Vec<&'a str> {
    a.iter().chain(b).copied().collect()
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: descriptors in = `similarity` then the matrix path"]
fn threshold_and_calibrate_from_descriptors_equal_the_matrix_path() {
    let Some((dir, _)) = case() else {
        return;
    };
    let d = dir.path();
    for opts in [
        &["--segment-size", "10"][..],
        &["--segment-size", "64", "--matching", "multi", "--k", "5"],
        &["--precision", "0.9"],
    ] {
        let run = |a: &[&str]| without_orientation(&ok_in(d, &args(&args(&["threshold", "-q"], a), opts)));
        // The matrix sliced first: the reference.
        let want = run(&["--cal", "S_cal.npy", "--cal-gt", "gt_cal.npy", "--val", "S_val.npy"]);
        assert_eq!([&want["calibration_queries"], &want["deployment_queries"]], [137, 463]);
        // One matrix split, with ground truth for every query or a tolerance.
        let split = ["--cal-queries", "137", "--cal-gt", "gt.npy"];
        assert_eq!(run(&args(&["--similarity", "S.npy"], &split)), want, "{opts:?}");
        // floor(0.229 * 600) = 137: the same split as a fraction.
        let fraction = ["--cal-fraction", "0.229", "--cal-gt-tolerance", "1"];
        assert_eq!(run(&args(&["--similarity", "S.npy"], &fraction)), want, "{opts:?}");
        // Descriptors, never a matrix.
        assert_eq!(run(&args(&DESCRIPTORS, &split)), want, "{opts:?}");
        assert_eq!(run(&args(&DESCRIPTORS, &fraction)), want, "{opts:?}");
    }
    // calibrate from descriptors, then threshold the deployment descriptors with it:
    // the same as the calibration file of the matrix with the matrix of q_val.
    let cal = [
        "calibrate",
        "--cal-gt-tolerance",
        "1",
        "--cal-queries",
        "137",
        "-o",
        "cal_d.npz",
    ];
    ok_in(d, &args(&cal, &DESCRIPTORS));
    ok_in(
        d,
        &[
            "calibrate",
            "--cal",
            "S_cal.npy",
            "--cal-gt-tolerance",
            "1",
            "-o",
            "cal_s.npz",
        ],
    );
    assert_eq!(
        std::fs::read(d.join("cal_d.npz")).unwrap(),
        std::fs::read(d.join("cal_s.npz")).unwrap()
    );
    ok_in(
        d,
        &[
            "similarity",
            "--db",
            "db.npy",
            "--queries",
            "q_val.npy",
            "-o",
            "S_qval.npy",
            "-q",
        ],
    );
    let fused = ["threshold", "-q", "--cal", "cal_d.npz", "--db-descriptors", "db.npy"];
    let got = ok_in(
        d,
        &args(&fused, &["--query-descriptors", "q_val.npy", "--segment-size", "50"]),
    );
    let want = ok_in(
        d,
        &[
            "threshold",
            "-q",
            "--cal",
            "cal_s.npz",
            "--val",
            "S_qval.npy",
            "--segment-size",
            "50",
        ],
    );
    assert_eq!(without_orientation(&got), without_orientation(&want));
}

/// The JSON document without its `orientation`, which only a similarity matrix has
/// (with evidence that depends on its ground truth's source).
fn without_orientation(json: &str) -> serde_json::Value {
    let mut v: serde_json::Value = serde_json::from_str(json).unwrap();
    v.as_object_mut().unwrap().remove("orientation");
    v
}

/// The JSON without its `dataset` line (a file name, which differs by construction).
fn without_dataset(json: &str) -> String {
    json.lines()
        .filter(|l| !l.contains("\"dataset\""))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: `evaluate` of descriptors = of their matrix"]
fn evaluate_from_descriptors_equals_the_matrix_path() {
    let Some((dir, _)) = case() else {
        return;
    };
    let d = dir.path();
    let opts = [
        "--cal-queries",
        "137",
        "--segment-size",
        "20",
        "--gt",
        "gt.npy",
        "-q",
        "--format",
        "json",
    ];
    let want = ok_in(d, &args(&["evaluate", "--similarity", "S.npy"], &opts));
    let got = ok_in(d, &args(&args(&["evaluate"], &DESCRIPTORS), &opts));
    assert!(got.contains("\"dataset\": \"db.npy x q.npy\""), "{got}");
    assert_eq!(
        without_orientation(&without_dataset(&got)),
        without_orientation(&without_dataset(&want))
    );
    // --sequence 5: as `similarity --sequence 5` and the matrix path.
    ok_in(
        d,
        &[
            "similarity",
            "--db",
            "db.npy",
            "--queries",
            "q.npy",
            "--sequence",
            "5",
            "-o",
            "S5.npy",
            "-q",
        ],
    );
    let want = ok_in(d, &args(&["evaluate", "--similarity", "S5.npy"], &opts));
    let got = ok_in(d, &args(&args(&["evaluate", "--sequence", "5"], &DESCRIPTORS), &opts));
    assert_eq!(
        without_orientation(&without_dataset(&got)),
        without_orientation(&without_dataset(&want))
    );
    assert_ne!(
        without_dataset(&got),
        without_dataset(&ok_in(d, &args(&["evaluate", "--similarity", "S.npy"], &opts)))
    );
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: the valid descriptor files its bad ones are made from"]
fn bad_descriptors_and_options_exit_2_naming_the_file() {
    let Some((dir, q)) = case() else {
        return;
    };
    let d = dir.path();
    let mut nan = q.clone();
    nan[[3, 5]] = f32::NAN;
    write_npy(&d.join("q_nan.npy"), nan.view()).unwrap();
    let mut zero = q.clone();
    zero.row_mut(42).fill(0.0);
    write_npy(&d.join("q_zero.npy"), zero.view()).unwrap();
    write_npy(&d.join("q_narrow.npy"), q.slice(s![.., ..755])).unwrap();
    write_npy(&d.join("q_empty.npy"), q.slice(s![..0, ..])).unwrap();
    let out = d.join("out.json");
    let fail = |a: &[&str], needles: &[&str]| {
        let a = args(a, &["-o", "out.json"]);
        assert_clean_failure(&run_in(d, &a), d, &[&out], needles);
    };
    let split = ["--cal-queries", "137", "--cal-gt-tolerance", "1"];
    let with_q = |q: &'static str| -> Vec<&'static str> {
        args(
            &["threshold", "--db-descriptors", "db.npy", "--query-descriptors", q],
            &split,
        )
    };
    fail(
        &with_q("q_nan.npy"),
        &["--query-descriptors q_nan.npy", "NaN at row 3, column 5"],
    );
    fail(
        &with_q("q_zero.npy"),
        &["--query-descriptors q_zero.npy", "row 42 is all zeros"],
    );
    fail(
        &with_q("q_narrow.npy"),
        &["--query-descriptors q_narrow.npy", "755 columns", "756"],
    );
    fail(&with_q("q_empty.npy"), &["q_empty.npy", "empty"]);
    let eval = [
        "evaluate",
        "--db-descriptors",
        "db.npy",
        "--query-descriptors",
        "q_zero.npy",
        "--gt-tolerance",
        "1",
    ];
    fail(&eval, &["--query-descriptors q_zero.npy", "row 42 is all zeros"]);
    let cal = [
        "calibrate",
        "--db-descriptors",
        "db.npy",
        "--query-descriptors",
        "q_nan.npy",
        "--cal-gt-tolerance",
        "1",
    ];
    fail(&cal, &["--query-descriptors q_nan.npy", "row 3"]);
    // Mixed inputs are usage errors (clap's: exit 2, the error with a usage line).
    let usage = |a: &[&str], needle: &str| {
        let out = run_in(d, &args(a, &["-o", "out.json"]));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(stderr.starts_with("error: ") && stderr.contains(needle), "{stderr}");
        assert!(!d.join("out.json").exists());
    };
    usage(
        &args(&["threshold", "--similarity", "S.npy"], &args(&DESCRIPTORS, &split)),
        "cannot be used with",
    );
    usage(
        &args(
            &["threshold", "--val", "S_val.npy", "--cal", "S_cal.npy"],
            &args(&DESCRIPTORS, &split),
        ),
        "cannot be used with",
    );
    usage(
        &[
            "evaluate",
            "--similarity",
            "S.npy",
            "--db-descriptors",
            "db.npy",
            "--query-descriptors",
            "q.npy",
            "--gt-tolerance",
            "1",
        ],
        "cannot be used with",
    );
    usage(
        &args(&["threshold", "--similarity", "S.npy"], &["--cal-gt-tolerance", "1"]),
        "--cal-queries",
    );
    // The split: a bad fraction, too many queries, ground truth of the calibration only.
    let base = args(&["threshold"], &DESCRIPTORS);
    fail(
        &args(&base, &["--cal-fraction", "1.5", "--cal-gt-tolerance", "1"]),
        &["--cal-fraction", "must be in (0, 1), got 1.5"],
    );
    fail(
        &args(&base, &["--cal-queries", "600", "--cal-gt-tolerance", "1"]),
        &["--cal-queries", "between 1 and 599 of the 600 queries"],
    );
    // A fraction too small for any query: the real count, no sentinel.
    let tiny = args(&base, &["--cal-fraction", "1e-300", "--cal-gt-tolerance", "1"]);
    fail(
        &tiny,
        &["--cal-fraction", "between 1 and 599 of the 600 queries, got 0"],
    );
    let calibrate = args(&["calibrate"], &DESCRIPTORS);
    fail(
        &args(&calibrate, &["--cal-fraction", "1e-300", "--cal-gt-tolerance", "1"]),
        &["--cal-fraction", "between 1 and 599 of the 600 queries, got 0"],
    );
    fail(
        &args(&base, &["--cal-queries", "137", "--cal-gt", "gt_cal.npy"]),
        &["--cal-gt gt_cal.npy", "3576x137", "3576x600", "labels every query"],
    );
    fail(&args(&base, &["--cal-gt-tolerance", "1"]), &["no calibration"]);
    // --sequence needs the whole matrix: threshold says what to do instead.
    fail(
        &args(&args(&base, &split), &["--sequence", "5"]),
        &["similarity --sequence L", "evaluate --sequence L"],
    );
}
