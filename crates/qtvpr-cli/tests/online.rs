//! End-to-end tests of `calibrate`, `stream` and `threshold --cal cal.npz` on real
//! VPR-Bench matrices (`../shared/data`): the stream equals `qtvpr::Online` bit for bit
//! in both matching modes, with query-major input, soft ground truth and a warm-up; a
//! calibration file gives the same thresholds as the matrices it was made from; every
//! bad calibration file exits 2 with one line naming it; written files get the mode of a
//! plain create.

use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::Arc;

use ndarray::{Array2, ArrayView2, s};
use qtvpr::ScoresView;
use qtvpr::npy::{NpyArray, read_scores, write_npy, write_npz};
use qtvpr::{Calibration, Decision, Defaults, GroundTruth, Matching, Online, OnlineParams, Score};
use tempfile::TempDir;

use crate::common::{assert_clean_failure, ok_in, run_in};
use qtvpr_testkit::data;

/// Corridor (111 x 111) of one technique: calibration = the first 11 queries.
struct Case {
    dir: TempDir,
    s: Array2<f64>,
    gt: Array2<bool>,
    f32: bool,
}

const N_CAL: usize = 11;

impl Case {
    /// `None` without `../shared/data`.
    fn new(technique: &str) -> Option<Self> {
        let (s_path, gt_path) = (
            data::shared(&format!("vprbench-corridor/S_{technique}.npy"))?,
            data::shared("vprbench-corridor/GT.npy")?,
        );
        let scores = read_scores(&s_path).unwrap();
        let (s, f32) = match scores.view() {
            ScoresView::F32(v) => (v.mapv(f64::from), true),
            ScoresView::F64(v) => (v.to_owned(), false),
        };
        let gt = qtvpr::npy::read_hard_ground_truth(&gt_path).unwrap();
        let gt = gt.view().mapv(|t| t == qtvpr::Truth::True);
        let case = Self {
            dir: tempfile::tempdir().unwrap(),
            s,
            gt,
            f32,
        };
        // DB x Q and query-major copies of the calibration and deployment halves, in the
        // technique's own dtype.
        for (name, cols) in [("cal", 0..N_CAL), ("val", N_CAL..111)] {
            let part = case.s.slice(s![.., cols.clone()]);
            case.write_scores(&format!("{name}.npy"), part);
            case.write_scores(&format!("{name}_qm.npy"), part.t());
            let gt = case.gt.slice(s![.., cols]);
            write_npy(&case.path(&format!("{name}_gt.npy")), gt).unwrap();
            write_npy(&case.path(&format!("{name}_gt_qm.npy")), gt.t()).unwrap();
        }
        Some(case)
    }

