//! End-to-end tests of what every command reads: hostile `.npy` headers on every path
//! that opens a file, errors in the files' own orientation, the ground-truth sources of
//! `evaluate`, and the exact wording of messages that were once wrong.

use std::path::PathBuf;
use std::process::Output;
use std::time::{Duration, Instant};

use tempfile::TempDir;

use crate::common::{assert_clean_failure, f64s, npy_bool, npy_f64, npy_header, npy_raw, ok_in, run_in};

struct Dir(TempDir);

impl Dir {
    fn new() -> Self {
        let dir = Self(tempfile::tempdir().unwrap());
        // The tiny case of tests/evaluate.rs: |DB| = 3, |Q| = 7; GT c0 -> db0, c1 -> db2,
        // d0 -> db0, d1 -> db2, i.e. query j matches database image j for j = 0 and the
        // rest as listed.
        npy_f64(
            &dir.path("S.npy"),
            &[
                &[0.9, 0.2, 0.7, 0.1, 0.5, 0.2, 0.3],
                &[0.1, 0.95, 0.3, 0.6, 0.4, 0.9, 0.3],
                &[0.3, 0.4, 0.2, 0.5, 0.3, 0.1, 0.3],
            ],
        );
        npy_bool(
            &dir.path("GT.npy"),
            &[&[1, 0, 1, 0, 0, 0, 0], &[0, 0, 0, 0, 0, 0, 0], &[0, 1, 0, 1, 0, 0, 0]],
        );
        npy_f64(&dir.path("p.npy"), &[&[0.0, 0.0], &[10.0, 0.0]]);
        dir
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }

    fn run(&self, args: &[&str]) -> Output {
        run_in(self.0.path(), args)
    }

    fn ok(&self, args: &[&str]) -> String {
        ok_in(self.0.path(), args)
    }

    /// Exit 2 with one `error:` line containing every needle, nothing written.
    fn fails(&self, args: &[&str], needles: &[&str]) -> String {
        let out = self.run(args);
        assert_clean_failure(&out, self.0.path(), &[&self.path("out")], needles);
        String::from_utf8(out.stderr).unwrap()
    }
}

/// A version 1.0 `.npy` of 128 bytes whose header nests 20 brackets inside its dict
/// (21 deep), followed by no data.
fn nested_header() -> Vec<u8> {
    let dict = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': {}{}}}",
        "[".repeat(20),
        "]".repeat(20)
    );
    let bytes = npy_header(&dict);
    assert_eq!(bytes.len(), 128);
    bytes
}

#[test]
fn nested_headers_fail_fast_on_every_path() {
    // Regression: `similarity`, `ground-truth --like` and the position files of a
    // ground-truth source opened headers with npyz directly, whose parser is exponential
    // in the nesting (16 levels took 1.4 s, 20 levels never finished in a test's time).
    let dir = Dir::new();
    std::fs::write(dir.path("nested.npy"), nested_header()).unwrap();
    let refused = "nested.npy is not a valid .npy file: its header nests brackets 21 deep";
    let positions = |prefix: &str| {
        [
            format!("--{prefix}db-positions"),
            "nested.npy".into(),
            format!("--{prefix}query-positions"),
            "p.npy".into(),
            format!("--{prefix}radius"),
            "1".into(),
        ]
    };
    let cal_gt: Vec<String> = positions("cal-gt-").into();
    let eval_gt: Vec<String> = positions("gt-").into();
    let gt: Vec<String> = positions("").into();
    let runs: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["similarity", "--db", "nested.npy", "--queries", "p.npy", "-o", "out"],
            "--db",
        ),
        (
            vec!["similarity", "--db", "p.npy", "--queries", "nested.npy", "-o", "out"],
            "--queries",
        ),
        (
            vec!["ground-truth", "--tolerance", "1", "--like", "nested.npy", "-o", "out"],
            "--like nested.npy",
        ),
        (
            [
                &["ground-truth", "-o", "out"][..],
                &gt.iter().map(String::as_str).collect::<Vec<_>>(),
            ]
            .concat(),
            "--db-positions nested.npy",
        ),
        (
            [
                &["threshold", "--cal", "S.npy", "--val", "S.npy", "-o", "out"][..],
                &cal_gt.iter().map(String::as_str).collect::<Vec<_>>(),
            ]
            .concat(),
            "--cal-gt-db-positions nested.npy",
        ),
        (
            [
                &["evaluate", "--similarity", "S.npy", "-o", "out"][..],
                &eval_gt.iter().map(String::as_str).collect::<Vec<_>>(),
            ]
            .concat(),
            "--gt-db-positions nested.npy",
        ),
    ];
    for (args, flag) in runs {
        let start = Instant::now();
        let stderr = dir.fails(&args, &[]);
        let elapsed = start.elapsed();
        assert!(elapsed < Duration::from_secs(1), "{args:?} took {elapsed:?}");
        assert_eq!(stderr, format!("error: {flag}: {refused}\n"), "{args:?}");
    }
}

