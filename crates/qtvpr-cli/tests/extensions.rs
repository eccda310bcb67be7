//! End-to-end tests of `qtvpr-cli similarity`, `qtvpr-cli ground-truth`, and the
//! ground-truth sources of `threshold` (`--cal-gt-tolerance`, `--cal-gt-db-positions`):
//! hand-computed results, and bad input (exit 2, one `error:` line naming the option
//! and file, no output file).

use std::path::{Path, PathBuf};
use std::process::Output;

use tempfile::TempDir;

use crate::common::{assert_clean_failure, f64s, npy_bool, npy_f32, npy_f64, npy_raw, ok_in, run_in};

struct Dir(TempDir);

impl Dir {
    fn new() -> Self {
        Self(tempfile::tempdir().unwrap())
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }

    /// Run `qtvpr-cli` with `args`; a bare file name in `args` stays as it is, so
    /// the command runs inside the directory.
    fn run(&self, args: &[&str]) -> Output {
        run_in(self.0.path(), args)
    }

    fn ok(&self, args: &[&str]) {
        ok_in(self.0.path(), args);
    }

    fn fails(&self, args: &[&str], outputs: &[&str], needles: &[&str]) {
        let out = self.run(args);
        let outputs: Vec<PathBuf> = outputs.iter().map(|o| self.path(o)).collect();
        let outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
        assert_clean_failure(&out, self.0.path(), &outputs, needles);
    }
}

/// Shape, C order, and values of a `.npy` written by the CLI.
fn read_npy<T: npyz::Deserialize>(path: &Path) -> (Vec<u64>, Vec<T>) {
    let npy = npyz::NpyFile::new(std::fs::File::open(path).unwrap()).unwrap();
    assert_eq!(npy.order(), npyz::Order::C);
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec().unwrap())
}

fn bools(rows: &[&[u8]]) -> Vec<bool> {
    rows.iter().flat_map(|r| r.iter().map(|&v| v == 1)).collect()
}

// ---------------------------------------------------------------------------------------
// similarity
// ---------------------------------------------------------------------------------------

/// db rows (3, 4) and (1, 0) as float32; query rows (4, 3), (0, 2), (-1, 0) as float64.
fn descriptors(dir: &Dir) {
    npy_f32(&dir.path("db.npy"), &[&[3.0, 4.0], &[1.0, 0.0]]);
    npy_f64(&dir.path("q.npy"), &[&[4.0, 3.0], &[0.0, 2.0], &[-1.0, 0.0]]);
}

#[test]
fn similarity_hand_computed() {
    let dir = Dir::new();
    descriptors(&dir);
    dir.ok(&[
        "similarity",
        "--db",
        "db.npy",
        "--queries",
        "q.npy",
        "--output",
        "s.npy",
    ]);
    // |(3,4)| = 5: with (4,3) 24/25, with (0,2) 8/10, with (-1,0) -3/5;
    // (1,0): 4/5, 0, -1.
    let (shape, s) = read_npy::<f32>(&dir.path("s.npy"));
    assert_eq!(shape, [2, 3]);
    let want = [0.96, 0.8, -0.6, 0.8, 0.0, -1.0];
    for (got, want) in s.iter().zip(want) {
        assert!((f64::from(*got) - want).abs() < 1e-7, "{s:?}");
    }
}