    fn write_scores(&self, name: &str, m: ArrayView2<'_, f64>) {
        if self.f32 {
            write_npy(&self.path(name), m.mapv(|v| v as f32).view()).unwrap();
        } else {
            write_npy(&self.path(name), m).unwrap();
        }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn run(&self, args: &[&str]) -> Output {
        run_in(self.dir.path(), args)
    }

    fn ok(&self, args: &[&str]) -> String {
        ok_in(self.dir.path(), args)
    }

    fn fails(&self, args: &[&str], outputs: &[&str], needles: &[&str]) {
        let outputs: Vec<PathBuf> = outputs.iter().map(|o| self.path(o)).collect();
        let refs: Vec<&Path> = outputs.iter().map(|p| p.as_path()).collect();
        assert_clean_failure(&self.run(args), self.dir.path(), &refs, needles);
    }

    /// The decisions `qtvpr::Online` makes on the deployment half, from a calibration
    /// built in this process (not from the file).
    fn expected(&self, matching: Matching, soft: Option<&Array2<bool>>, p: OnlineParams) -> Vec<Decision> {
        self.expected_matched(matching, soft, p, 1)
    }

    /// [`Case::expected`] on a calibration of sequence length `length` (semantics §15).
    fn expected_matched(
        &self,
        matching: Matching,
        soft: Option<&Array2<bool>>,
        p: OnlineParams,
        length: usize,
    ) -> Vec<Decision> {
        let mut gt = GroundTruth::new(self.gt.slice(s![.., ..N_CAL])).unwrap();
        if let Some(soft) = soft {
            gt = gt.with_soft(soft.slice(s![.., ..N_CAL])).unwrap();
        }
        let (cal, val) = (self.s.slice(s![.., ..N_CAL]), self.s.slice(s![.., N_CAL..]));
        fn go<T: Score>(
            cal: ArrayView2<'_, T>,
            val: ArrayView2<'_, T>,
            gt: &GroundTruth,
            m: Matching,
            p: OnlineParams,
            length: usize,
        ) -> Vec<Decision> {
            let cal = Arc::new(Calibration::new_sequence(cal, gt, m, length).unwrap());
            Online::new(cal, p).unwrap().push_many(val).unwrap()
        }
        if self.f32 {
            let (c, v) = (cal.mapv(|x| x as f32), val.mapv(|x| x as f32));
            go(c.view(), v.view(), &gt, matching, p, length)
        } else {
            go(cal, val, &gt, matching, p, length)
        }
    }
}

/// Parse `stream --format csv` and compare every field with `expected`, bit for bit:
/// the eleven fields of the decision record in both matching modes (a confidence of
/// multi matching is NaN).
fn assert_csv_equals(csv: &str, expected: &[Decision]) {
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("query,query_quantile,weight,quantile,threshold,best,score,accepted,accept,confidence,confidence_lower95")
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), expected.len());
    let f = |x: &str| x.parse::<f64>().unwrap().to_bits();
    for (row, d) in rows.iter().zip(expected) {
        let v: Vec<&str> = row.split(',').collect();
        assert_eq!(v[0].parse::<usize>().unwrap(), d.query);
        let got = (f(v[1]), f(v[2]), f(v[3]), f(v[4]));
        let want = (
            d.query_quantile.to_bits(),
            d.weight.to_bits(),
            d.quantile.to_bits(),
            d.threshold.to_bits(),
        );
        assert_eq!(got, want, "query {}: {row}", d.query);
        assert_eq!(
            (
                v[5].parse::<usize>().unwrap(),
                f(v[6]),
                v[7].parse::<usize>().unwrap(),
                v[8]
            ),
            (d.best, d.score.to_bits(), d.accepted, &*d.accept().to_string()),
            "query {}: {row}",
            d.query
        );
        assert_eq!(
            (f(v[9]), f(v[10])),
            (d.confidence.to_bits(), d.confidence_lower95.to_bits()),
            "query {}: {row}",
            d.query
        );
    }
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (NetVLAD): `stream` = qtvpr::Online, bit for bit"]
fn single_matching_stream_equals_online() {
    let Some(case) = Case::new("NetVLAD") else {
        return;
    };
    case.ok(&[
        "calibrate",
        "--cal",
        "cal.npy",
        "--cal-gt",
        "cal_gt.npy",
        "--window",
        "5",
        "-o",
        "cal.npz",
    ]);
    let p = OnlineParams {
        k: 10,
        precision: 1.0,
        window: 5,
        min_window: 1,
        gate: qtvpr::Gate::None,
        sequence_gate: Default::default(),
    };
    let expected = case.expected(Matching::Single, None, p);
    // The window comes from the file.
    let csv = case.ok(&[
        "stream",
        "--calibration",
        "cal.npz",
        "--val",
        "val.npy",
        "--format",
        "csv",
    ]);
    assert_csv_equals(&csv, &expected);
    // Some are accepted, some not (the test can tell a wrong threshold).
    assert!(expected.iter().any(Decision::accept));
    assert!(!expected.iter().all(Decision::accept));
    assert!(expected.iter().all(|d| d.accepted <= 1));

    // JSON lines carry the same values.
    let jsonl = case.ok(&["stream", "--calibration", "cal.npz", "--val", "val.npy"]);
    let lines: Vec<serde_json::Value> = jsonl.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 100);
    for (l, d) in lines.iter().zip(&expected) {
        assert_eq!(l["query"], d.query);
        assert_eq!(
            (l["accept"].as_bool(), l["best"].as_u64(), l["accepted"].as_u64()),
            (Some(d.accept()), Some(d.best as u64), Some(d.accepted as u64))
        );
        for (key, want) in [("threshold", d.threshold), ("quantile", d.quantile), ("score", d.score)] {
            assert!(
                (l[key].as_f64().unwrap() - want).abs() <= 1e-15 * want.abs(),
                "{key}: {l}"
            );
        }
        // The confidence, a probability in single matching.
        assert_eq!(l["confidence"].as_f64(), Some(d.confidence));
        assert!((0.0..=1.0).contains(&d.confidence), "{l}");
        let lower = l["confidence_lower95"].as_f64().unwrap();
        assert!((lower - d.confidence_lower95).abs() <= 1e-15, "{l}");
        assert_eq!(l.as_object().unwrap().len(), 11, "the eleven fields of the record: {l}");
    }

    // Options override the file: k, precision, window, min-window.
    let p = OnlineParams {
        k: 3,
        precision: 0.9,
        window: 8,
        min_window: 4,
        gate: qtvpr::Gate::None,
        sequence_gate: Default::default(),
    };
    let csv = case.ok(&[
        "stream",
        "--calibration",
        "cal.npz",
        "--val",
        "val.npy",
        "--format",
        "csv",
        "--k",
        "3",
        "--precision",
        "0.9",
        "--window",
        "8",
        "--min-window",
        "4",
    ]);
    let expected = case.expected(Matching::Single, None, p);
    assert_csv_equals(&csv, &expected);
    assert!(expected[..3].iter().all(|d| d.quantile == 1.0 && !d.accept()));
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (CoHOG, f32): `stream` in multi matching, query-major"]
fn multi_matching_query_major_soft_ground_truth() {
    // float32 scores, stored query-major; soft ground truth |i - j| <= 3 around the hard
    // |i - j| <= 2 (by tolerance, from the calibration's own columns 0..11).
    let Some(case) = Case::new("CoHOG") else {
        return;
    };
    assert!(case.f32);
    case.ok(&[
        "calibrate",
        "--cal",
        "cal_qm.npy",
        "--cal-gt-tolerance",
        "2",
        "--cal-gt-soft-tolerance",
        "3",
        "--matching",
        "multi",
        "--k",
        "4",
        "--precision",
        "0.9",
        "--window",
        "6",
        "--query-major",
        "-o",
        "cal.npz",
    ]);
    let hard = Array2::from_shape_fn((111, 111), |(i, j)| i.abs_diff(j) <= 2);
    let soft = Array2::from_shape_fn((111, 111), |(i, j)| i.abs_diff(j) <= 3);
    let case = Case { gt: hard, ..case };
    let p = OnlineParams {
        k: 4,
        precision: 0.9,
        window: 6,
        min_window: 3,
        gate: qtvpr::Gate::None,
        sequence_gate: Default::default(),
    };
    let expected = case.expected(Matching::Multi, Some(&soft), p);
    let csv = case.ok(&[
        "stream",
        "--calibration",
        "cal.npz",
        "--val",
        "val_qm.npy",
        "--query-major",
        "--format",
        "csv",
        "--min-window",
        "3",
        "-o",
        "out.csv",
    ]);
    assert!(csv.is_empty());
    let csv = std::fs::read_to_string(case.path("out.csv")).unwrap();
    assert_csv_equals(&csv, &expected);
    assert!(expected.iter().any(|d| d.accepted > 1));
    // The file holds |DB| x |Qcal| and the soft ground truth.
    let cal = Calibration::load(&case.path("cal.npz")).unwrap();
    assert_eq!(
        (cal.db_size(), cal.len(), cal.matching()),
        (111, N_CAL, Matching::Multi)
    );
    assert!(
        cal.ground_truth()
            .expect("kept")
            .view()
            .iter()
            .any(|&t| t == qtvpr::Truth::Ignored)
    );
    let lines = case.ok(&[
        "stream",
        "--calibration",
        "cal.npz",
        "--val",
        "val_qm.npy",
        "--query-major",
        "--min-window",
        "3",
    ]);
    let first: serde_json::Value = serde_json::from_str(lines.lines().next().unwrap()).unwrap();
    assert_eq!(
        (&first["accepted"], &first["accept"]),
        (&0.into(), &false.into()),
        "warm-up"
    );
    // Multi matching reports the column's best match too (the record is one).
    assert_eq!(
        (first["best"].as_u64(), first["score"].as_f64()),
        (Some(expected[0].best as u64), Some(expected[0].score))
    );
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (NetVLAD): `threshold --cal FILE` = the matrices' thresholds"]
fn threshold_takes_a_calibration_file() {
    let Some(case) = Case::new("NetVLAD") else {
        return;
    };
    let matrices = [
        "threshold",
        "--cal",
        "cal.npy",
        "--cal-gt",
        "cal_gt.npy",
        "--val",
        "val.npy",
        "--segment-size",
        "20",
    ];
    let file = [
        "threshold",
        "--cal",
        "cal.npz",
        "--val",
        "val.npy",
        "--segment-size",
        "20",
    ];
    for (matching, k, precision) in [("single", "10", "1.0"), ("multi", "3", "0.9")] {
        case.ok(&[
            "calibrate",
            "--cal",
            "cal.npy",
            "--cal-gt",
            "cal_gt.npy",
            "--matching",
            matching,
            "--k",
            k,
            "--precision",
            precision,
            "-o",
            "cal.npz",
        ]);
        let params = ["--matching", matching, "--k", k, "--precision", precision];
        let want = case.ok(&[&matrices[..], &params].concat());
        // The file's k, precision and matching are the defaults; giving them again is the
        // same. But for the orientation's evidence: a calibration file does not say where
        // its ground truth came from (made for the matrix as read, it says nothing).
        let without_evidence = |out: &str| {
            let mut json: serde_json::Value = serde_json::from_str(out).unwrap();
            // The layout's wording says whether that evidence confirmed it.
            let orientation = json["orientation"].as_object_mut().unwrap();
            orientation.remove("evidence");
            orientation.remove("layout");
            json
        };
        let json = without_evidence(&want);
        assert_eq!(without_evidence(&case.ok(&file)), json);
        assert_eq!(without_evidence(&case.ok(&[&file[..], &params].concat())), json);
        assert_eq!(
            serde_json::from_str::<serde_json::Value>(&want).unwrap()["orientation"]["evidence"]["verdict"],
            "consistent"
        );
        assert_eq!(json["params"]["matching"], matching);
        assert_eq!(json["segments"].as_array().unwrap().len(), 5);
    }
    // A calibration file told apart by its content, whatever its name.
    std::fs::copy(case.path("cal.npz"), case.path("cal_file.npy")).unwrap();
    let want = case.ok(&file);
    assert_eq!(
        case.ok(&[
            "threshold",
            "--cal",
            "cal_file.npy",
            "--val",
            "val.npy",
            "--segment-size",
            "20"
        ]),
        want
    );
    // A zip with bytes prepended (a self-extracting archive, say): `stream` loads it
    // (the zip reader finds the archive from its end), and so does `threshold`, which
    // used to call it "a similarity matrix, which needs its ground truth".
    let mut prefixed = b"#!/bin/sh\nexit 0\n".to_vec();
    prefixed.extend(std::fs::read(case.path("cal.npz")).unwrap());
    std::fs::write(case.path("prefixed.npz"), prefixed).unwrap();
    assert_eq!(
        case.ok(&[
            "threshold",
            "--cal",
            "prefixed.npz",
            "--val",
            "val.npy",
            "--segment-size",
            "20"
        ]),
        want
    );
    // A .npy is still a matrix, and junk that is neither is read as a .npy (whose
    // message says what a .npy must start with).
    std::fs::write(case.path("junk.bin"), b"neither a zip nor a .npy").unwrap();
    case.fails(
        &[
            "threshold",
            "--cal",
            "junk.bin",
            "--cal-gt",
            "cal_gt.npy",
            "--val",
            "val.npy",
        ],
        &[],
        &["junk.bin is not a valid .npy file"],
    );
    // --cal-gt with a calibration file, a different --matching, no --cal-gt with a matrix.
    case.fails(
        &[&file[..], &["--cal-gt", "cal_gt.npy", "-o", "out.json"]].concat(),
        &["out.json"],
        &[
            "--cal cal.npz is a calibration file, which holds its own ground truth",
            "--cal-gt cal_gt.npy",
        ],
    );
    case.fails(
        &[&file[..], &["--matching", "single", "-o", "out.json"]].concat(),
        &["out.json"],
        &["--matching single: --cal cal.npz was calibrated for multi matching"],
    );
    case.fails(
        &["threshold", "--cal", "cal.npy", "--val", "val.npy", "-o", "out.json"],
        &["out.json"],
        &["--cal cal.npy is a similarity matrix, which needs its ground truth"],
    );
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (NetVLAD): the valid file its bad ones are made from"]
fn bad_calibration_files_name_the_file() {
    let Some(case) = Case::new("NetVLAD") else {
        return;
    };
    let stream = |cal: &str| -> Vec<String> {
        [
            "stream",
            "--calibration",
            cal,
            "--val",
            "val.npy",
            "--window",
            "3",
            "-o",
            "out.jsonl",
        ]
        .map(String::from)
        .to_vec()
    };
    let fails = |cal: &str, needle: &str| {
        let args = stream(cal);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        case.fails(&args, &["out.jsonl"], &["--calibration", cal, needle]);
        let args = ["threshold", "--cal", cal, "--val", "val.npy", "-o", "out.json"];
        if cal.ends_with(".npz") && cal != "missing.npz" {
            case.fails(&args, &["out.json"], &["--cal", cal, needle]);
        }
    };
    std::fs::write(case.path("junk.npz"), b"PK\x03\x04 not a zip at all").unwrap();
    fails("junk.npz", "is not a valid .npz archive");
    fails("missing.npz", "cannot read missing.npz");
    let s = array2(&[&[0.5, 0.1], &[0.2, 0.9]]);
    let gt = ndarray::array![[true, false], [false, true]];
    let meta = |version: u32| {
        format!(
            r#"{{"format": "qtvpr-calibration", "version": {version}, "matching": "single", "params": {{"k": 10, "precision": 1.0, "window": null}}, "qtvpr": "0"}}"#
        )
    };
    let (m1, m2) = (meta(1), meta(2));
    write_npz(
        &case.path("no_meta.npz"),
        &[("s", NpyArray::F64(s.view())), ("gt", NpyArray::Bool(gt.view()))],
    )
    .unwrap();
    fails("no_meta.npz", "has no array meta: it is not a qtvpr calibration file");
    write_npz(
        &case.path("v2.npz"),
        &[
            ("s", s.view().into()),
            ("gt", gt.view().into()),
            ("meta", m2.as_str().into()),
        ],
    )
    .unwrap();
    fails("v2.npz", "has calibration file version 2");
    let nan = array2(&[&[0.5, f64::NAN], &[0.2, 0.9]]);
    write_npz(
        &case.path("nan.npz"),
        &[
            ("s", nan.view().into()),
            ("gt", gt.view().into()),
            ("meta", m1.as_str().into()),
        ],
    )
    .unwrap();
    fails("nan.npz", "calibration similarity contains NaN at row 0, column 1");
    // A good file of another |DB|: the stream names the mismatch.
    write_npz(
        &case.path("small.npz"),
        &[
            ("s", s.view().into()),
            ("gt", gt.view().into()),
            ("meta", m1.as_str().into()),
        ],
    )
    .unwrap();
    let args = stream("small.npz");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    case.fails(
        &args,
        &["out.jsonl"],
        &[
            "--val val.npy",
            "deployment query 0 has 111 scores but the calibration has 2 database images",
        ],
    );
    // No window anywhere.
    write_npz(
        &case.path("ok.npz"),
        &[
            ("s", s.view().into()),
            ("gt", gt.view().into()),
            ("meta", m1.as_str().into()),
        ],
    )
    .unwrap();
    case.fails(
        &["stream", "--calibration", "ok.npz", "--val", "val.npy"],
        &[],
        &["window is not given and the calibration sets none"],
    );
    // A NaN in the deployment matrix names the query; nothing is written.
    case.ok(&[
        "calibrate",
        "--cal",
        "cal.npy",
        "--cal-gt",
        "cal_gt.npy",
        "--window",
        "5",
        "-o",
        "cal.npz",
    ]);
    // One flipped bit in a score: the member's CRC-32 fails, in stream and threshold.
    let mut bytes = std::fs::read(case.path("cal.npz")).unwrap();
    let s_data = bytes.windows(6).position(|w| w == b"\x93NUMPY").unwrap() + 200;
    bytes[s_data] ^= 0x01;
    std::fs::write(case.path("flipped.npz"), &bytes).unwrap();
    fails(
        "flipped.npz",
        "flipped.npz (array s) is corrupt: its CRC-32 does not match its data",
    );
    let mut val = case.s.slice(s![.., N_CAL..]).to_owned();
    val[[7, 42]] = f64::INFINITY;
    write_npy(&case.path("bad_val.npy"), val.view()).unwrap();
    case.fails(
        &[
            "stream",
            "--calibration",
            "cal.npz",
            "--val",
            "bad_val.npy",
            "-o",
            "out.jsonl",
        ],
        &["out.jsonl"],
        &["--val bad_val.npy", "contains inf at row 7, column 42"],
    );
    // calibrate's own bad input and parameters.
    case.fails(
        &["calibrate", "--cal", "cal.npy", "--cal-gt", "val_gt.npy", "-o", "c.npz"],
        &["c.npz"],
        &["ground truth shape 111x100 does not match calibration similarity shape 111x11"],
    );
    case.fails(
        &[
            "calibrate",
            "--cal",
            "cal.npy",
            "--cal-gt",
            "cal_gt.npy",
            "--window",
            "0",
            "-o",
            "c.npz",
        ],
        &["c.npz"],
        &["window must be >= 1, got 0"],
    );
}

fn array2(rows: &[&[f64]]) -> Array2<f64> {
    Array2::from_shape_fn((rows.len(), rows[0].len()), |(i, j)| rows[i][j])
}

#[cfg(unix)]
#[test]
#[ignore = "needs ../shared/data vprbench-corridor (NetVLAD): the inputs of the commands that write"]
fn written_files_get_the_mode_of_a_plain_create() {
    use std::os::unix::fs::PermissionsExt;
    let Some(case) = Case::new("NetVLAD") else {
        return;
    };
    std::fs::File::create(case.path("plain")).unwrap();
    let mode = |name: &str| std::fs::metadata(case.path(name)).unwrap().permissions().mode() & 0o777;
    case.ok(&[
        "calibrate",
        "--cal",
        "cal.npy",
        "--cal-gt",
        "cal_gt.npy",
        "-o",
        "cal.npz",
    ]);
    case.ok(&[
        "threshold",
        "--cal",
        "cal.npz",
        "--val",
        "val.npy",
        "--output",
        "t.json",
    ]);
    case.ok(&[
        "stream",
        "--calibration",
        "cal.npz",
        "--val",
        "val.npy",
        "--window",
        "4",
        "--output",
        "s.jsonl",
    ]);
    write_npy(&case.path("db.npy"), array2(&[&[3.0, 4.0], &[1.0, 0.0]]).view()).unwrap();
    case.ok(&[
        "similarity",
        "--db",
        "db.npy",
        "--queries",
        "db.npy",
        "--output",
        "sim.npy",
    ]);
    for name in ["cal.npz", "t.json", "s.jsonl", "sim.npy"] {
        assert_eq!(mode(name), mode("plain"), "{name}");
        assert_ne!(mode(name), 0o600, "{name} has a temporary file's mode");
    }
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (NetVLAD): `evaluate`'s online method = qtvpr::Online"]
fn evaluate_reports_the_online_method() {
    let Some(case) = Case::new("NetVLAD") else {
        return;
    };
    write_npy(&case.path("S.npy"), case.s.view()).unwrap();
    write_npy(&case.path("GT.npy"), case.gt.view()).unwrap();
    let base = [
        "evaluate",
        "--format",
        "json",
        "--similarity",
        "S.npy",
        "--gt",
        "GT.npy",
        "--segment-size",
        "5",
    ];
    let json = case.ok(&[&base[..], &["--method", "quantile-transfer-online"]].concat());
    let json: serde_json::Value = serde_json::from_str(&json).unwrap();
    let online = &json["methods"]["quantile-transfer-online"];
    // Against Online directly: 20 segments of 5 over the 100 deployment queries, each
    // reporting its last query's threshold.
    let p = OnlineParams {
        k: 10,
        precision: 1.0,
        window: 5,
        min_window: 1,
        gate: qtvpr::Gate::None,
        sequence_gate: Default::default(),
    };
    let expected = case.expected(Matching::Single, None, p);
    let segments = online["segments"].as_array().unwrap();
    assert_eq!(segments.len(), 20);
    for (i, g) in segments.iter().enumerate() {
        let t = expected[5 * i + 4].threshold;
        assert!((g["threshold"].as_f64().unwrap() - t).abs() <= 1e-15 * t.abs(), "{g}");
    }
    // base asks for JSON (its second and third arguments): the table, then CSV, instead.
    let table = case.ok(&[&base[..2], &["table"], &base[3..]].concat());
    assert!(
        table.lines().any(|l| l.starts_with("| quantile-transfer-online | ")),
        "{table}"
    );
    let csv = case.ok(&[&base[..2], &["csv"], &base[3..]].concat());
    assert!(csv.lines().any(|l| l.contains(",quantile-transfer-online,")), "{csv}");
}

/// Run `qtvpr-cli` in `dir` under `ulimit -v 1000000` (1 GB of address space).
fn run_capped(dir: &Path, args: &[&str]) -> Output {
    crate::common::run_in_shell(dir, crate::common::CAP, "", args)
}

/// A calibration whose `s.npy` is marked bzip2 (a few kB claiming 128 MiB), and a
/// `.npy` whose header claims 80 GB that is read unmapped (big-endian): under a 1 GB
/// address-space cap both are refused with exit 2 and a message, fast, never a signal.
#[test]
fn bombs_and_huge_claims_exit_2_under_a_memory_cap() {
    use crate::common::zip::{Member, npy_header, zip};
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name);
    let n: usize = 1 << 27; // bytes of zeros in s.npy
    // Marked bzip2 (12): its bytes are deflated, since no bzip2 reader is asked to look.
    let mut s = npy_header("<f8", &format!("({}, 1024)", n / 8 / 1024));
    s.resize(s.len() + n, 0);
    let mut gt = npy_header("|b1", "(1, 1)");
    gt.push(1);
    let meta = r#"{"format": "qtvpr-calibration", "version": 1, "matching": "single", "params": {"k": 1, "precision": 1.0, "window": null}}"#;
    let mut m = npy_header(&format!("<U{}", meta.len()), "()");
    m.extend(meta.chars().flat_map(|c| (c as u32).to_le_bytes()));
    let bomb = zip(&[
        Member {
            method: 12,
            ..Member::deflated("s.npy", &s)
        },
        Member::stored("gt.npy", &gt),
        Member::stored("meta.npy", &m),
    ]);
    drop(s);
    std::fs::write(path("bomb.npz"), bomb).unwrap();
    let size = std::fs::metadata(path("bomb.npz")).unwrap().len();
    assert!(size < 1 << 20, "{size}");
    crate::common::npy_f64(&path("val.npy"), &[&[0.5, 0.1], &[0.2, 0.9]]);
    crate::common::npy_raw(&path("huge.npy"), ">f8", false, &[100_000, 100_000], &[0; 8]);
    for (args, needle) in [
        (
            &["stream", "--calibration", "bomb.npz", "--val", "val.npy"][..],
            "bomb.npz (array s) cannot be decompressed: compression method",
        ),
        (
            &["stream", "--calibration", "bomb.npz", "--val", "huge.npy"][..],
            "bomb.npz (array s) cannot be decompressed: compression method",
        ),
        (
            &[
                "threshold",
                "--cal",
                "val.npy",
                "--cal-gt",
                "huge.npy",
                "--val",
                "val.npy",
            ][..],
            "huge.npy",
        ),
    ] {
        let start = std::time::Instant::now();
        let out = run_capped(dir.path(), args);
        let elapsed = start.elapsed();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {:?} {stderr}", out.status);
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert!(elapsed < std::time::Duration::from_secs(2), "{args:?}: {elapsed:?}");
    }
}

/// The margin gate end to end: `calibrate --gate margin` stores it, `stream` and
/// `threshold --cal` use it as the file's default (and `--gate none` overrides it),
/// every line carries `margin` and `gate` equal to `qtvpr::Online`'s, `evaluate` has
/// both gated methods, and multi matching with the gate exits 2 naming `--gate`.
#[test]
#[ignore = "needs ../shared/data vprbench-corridor (AlexNet_VPR): the gate through every command"]
fn the_margin_gate_in_calibrate_stream_threshold_and_evaluate() {
    let Some(case) = Case::new("AlexNet_VPR") else {
        return;
    };
    let calibrate = [
        "calibrate",
        "--cal",
        "cal.npy",
        "--cal-gt",
        "cal_gt.npy",
        "--window",
        "5",
    ];
    case.ok(&[&calibrate[..], &["--gate", "margin", "-o", "gated.npz"]].concat());
    let p = OnlineParams {
        k: 10,
        precision: 1.0,
        window: 5,
        min_window: 1,
        gate: qtvpr::Gate::Margin,
        sequence_gate: Default::default(),
    };
    let expected = case.expected(Matching::Single, None, p);
    let plain = case.expected(
        Matching::Single,
        None,
        OnlineParams {
            gate: qtvpr::Gate::None,
            ..p
        },
    );
    // The gate turns some accepted decisions down on this matrix.
    assert!(expected.iter().zip(&plain).any(|(g, u)| u.accept() && !g.accept()));

    let jsonl = case.ok(&["stream", "--calibration", "gated.npz", "--val", "val.npy"]);
    let lines: Vec<serde_json::Value> = jsonl.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), expected.len());
    for ((l, text), d) in lines.iter().zip(jsonl.lines()).zip(&expected) {
        // The record's fields, in its order.
        let at: Vec<usize> = Decision::fields(qtvpr::Gate::Margin)
            .iter()
            .map(|k| text.find(&format!("\"{k}\":")).unwrap())
            .collect();
        assert!(at.is_sorted() && l.as_object().unwrap().len() == at.len(), "{text}");
        // serde_json parses floats to within an ulp (the CSV below is compared bit for bit).
        for (key, want) in [("margin", d.margin.unwrap()), ("gate", d.gate.unwrap())] {
            assert!(
                (l[key].as_f64().unwrap() - want).abs() <= 1e-15 * want.abs(),
                "{key}: {l}"
            );
        }
        assert_eq!(l["accept"].as_bool(), Some(d.accept()));
        let (margin, gate) = (d.margin.unwrap(), d.gate.unwrap());
        assert_eq!(d.accept(), d.score >= d.threshold && margin >= gate);
    }
    let csv = case.ok(&[
        "stream",
        "--calibration",
        "gated.npz",
        "--val",
        "val.npy",
        "--format",
        "csv",
    ]);
    let mut rows = csv.lines();
    assert_eq!(rows.next(), Some(&*Decision::fields(qtvpr::Gate::Margin).join(",")));
    for (row, d) in rows.zip(&expected) {
        let v: Vec<&str> = row.split(',').collect();
        let f = |x: &str| x.parse::<f64>().unwrap().to_bits();
        assert_eq!(
            (f(v[11]), f(v[12])),
            (d.margin.unwrap().to_bits(), d.gate.unwrap().to_bits())
        );
    }
    // --gate none overrides the file: the eleven fields, the ungated decisions.
    let csv = case.ok(&[
        "stream",
        "--calibration",
        "gated.npz",
        "--val",
        "val.npy",
        "--format",
        "csv",
        "--gate",
        "none",
    ]);
    assert_csv_equals(&csv, &plain);

    // threshold: the file's gate by default, m* in the document and in the CSV.
    // m*, as the calibration built in this process has it.
    let m_star = expected[0].gate.unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&case.ok(&["threshold", "--cal", "gated.npz", "--val", "val.npy"])).unwrap();
    assert_eq!(json["params"]["gate"], "margin");
    assert!(
        (json["gate"].as_f64().unwrap() - m_star).abs() <= 1e-15 * m_star,
        "{json}"
    );
    let csv = case.ok(&["threshold", "--cal", "gated.npz", "--val", "val.npy", "--format", "csv"]);
    assert_eq!(csv.lines().next(), Some("start,end,quantile,threshold,gate"));
    let json: serde_json::Value =
        serde_json::from_str(&case.ok(&["threshold", "--cal", "gated.npz", "--val", "val.npy", "--gate", "none"]))
            .unwrap();
    assert!(json.get("gate").is_none() && json["params"]["gate"] == "none", "{json}");

    // evaluate: both gated methods, each segment with m*.
    case.write_scores("S.npy", case.s.view());
    write_npy(&case.path("GT.npy"), case.gt.view()).unwrap();
    let eval = [
        "evaluate",
        "--format",
        "json",
        "--similarity",
        "S.npy",
        "--gt",
        "GT.npy",
        "--cal-queries",
        "11",
    ];
    let json: serde_json::Value =
        serde_json::from_str(&case.ok(&[&eval[..], &["--method", "margin,quantile-transfer-margin"]].concat()))
            .unwrap();
    for method in ["margin", "quantile-transfer-margin"] {
        let segments = json["methods"][method]["segments"].as_array().unwrap();
        assert!(!segments.is_empty());
        let close = |g: &serde_json::Value| (g["gate"].as_f64().unwrap() - m_star).abs() <= 1e-15 * m_star;
        assert!(segments.iter().all(close), "{method}");
    }
    assert!(json["methods"]["margin"]["threshold_mse"].is_null());

    // Multi matching has no gate: exit 2, naming --gate, and no file.
    let why = "gate margin needs single matching";
    case.fails(
        &[
            &calibrate[..],
            &["--matching", "multi", "--gate", "margin", "-o", "multi.npz"],
        ]
        .concat(),
        &["multi.npz"],
        &["--gate", why],
    );
    case.fails(
        &[&eval[..], &["--matching", "multi", "--method", "margin"]].concat(),
        &[],
        &[why],
    );
    // A gate the core does not know: clap's usage error (exit 2), listing the gates.
    let out = case.run(&[
        "stream",
        "--calibration",
        "gated.npz",
        "--val",
        "val.npy",
        "--gate",
        "ratio",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains("'ratio'") && stderr.contains("none, or one or more of margin, sequence"),
        "{stderr}"
    );
    // `all` in multi matching is every method that applies.
    let json: serde_json::Value =
        serde_json::from_str(&case.ok(&[&eval[..], &["--matching", "multi"]].concat())).unwrap();
    let methods = json["methods"].as_object().unwrap();
    assert!(methods.contains_key("quantile-transfer") && !methods.contains_key("margin"));
}