#[test]
fn like_refuses_a_shape_larger_than_any_file() {
    // Regression: `--like` cast the header's u64 dimensions to usize unchecked and
    // then tried to allocate 2^64 entries.
    let dir = Dir::new();
    npy_raw(&dir.path("huge.npy"), "|b1", false, &[1 << 32, 1 << 32], &[]);
    dir.fails(
        &["ground-truth", "--tolerance", "1", "--like", "huge.npy", "-o", "out"],
        &["--like huge.npy: huge.npy is corrupt: its shape 4294967296x4294967296 is larger than any file"],
    );
}

#[test]
fn evaluate_query_major_errors_name_the_files_entries() {
    // Regression: `evaluate --query-major` reported positions and shapes of its
    // transposed view. The file is |Q| x |DB| = 7 x 3 with NaN at its row 5, column 1.
    let dir = Dir::new();
    let mut rows = vec![vec![0.5; 3]; 7];
    rows[5][1] = f64::NAN;
    let flat: Vec<f64> = rows.concat();
    npy_raw(&dir.path("S_t.npy"), "<f8", false, &[7, 3], &f64s(&flat));
    npy_raw(&dir.path("GT_t.npy"), "|b1", false, &[7, 3], &[0u8; 21]);
    let args = [
        "evaluate",
        "--similarity",
        "S_t.npy",
        "--gt",
        "GT_t.npy",
        "--query-major",
        "--cal-queries",
        "2",
        "--segment-size",
        "2",
        "-o",
        "out",
    ];
    let stderr = dir.fails(&args, &[]);
    assert_eq!(
        stderr,
        "error: --similarity S_t.npy / --gt GT_t.npy: similarity contains NaN at row 5, column 1; \
         scores must be finite\n"
    );
    // A ground truth of 6 x 3 against the 7 x 3 file, both as stored.
    npy_raw(&dir.path("GT_short_t.npy"), "|b1", false, &[6, 3], &[0u8; 18]);
    npy_raw(&dir.path("S_ok_t.npy"), "<f8", false, &[7, 3], &f64s(&[0.5; 21]));
    let mut args = args;
    (args[2], args[4]) = ("S_ok_t.npy", "GT_short_t.npy");
    dir.fails(&args, &["ground truth shape 6x3 does not match similarity shape 7x3"]);
}