#[test]
fn similarity_with_sequences() {
    let dir = Dir::new();
    // 1-D descriptors: the cosine is the product of signs.
    // db signs (+, -, +), query signs (+, +, -):
    // S = [[ 1,  1, -1],
    //      [-1, -1,  1],
    //      [ 1,  1, -1]]
    npy_f32(&dir.path("db.npy"), &[&[2.0], &[-1.0], &[0.5]]);
    npy_f32(&dir.path("q.npy"), &[&[1.0], &[3.0], &[-2.0]]);
    dir.ok(&[
        "similarity",
        "--db",
        "db.npy",
        "--queries",
        "q.npy",
        "--sequence",
        "3",
        "-o",
        "c.npy",
    ]);
    // Centred, d in -1..=1, over entries inside:
    // (0,0): S00 + S11 = 1 - 1 = 0 / 2 = 0      (0,1): S01 + S12 = 1 + 1 = 2 / 2 = 1
    // (0,2): S02 = -1                           (1,0): S10 + S21 = -1 + 1 = 0 / 2 = 0
    // (1,1): S00 + S11 + S22 = 1 - 1 - 1 = -1/3 (1,2): S01 + S12 = 2 / 2 = 1
    // (2,0): S20 = 1                            (2,1): S10 + S21 = 0
    // (2,2): S11 + S22 = -2 / 2 = -1
    let (_, c) = read_npy::<f32>(&dir.path("c.npy"));
    assert_eq!(c, [0.0, 1.0, -1.0, 0.0, -1.0 / 3.0, 1.0, 1.0, 0.0, -1.0]);
    dir.ok(&[
        "similarity",
        "--db",
        "db.npy",
        "--queries",
        "q.npy",
        "--sequence",
        "3",
        "--causal",
        "-o",
        "k.npy",
    ]);
    // Causal, d in -2..=0: row 0 and column 0 are S itself;
    // (1,1): S00 + S11 = 0;  (1,2): S01 + S12 = 2 / 2 = 1;  (2,1): S10 + S21 = 0;
    // (2,2): S00 + S11 + S22 = -1/3.
    let (_, k) = read_npy::<f32>(&dir.path("k.npy"));
    assert_eq!(k, [1.0, 1.0, -1.0, -1.0, 0.0, 1.0, 1.0, 0.0, -1.0 / 3.0]);
}

#[test]
fn similarity_bad_parameters() {
    let dir = Dir::new();
    descriptors(&dir);
    let base = ["similarity", "--db", "db.npy", "--queries", "q.npy", "-o", "s.npy"];
    for l in ["0", "2", "10", "-1", "-3"] {
        let args: Vec<&str> = base.iter().copied().chain(["--sequence", l]).collect();
        dir.fails(
            &args,
            &["s.npy"],
            &["--sequence", &format!("sequence length must be odd and >= 1, got {l}")],
        );
    }
    // --causal alone is a usage error (clap's own message, also exit 2).
    let args: Vec<&str> = base.iter().copied().chain(["--causal"]).collect();
    assert_eq!(dir.run(&args).status.code(), Some(2));
    assert!(!dir.path("s.npy").exists());
}