/// `stream`'s CSV header and rows and its JSON keys are the core's record
/// (`qtvpr::Decision::RECORD`), field for field and in order, with the margin gate and
/// without: a field the CLI missed fails here (no data needed).
#[test]
fn stream_lines_are_the_core_record() {
    let dir = tempfile::tempdir().unwrap();
    let s = array2(&[&[0.9, 0.2, 0.3], &[0.1, 0.8, 0.2], &[0.3, 0.4, 0.7], &[0.2, 0.1, 0.1]]);
    let gt = GroundTruth::new(Array2::from_shape_fn((4, 3), |(i, j)| i == j).view()).unwrap();
    let cal = Calibration::new(s.view(), &gt, Matching::Single).unwrap();
    std::fs::write(dir.path().join("cal.npz"), cal.to_bytes(&Defaults::default()).unwrap()).unwrap();
    let val = array2(&[&[0.8, 0.2, 0.5], &[0.1, 0.9, 0.4], &[0.2, 0.1, 0.6], &[0.3, 0.1, 0.1]]);
    write_npy(&dir.path().join("val.npy"), val.view()).unwrap();
    for gate in [qtvpr::Gate::None, qtvpr::Gate::Margin] {
        let names = Decision::fields(gate);
        let line = format!("stream --calibration cal.npz --val val.npy --window 2 --gate {gate}");
        let stream: Vec<&str> = line.split(' ').collect();
        let csv = ok_in(dir.path(), &[&stream[..], &["--format", "csv"]].concat());
        let mut rows = csv.lines();
        assert_eq!(rows.next(), Some(&*names.join(",")), "{csv}");
        assert!(rows.all(|row| row.split(',').count() == names.len()), "{csv}");
        let jsonl = ok_in(dir.path(), &stream);
        assert_eq!(jsonl.lines().count(), 3);
        for line in jsonl.lines() {
            // The values are numbers, booleans and nulls: the quoted strings are the keys.
            let keys: Vec<&str> = line.split('"').skip(1).step_by(2).collect();
            assert_eq!(keys, names, "{line}");
        }
    }
}