#[test]
fn evaluate_takes_every_ground_truth_source() {
    let dir = Dir::new();
    // GT.npy is not a tolerance; a 3 x 7 tolerance 0 is the padded identity: db0 for
    // query 0, db1 for query 1, db2 for query 2. Write it as a file and compare.
    npy_bool(
        &dir.path("tol0.npy"),
        &[&[1, 0, 0, 0, 0, 0, 0], &[0, 1, 0, 0, 0, 0, 0], &[0, 0, 1, 0, 0, 0, 0]],
    );
    // Soft tolerance 1 adds |i - j| = 1.
    npy_bool(
        &dir.path("tol1.npy"),
        &[&[1, 1, 0, 0, 0, 0, 0], &[1, 1, 1, 0, 0, 0, 0], &[0, 1, 1, 1, 0, 0, 0]],
    );
    let common = [
        "evaluate",
        "--format",
        "json",
        "--similarity",
        "S.npy",
        "--cal-queries",
        "2",
        "--segment-size",
        "2",
        "--precision",
        "0.5",
    ];
    let run = |gt: &[&str]| dir.ok(&[&common[..], gt].concat());
    let file = run(&["--gt", "tol0.npy", "--gt-soft", "tol1.npy"]);
    let tolerance = run(&["--gt-tolerance", "0", "--gt-soft-tolerance", "1"]);
    // Only ground truth read from a file is evidence of the orientation: here every
    // database image has a positive and queries 3..6 (4 of 7) none, which is what a
    // transposed traverse looks like, and also a frame-aligned one whose queries run past
    // the database (a warning the evidence cannot avoid).
    let evidence = "  \"orientation\": {\n    \"db\": 3,\n    \"queries\": 7,\n    \"query_major\": false,\n    \
                    \"layout\": \"contradicted by the ground truth (queries without a positive: 4 of 7, while \
                    every database image has one)\",\n    \"evidence\": {\n      \"labelled_queries\": 7,\n      \"queries_without_positive\": 4,\n      \
                    \"db_without_positive\": 0,\n      \"verdict\": \"contradicts\"\n    }\n  },\n";
    let without = "  \"orientation\": {\n    \"db\": 3,\n    \"queries\": 7,\n    \"query_major\": false,\n    \
                   \"layout\": \"assumed (no ground truth was read in the matrix's layout to tell)\"\n  },\n";
    assert!(file.contains(evidence), "{file}");
    let file = file.replace(evidence, without);
    assert_eq!(file, tolerance);
    assert!(file.contains("\"quantile-transfer\""), "{file}");
    // Positions: database images at x = 0, 10, 20 and queries at x = 0, 10, 20, 30, ...:
    // radius 0 is the same padded identity, radius 10 the tolerance 1.
    npy_f64(&dir.path("db.npy"), &[&[0.0, 0.0], &[10.0, 0.0], &[20.0, 0.0]]);
    let q: Vec<[f64; 2]> = (0..7).map(|j| [10.0 * j as f64, 0.0]).collect();
    let q: Vec<&[f64]> = q.iter().map(|r| &r[..]).collect();
    npy_f64(&dir.path("q.npy"), &q);
    let positions = run(&[
        "--gt-db-positions",
        "db.npy",
        "--gt-query-positions",
        "q.npy",
        "--gt-radius",
        "0",
        "--gt-soft-radius",
        "10",
    ]);
    assert_eq!(file, positions);
    // The files' orientation applies to files only: tolerance and positions give
    // |DB| x |Q| of the oriented matrix. S_t.npy is S.npy stored query-major.
    let s: Vec<f64> = [
        [0.9, 0.2, 0.7, 0.1, 0.5, 0.2, 0.3],
        [0.1, 0.95, 0.3, 0.6, 0.4, 0.9, 0.3],
        [0.3, 0.4, 0.2, 0.5, 0.3, 0.1, 0.3],
    ]
    .concat();
    npy_raw(&dir.path("S_t.npy"), "<f8", true, &[7, 3], &f64s(&s));
    let mut args = common.to_vec();
    args[4] = "S_t.npy";
    args.extend(["--query-major", "--gt-tolerance", "0", "--gt-soft-tolerance", "1"]);
    // (Read query-major: the orientation says so.)
    let query_major = dir.ok(&args).replace("S_t.npy", "S.npy");
    assert_eq!(
        query_major.replace("\"query_major\": true", "\"query_major\": false"),
        file
    );
    // One source at most, and none without --similarity.
    let out = dir.run(&[&common[..], &["--gt", "tol0.npy", "--gt-tolerance", "0"]].concat());
    assert_eq!(out.status.code(), Some(2));
    let out = dir.run(&["evaluate", "--gt-tolerance", "0"]);
    assert_eq!(out.status.code(), Some(2));
    // A tolerance's errors name its option.
    dir.fails(
        &[
            &common[..],
            &["--gt-tolerance", "1", "--gt-soft-tolerance", "0", "-o", "out"],
        ]
        .concat(),
        &["--gt-soft-tolerance 0 is smaller than --gt-tolerance 1"],
    );
}