#[test]
fn similarity_bad_descriptors() {
    let dir = Dir::new();
    descriptors(&dir);
    let fails = |db: &str, q: &str, needles: &[&str]| {
        dir.fails(
            &["similarity", "--db", db, "--queries", q, "-o", "s.npy"],
            &["s.npy"],
            needles,
        );
    };
    npy_f64(&dir.path("q3.npy"), &[&[1.0, 2.0, 3.0]]);
    fails(
        "db.npy",
        "q3.npy",
        &[
            "--queries q3.npy / --db db.npy",
            "query descriptor matrix has 3 columns but database descriptor matrix has 2",
        ],
    );
    npy_f32(&dir.path("nan.npy"), &[&[1.0, 2.0], &[3.0, f32::NAN]]);
    fails(
        "nan.npy",
        "q.npy",
        &[
            "--db nan.npy",
            "database descriptor matrix contains NaN at row 1, column 1",
        ],
    );
    npy_f64(&dir.path("inf.npy"), &[&[1.0, f64::INFINITY]]);
    fails(
        "db.npy",
        "inf.npy",
        &["--queries inf.npy", "contains inf at row 0, column 1"],
    );
    npy_f64(&dir.path("zero.npy"), &[&[1.0, 2.0], &[0.0, 0.0], &[0.0, 0.0]]);
    fails(
        "db.npy",
        "zero.npy",
        &["--queries zero.npy", "query descriptor matrix row 1 is all zeros"],
    );
    npy_raw(&dir.path("empty.npy"), "<f4", false, &[0, 2], &[]);
    fails(
        "empty.npy",
        "q.npy",
        &["--db empty.npy", "database descriptor matrix is empty (shape 0x2)"],
    );
    npy_raw(&dir.path("nodim.npy"), "<f4", false, &[2, 0], &[]);
    fails("db.npy", "nodim.npy", &["--queries nodim.npy", "is empty (shape 2x0)"]);
    npy_raw(&dir.path("one_d.npy"), "<f8", false, &[2], &f64s(&[1.0, 2.0]));
    fails(
        "one_d.npy",
        "q.npy",
        &[
            "--db",
            "one_d.npy holds a 1-D array",
            "expected an N x D descriptor matrix",
        ],
    );
    npy_raw(&dir.path("three_d.npy"), "<f8", false, &[1, 1, 2], &f64s(&[1.0, 2.0]));
    fails("db.npy", "three_d.npy", &["--queries", "three_d.npy holds a 3-D array"]);
    for (descr, size) in [("<i8", 8), ("|u1", 1), ("<c8", 8), ("<f2", 2), ("|b1", 1)] {
        npy_raw(&dir.path("dtype.npy"), descr, false, &[2, 2], &vec![0u8; 4 * size]);
        fails(
            "dtype.npy",
            "q.npy",
            &[
                "--db",
                &format!("dtype.npy has dtype {descr}; descriptors must be float32 or float64"),
            ],
        );
    }
    std::fs::write(dir.path("text.npy"), "not a .npy").unwrap();
    fails(
        "db.npy",
        "text.npy",
        &["--queries", "text.npy is not a valid .npy file"],
    );
    fails("missing.npy", "q.npy", &["--db", "cannot read missing.npy"]);
    let good = std::fs::read(dir.path("db.npy")).unwrap();
    std::fs::write(dir.path("short.npy"), &good[..good.len() - 3]).unwrap();
    fails("short.npy", "q.npy", &["--db", "short.npy is truncated"]);
}

#[test]
fn similarity_output_errors_leave_nothing() {
    let dir = Dir::new();
    descriptors(&dir);
    dir.fails(
        &[
            "similarity",
            "--db",
            "db.npy",
            "--queries",
            "q.npy",
            "-o",
            "no/such/dir/s.npy",
        ],
        &[],
        &["--output: cannot write no/such/dir/s.npy"],
    );
}

// ---------------------------------------------------------------------------------------
// ground-truth
// ---------------------------------------------------------------------------------------

#[test]
fn ground_truth_by_tolerance() {
    let dir = Dir::new();
    npy_raw(&dir.path("s.npy"), "<f4", false, &[4, 3], &[0u8; 48]);
    dir.ok(&["ground-truth", "--tolerance", "1", "--like", "s.npy", "-o", "gt.npy"]);
    // 4 x 3, |i - j| <= 1.
    let want = bools(&[&[1, 1, 0], &[1, 1, 1], &[0, 1, 1], &[0, 0, 1]]);
    let (shape, gt) = read_npy::<bool>(&dir.path("gt.npy"));
    assert_eq!((shape, gt), (vec![4, 3], want.clone()));
    // The same from counts, with a soft tolerance 2 into a second .npy:
    // |i - j| <= 2 is all but (3, 0).
    dir.ok(&[
        "ground-truth",
        "--tolerance",
        "1",
        "--soft-tolerance",
        "2",
        "--db-count",
        "4",
        "--query-count",
        "3",
        "-o",
        "gt2.npy",
        "--soft-output",
        "soft2.npy",
    ]);
    assert_eq!(read_npy::<bool>(&dir.path("gt2.npy")).1, want);
    let soft = bools(&[&[1, 1, 1], &[1, 1, 1], &[1, 1, 1], &[0, 1, 1]]);
    assert_eq!(read_npy::<bool>(&dir.path("soft2.npy")).1, soft);
    // And as a VPR_Tutorial .npz, which threshold's --cal-gt reads.
    dir.ok(&[
        "ground-truth",
        "--tolerance",
        "1",
        "--soft-tolerance",
        "2",
        "--db-count",
        "4",
        "--query-count",
        "3",
        "-o",
        "gt.npz",
    ]);
    let hard = crate::common::npz_bools(&dir.path("gt.npz"), "GThard");
    let gt_soft = crate::common::npz_bools(&dir.path("gt.npz"), "GTsoft");
    assert_eq!((hard, gt_soft), (want, soft));
}