/// The sequence gate and online sequence matching (semantics §15) through `calibrate`,
/// `stream` and `threshold`: a file of `calibrate --gate sequence --sequence 3` gives
/// the decisions of `qtvpr::Online` on a calibration matched the same way, bit for bit
/// (the consistency and its level among them), and `threshold` on that file gives the
/// same thresholds and consistencies as the stream, as the batch path of the causally
/// matched matrix.
#[test]
#[ignore = "needs ../shared/data vprbench-corridor: the sequence gate and L = 3 through calibrate and stream"]
fn the_sequence_gate_and_length_in_calibrate_stream_and_threshold() {
    let Some(case) = Case::new("AlexNet_VPR") else {
        return;
    };
    let length = 3;
    case.ok(&[
        "calibrate",
        "--cal",
        "cal.npy",
        "--cal-gt",
        "cal_gt.npy",
        "--window",
        "5",
        "--gate",
        "sequence",
        "--sequence",
        "3",
        "-o",
        "seq.npz",
    ]);
    let p = OnlineParams {
        k: 10,
        precision: 1.0,
        window: 5,
        min_window: 1,
        gate: qtvpr::Gate::Sequence,
        sequence_gate: Default::default(),
    };
    // What the core decides on a calibration matched over 3 queries in this process.
    let expected = case.expected_matched(Matching::Single, None, p, length);
    // The first 4 queries of the stream cannot pass (ceil(0.8 * 5) = 4), whatever their
    // scores; Corridor is one traverse, so some later ones do.
    assert!(expected[..4].iter().all(|d| !d.accept()));
    assert!(expected.iter().any(|d| d.consistency == Some(1.0)));
    let csv = case.ok(&[
        "stream",
        "--calibration",
        "seq.npz",
        "--val",
        "val.npy",
        "--format",
        "csv",
    ]);
    let mut rows = csv.lines();
    assert_eq!(rows.next(), Some(&*Decision::fields(qtvpr::Gate::Sequence).join(",")));
    let rows: Vec<&str> = rows.collect();
    assert_eq!(rows.len(), expected.len());
    let f = |x: &str| x.parse::<f64>().unwrap().to_bits();
    for (row, d) in rows.iter().zip(&expected) {
        let v: Vec<&str> = row.split(',').collect();
        // query, ..., threshold (4), best (5), accept (8), consistency (11), its level (12).
        assert_eq!(f(v[4]), d.threshold.to_bits(), "{row}");
        assert_eq!(v[5].parse::<usize>().unwrap(), d.best, "{row}");
        assert_eq!(v[8], d.accept().to_string(), "{row}");
        assert_eq!(
            (f(v[11]), f(v[12])),
            (d.consistency.unwrap().to_bits(), 0.8f64.to_bits()),
            "{row}"
        );
    }
    // threshold on the file: one segment per query, so each query's threshold is the
    // stream's of a window of 1; the consistencies are the stream's.
    let json: serde_json::Value = serde_json::from_str(&case.ok(&[
        "threshold",
        "--cal",
        "seq.npz",
        "--val",
        "val.npy",
        "--segment-size",
        "1",
    ]))
    .unwrap();
    assert_eq!(json["params"]["gate"], "sequence");
    assert_eq!(json["consistency_level"], 0.8);
    let consistencies: Vec<f64> = json["query_consistencies"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_f64().unwrap())
        .collect();
    let streamed: Vec<f64> = expected.iter().map(|d| d.consistency.unwrap()).collect();
    assert_eq!(consistencies, streamed);
    let one = case.expected_matched(Matching::Single, None, OnlineParams { window: 1, ..p }, length);
    let segments = json["segments"].as_array().unwrap();
    assert_eq!(segments.len(), one.len());
    for (seg, d) in segments.iter().zip(&one) {
        let t = seg["threshold"].as_f64().unwrap();
        assert!((t - d.threshold).abs() <= 1e-15 * d.threshold.abs().max(1.0), "{seg}");
    }
    // Another length than the file's: exit 2, naming both.
    case.fails(
        &[
            "stream",
            "--calibration",
            "seq.npz",
            "--val",
            "val.npy",
            "--sequence",
            "5",
        ],
        &[],
        &["--sequence", "5 is not the calibration's sequence length 3"],
    );
    // The sequence gate on multi matching: exit 2 naming --gate, and no file.
    case.fails(
        &[
            "calibrate",
            "--cal",
            "cal.npy",
            "--cal-gt",
            "cal_gt.npy",
            "--matching",
            "multi",
            "--gate",
            "margin,sequence",
            "-o",
            "multi.npz",
        ],
        &["multi.npz"],
        &["--gate", "needs single matching"],
    );
}