#[test]
fn a_bad_label_is_reported_once() {
    // Regression: the file's error carried the label error as its `source`, so the
    // whole chain printed it twice.
    let dir = Dir::new();
    let gt: Vec<u8> = [1i64, 0, 2, 1, 0, 0].iter().flat_map(|x| x.to_le_bytes()).collect();
    npy_raw(&dir.path("gt2.npy"), "<i8", false, &[3, 2], &gt);
    npy_f64(&dir.path("cal.npy"), &[&[3.0, 1.0], &[1.0, 4.0], &[2.0, 1.0]]);
    let stderr = dir.fails(
        &[
            "threshold",
            "--cal",
            "cal.npy",
            "--cal-gt",
            "gt2.npy",
            "--val",
            "cal.npy",
            "-o",
            "out",
        ],
        &[],
    );
    // The 2 is the third value in C order: row 1, column 0.
    assert_eq!(
        stderr,
        "error: --cal-gt: gt2.npy: ground truth has value 2 at row 1, column 0; ground truth must be 0/1 or bool\n"
    );
}

#[test]
fn a_database_mismatch_hints_at_query_major() {
    let dir = Dir::new();
    npy_f64(&dir.path("cal.npy"), &[&[3.0, 1.0], &[1.0, 4.0], &[2.0, 1.0]]);
    npy_bool(&dir.path("gt.npy"), &[&[1, 0], &[0, 1], &[0, 0]]);
    npy_f64(&dir.path("val.npy"), &[&[2.0, 2.0, 1.0], &[6.0, 5.0, 1.0]]);
    let args = [
        "threshold",
        "--cal",
        "cal.npy",
        "--cal-gt",
        "gt.npy",
        "--val",
        "val.npy",
        "-o",
        "out",
    ];
    let stderr = dir.fails(&args, &[]);
    assert_eq!(
        stderr,
        "error: --val val.npy: deployment similarity has 2 database images but calibration similarity has 3; \
         both must be scored against the same database; if the matrices are query-major (|Q| x |DB|, as VPR-Bench \
         stores them), pass --query-major\n"
    );
    // Given --query-major, the hint would be wrong: |DB| is then 2 (cal) vs 3 (val).
    // gt.npy, 3 x 2 as the calibration file, labels query i -> database image i.
    let stderr = dir.fails(
        &[
            "threshold",
            "--cal",
            "cal.npy",
            "--cal-gt",
            "gt.npy",
            "--val",
            "val.npy",
            "--query-major",
            "-o",
            "out",
        ],
        &[],
    );
    assert_eq!(
        stderr,
        "error: --val val.npy: deployment similarity has 3 database images but calibration similarity has 2; \
         both must be scored against the same database\n"
    );
}

#[test]
fn query_major_help_warns_about_vpr_bench() {
    let dir = Dir::new();
    for command in ["threshold", "evaluate"] {
        let help = dir.ok(&[command, "--help"]);
        let help = help.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(
            help.contains(
                "VPR-Bench files are query-major; a square matrix cannot be detected, so pass this flag for them"
            ),
            "{help}"
        );
    }
}