#[test]
fn ground_truth_by_positions_is_inclusive() {
    let dir = Dir::new();
    // Queries at (0, 0) and (10, 0), radius 5, soft radius 8.
    // db (3, 4): 5 (hard) and sqrt(65) = 8.06 (neither);
    // db (7, 0): 7 (soft) and 3 (hard); db (10, -5): sqrt(125) = 11.2 and 5 (hard).
    npy_f64(&dir.path("qp.npy"), &[&[0.0, 0.0], &[10.0, 0.0]]);
    npy_f32(&dir.path("dbp.npy"), &[&[3.0, 4.0], &[7.0, 0.0], &[10.0, -5.0]]);
    dir.ok(&[
        "ground-truth",
        "--db-positions",
        "dbp.npy",
        "--query-positions",
        "qp.npy",
        "--radius",
        "5",
        "--soft-radius",
        "8",
        "-o",
        "gt.npz",
    ]);
    let hard = crate::common::npz_bools(&dir.path("gt.npz"), "GThard");
    let soft = crate::common::npz_bools(&dir.path("gt.npz"), "GTsoft");
    assert_eq!(hard, bools(&[&[1, 0], &[0, 1], &[0, 1]]));
    assert_eq!(soft, bools(&[&[1, 0], &[1, 1], &[0, 1]]));
}

#[test]
fn ground_truth_bad_input() {
    let dir = Dir::new();
    npy_f64(&dir.path("p.npy"), &[&[0.0, 0.0], &[1.0, 1.0]]);
    let pos = |db: &str, q: &str, extra: &[&str], needles: &[&str]| {
        let mut args = vec![
            "ground-truth",
            "--db-positions",
            db,
            "--query-positions",
            q,
            "-o",
            "gt.npy",
        ];
        args.extend(extra);
        if !extra.contains(&"--radius") {
            args.extend(["--radius", "1"]);
        }
        dir.fails(&args, &["gt.npy"], needles);
    };
    for r in ["-1", "NaN", "inf"] {
        pos(
            "p.npy",
            "p.npy",
            &["--radius", r],
            &["--radius", "radius must be a finite number >= 0"],
        );
    }
    pos(
        "p.npy",
        "p.npy",
        &["--soft-radius", "-2", "--soft-output", "s.npy"],
        &["--soft-radius", "soft radius must be a finite number >= 0, got -2"],
    );
    pos(
        "p.npy",
        "p.npy",
        &["--soft-radius", "0.5", "--soft-output", "s.npy"],
        &["--soft-radius 0.5 is smaller than --radius 1"],
    );
    npy_f64(&dir.path("p4.npy"), &[&[0.0, 0.0, 0.0, 0.0]]);
    pos(
        "p4.npy",
        "p.npy",
        &[],
        &[
            "--db-positions p4.npy",
            "database position matrix has 4 columns; positions must be",
        ],
    );
    npy_f64(&dir.path("p3.npy"), &[&[0.0, 0.0, 0.0]]);
    pos(
        "p.npy",
        "p3.npy",
        &[],
        &[
            "--query-positions p3.npy / --db-positions p.npy",
            "query position matrix has 3 columns but database position matrix has 2",
        ],
    );
    npy_f32(&dir.path("nan.npy"), &[&[0.0, f32::NAN]]);
    pos(
        "p.npy",
        "nan.npy",
        &[],
        &["--query-positions nan.npy", "contains NaN at row 0, column 1"],
    );
    npy_raw(&dir.path("one_d.npy"), "<f8", false, &[2], &f64s(&[1.0, 2.0]));
    pos(
        "one_d.npy",
        "p.npy",
        &[],
        &["--db-positions", "one_d.npy holds a 1-D array", "position matrix"],
    );
    npy_raw(&dir.path("int.npy"), "<i8", false, &[1, 2], &[0u8; 16]);
    pos(
        "p.npy",
        "int.npy",
        &[],
        &[
            "--query-positions",
            "int.npy has dtype <i8; positions must be float32 or float64",
        ],
    );

    let tol = |extra: &[&str], outputs: &[&str], needles: &[&str]| {
        let mut args = vec!["ground-truth", "--tolerance"];
        args.extend(extra);
        dir.fails(&args, outputs, needles);
    };
    tol(
        &["1", "-o", "gt.npy"],
        &["gt.npy"],
        &["--tolerance needs the shape |DB| x |Q|"],
    );
    tol(
        &["-1", "--db-count", "2", "--query-count", "2", "-o", "gt.npy"],
        &["gt.npy"],
        &["--tolerance must be >= 0, got -1"],
    );
    tol(
        &[
            "1",
            "--soft-tolerance",
            "0",
            "--db-count",
            "2",
            "--query-count",
            "2",
            "-o",
            "gt.npz",
        ],
        &["gt.npz"],
        &["--soft-tolerance 0 is smaller than --tolerance 1"],
    );
    tol(
        &[
            "1",
            "--soft-tolerance",
            "2",
            "--db-count",
            "2",
            "--query-count",
            "2",
            "-o",
            "gt.npy",
        ],
        &["gt.npy"],
        &["a soft ground truth needs --soft-output"],
    );
    tol(
        &[
            "1",
            "--db-count",
            "2",
            "--query-count",
            "2",
            "-o",
            "gt.npz",
            "--soft-output",
            "s.npy",
        ],
        &["gt.npz", "s.npy"],
        &["--soft-output is for a .npy --output"],
    );
    tol(
        &["1", "--db-count", "0", "--query-count", "2", "-o", "gt.npy"],
        &["gt.npy"],
        &["ground truth is empty (shape 0x2)"],
    );
    tol(
        &["1", "--like", "missing.npy", "-o", "gt.npy"],
        &["gt.npy"],
        &["--like missing.npy", "cannot read missing.npy"],
    );
    npy_raw(&dir.path("s3.npy"), "<f4", false, &[1, 1, 1], &[0u8; 4]);
    tol(
        &["1", "--like", "s3.npy", "-o", "gt.npy"],
        &["gt.npy"],
        &["s3.npy holds a 3-D array"],
    );
    // Both sources, or none: clap usage errors, exit 2.
    for args in [
        &["ground-truth", "-o", "gt.npy"][..],
        &[
            "ground-truth",
            "--tolerance",
            "1",
            "--db-positions",
            "p.npy",
            "--query-positions",
            "p.npy",
            "--radius",
            "1",
            "-o",
            "gt.npy",
        ],
    ] {
        assert_eq!(dir.run(args).status.code(), Some(2));
        assert!(!dir.path("gt.npy").exists());
    }
}

// ---------------------------------------------------------------------------------------
// threshold with ground truth from a tolerance or from positions
// ---------------------------------------------------------------------------------------

/// The calibration and deployment matrices of `cli.rs`, and the ground truth
/// `|i - j| <= 0` of the 3 x 2 calibration matrix as a file.
fn threshold_case(dir: &Dir) {
    npy_f64(&dir.path("cal.npy"), &[&[3.0, 1.0], &[1.0, 4.0], &[2.0, 1.0]]);
    npy_f64(&dir.path("val.npy"), &[&[2.0, 2.0], &[6.0, 5.0], &[4.0, 2.0]]);
    npy_bool(&dir.path("gt.npy"), &[&[1, 0], &[0, 1], &[0, 0]]);
    npy_bool(&dir.path("soft.npy"), &[&[1, 1], &[1, 1], &[0, 1]]);
    // Positions on a line, 10 apart; the queries at the first two database positions.
    npy_f64(&dir.path("dbp.npy"), &[&[0.0, 0.0], &[10.0, 0.0], &[20.0, 0.0]]);
    npy_f64(&dir.path("qp.npy"), &[&[0.0, 0.0], &[10.0, 0.0]]);
}

fn threshold(dir: &Dir, gt: &[&str], out: &str) -> Output {
    let mut args = vec![
        "threshold",
        "--cal",
        "cal.npy",
        "--val",
        "val.npy",
        "--k",
        "1",
        "--format",
        "csv",
    ];
    args.extend(gt);
    args.extend(["-o", out]);
    dir.run(&args)
}

#[test]
fn threshold_ground_truth_sources_agree() {
    let dir = Dir::new();
    threshold_case(&dir);
    let read = |name: &str| std::fs::read_to_string(dir.path(name)).unwrap();
    for (file, generated) in [
        (&["--cal-gt", "gt.npy"][..], &["--cal-gt-tolerance", "0"][..]),
        (
            &["--cal-gt", "gt.npy"][..],
            &[
                "--cal-gt-db-positions",
                "dbp.npy",
                "--cal-gt-query-positions",
                "qp.npy",
                "--cal-gt-radius",
                "9.5",
            ][..],
        ),
        (
            &["--cal-gt", "gt.npy", "--cal-gt-soft", "soft.npy"][..],
            &["--cal-gt-tolerance", "0", "--cal-gt-soft-tolerance", "1"][..],
        ),
        (
            &["--cal-gt", "gt.npy", "--cal-gt-soft", "soft.npy"][..],
            &[
                "--cal-gt-db-positions",
                "dbp.npy",
                "--cal-gt-query-positions",
                "qp.npy",
                "--cal-gt-radius",
                "0",
                "--cal-gt-soft-radius",
                "10",
            ][..],
        ),
    ] {
        for matching in ["single", "multi"] {
            let a = threshold(&dir, &[file, &["--matching", matching]].concat(), "a.csv");
            let b = threshold(&dir, &[generated, &["--matching", matching]].concat(), "b.csv");
            assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
            assert!(
                b.status.success(),
                "{generated:?}: {}",
                String::from_utf8_lossy(&b.stderr)
            );
            assert_eq!(read("a.csv"), read("b.csv"), "{generated:?}");
        }
    }
}

#[test]
fn threshold_ground_truth_source_errors() {
    let dir = Dir::new();
    threshold_case(&dir);
    let fails = |gt: &[&str], needles: &[&str]| {
        let out = threshold(&dir, gt, "t.csv");
        assert_clean_failure(&out, dir.0.path(), &[&dir.path("t.csv")], needles);
    };
    fails(
        &["--cal-gt-tolerance", "-1"],
        &["--cal-gt-tolerance must be >= 0, got -1"],
    );
    fails(
        &["--cal-gt-tolerance", "1", "--cal-gt-soft-tolerance", "0"],
        &["--cal-gt-soft-tolerance 0 is smaller than --cal-gt-tolerance 1"],
    );
    let positions = [
        "--cal-gt-db-positions",
        "dbp.npy",
        "--cal-gt-query-positions",
        "dbp.npy",
    ];
    fails(
        &[&positions[..], &["--cal-gt-radius", "1"]].concat(),
        &["3 database and 3 query positions, but the similarity matrix has shape 3x2"],
    );
    let positions = ["--cal-gt-db-positions", "dbp.npy", "--cal-gt-query-positions", "qp.npy"];
    fails(
        &[&positions[..], &["--cal-gt-radius", "-1"]].concat(),
        &["--cal-gt-radius", "radius must be a finite number >= 0, got -1"],
    );
    npy_f64(&dir.path("qnan.npy"), &[&[0.0, 0.0], &[f64::NAN, 0.0]]);
    fails(
        &[
            "--cal-gt-db-positions",
            "dbp.npy",
            "--cal-gt-query-positions",
            "qnan.npy",
            "--cal-gt-radius",
            "1",
        ],
        &["--cal-gt-query-positions qnan.npy", "contains NaN at row 1, column 0"],
    );
    // Exactly one source: none, or two, are usage errors (exit 2).
    for gt in [&[][..], &["--cal-gt", "gt.npy", "--cal-gt-tolerance", "0"][..]] {
        assert_eq!(threshold(&dir, gt, "t.csv").status.code(), Some(2));
        assert!(!dir.path("t.csv").exists());
    }
}
