//! End-to-end tests of `qtvpr-cli evaluate`: a hand-computed run in every format, the
//! embedded demo data, figures, ablations, and bad input (exit 2, one `error:` line,
//! no output file).

use std::path::PathBuf;
use std::process::{Command, Output};

use serde_json::{Value, json};
use tempfile::TempDir;

use crate::common::{npy_bool, npy_f64};

const Z: f64 = 4.753424308817087;

/// |DB| = 3, |Q| = 7: calibration c0, c1, deployment d0..d4 (crates/qtvpr/src/operations/evaluate/mod.rs).
///
/// ```text
///        c0   c1    d0   d1   d2   d3   d4
/// db0   0.9  0.2   0.7  0.1  0.5  0.2  0.3
/// db1   0.1  0.95  0.3  0.6  0.4  0.9  0.3
/// db2   0.3  0.4   0.2  0.5  0.3  0.1  0.3
/// ```
/// GT: c0 -> db0, c1 -> db2, d0 -> db0, d1 -> db2.
struct Case {
    dir: TempDir,
}

impl Case {
    fn new() -> Self {
        let case = Self {
            dir: tempfile::tempdir().unwrap(),
        };
        npy_f64(
            &case.path("S.npy"),
            &[
                &[0.9, 0.2, 0.7, 0.1, 0.5, 0.2, 0.3],
                &[0.1, 0.95, 0.3, 0.6, 0.4, 0.9, 0.3],
                &[0.3, 0.4, 0.2, 0.5, 0.3, 0.1, 0.3],
            ],
        );
        npy_bool(
            &case.path("GT.npy"),
            &[&[1, 0, 1, 0, 0, 0, 0], &[0, 0, 0, 0, 0, 0, 0], &[0, 1, 0, 1, 0, 0, 0]],
        );
        case
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// `evaluate --similarity S.npy --gt GT.npy` with the tiny protocol (2 calibration
    /// queries, segments of 2, tau = 0.5), as JSON, and `extra` arguments.
    /// Each default is left out when `extra` gives that flag itself.
    fn run(&self, extra: &[&str]) -> Output {
        let (s, gt) = (self.path("S.npy"), self.path("GT.npy"));
        let defaults = [
            ("--similarity", s.to_str().unwrap()),
            ("--gt", gt.to_str().unwrap()),
            ("--cal-queries", "2"),
            ("--segment-size", "2"),
            ("--precision", "0.5"),
            ("--format", "json"),
        ];
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"));
        cmd.arg("evaluate");
        let given = |flag: &str| {
            let alias = match flag {
                "--cal-queries" => "--cal-fraction",
                "--segment-size" => "--segment-fraction",
                other => other,
            };
            extra.contains(&flag) || extra.contains(&alias)
        };
        for (flag, value) in defaults {
            if !given(flag) {
                cmd.args([flag, value]);
            }
        }
        cmd.args(extra).output().unwrap()
    }

    fn ok(&self, extra: &[&str]) -> String {
        let out = self.run(extra);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    }

    /// A clean failure whose one-line message contains every needle, and no output file.
    fn fails(&self, extra: &[&str], needles: &[&str]) {
        let out_file = self.path("out.json");
        let mut args = vec!["--output", out_file.to_str().unwrap()];
        args.extend_from_slice(extra);
        let out = self.run(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
        assert!(stderr.starts_with("error: "), "{stderr}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        for needle in needles {
            assert!(stderr.contains(needle), "{needle:?} not in {stderr}");
        }
        assert!(!out_file.exists(), "an output file was left behind");
    }
}

fn near(v: &Value, x: f64) -> bool {
    (v.as_f64().unwrap() - x).abs() < 1e-12
}

#[test]
fn hand_computed_json() {
    let case = Case::new();
    let text = case.ok(&[]);
    // Methods come in report order (serde_json::Value would sort them, so look at the text).
    let at = |name: &str| text.find(&format!("\"{name}\": {{")).unwrap();
    let names = [
        "quantile-transfer",
        "quantile-transfer-online",
        "schubert",
        "schubert-calibrated",
        "calibration-threshold",
        "oracle",
    ];
    assert!(names.windows(2).all(|w| at(w[0]) < at(w[1])), "{text}");
    let out: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(
        out["params"],
        json!({"k": 10, "precision": 0.5, "matching": "single", "queries": 7, "database_size": 3,
               "calibration_queries": 2, "deployment_start": 2, "deployment_queries": 5,
               "segment_size": 2, "segments": 2, "calibration": {"count": 2}, "segment": {"count": 2},
               "deploy_fraction": null,
               "sequence_gate": {"window": 5, "level": 0.8, "speed": 1.0, "tolerance": 2.0, "drift": 0.2}})
    );
    // Full segments d0..d3: best matches d0 (db0, hard), d1 (db1, wrong), d2 and d3 (no
    // match); d0 and d1 have a hard match -> R@1 = 1/2.
    assert_eq!(out["recall_at_1"], 0.5);
    assert_eq!(out["dataset"], case.path("S.npy").display().to_string());
    let methods = out["methods"].as_object().unwrap();
    assert_eq!(methods.len(), 8);
    for m in methods.values() {
        // Segment (2, 4) = d2, d3 has no hard match: skipped. Its oracle is reject-all (null).
        assert_eq!(
            (m["segments_counted"].as_u64(), m["segments_skipped"].as_u64()),
            (Some(1), Some(1))
        );
        let segs = m["segments"].as_array().unwrap();
        assert_eq!((segs[0]["start"].as_u64(), segs[0]["end"].as_u64()), (Some(0), Some(2)));
        assert_eq!(segs[0]["oracle_threshold"], 0.7);
        assert_eq!(segs[1]["oracle_threshold"], Value::Null);
    }
    // Oracle 0.7 on segment 0: d0 (0.7, correct) accepted, d1 (0.6) not: TP 1, FP 0,
    // 2 positives -> recall 0.5, %Segs 100, MSE 0.
    let o = &methods["oracle"];
    assert_eq!(
        (o["pct_segs"].as_f64(), o["avg_recall"].as_f64()),
        (Some(100.0), Some(0.5))
    );
    assert_eq!(o["threshold_mse"], 0.0);
    // One correct decision: the precision's 95% lower bound is 0.05^(1/1) = 0.05.
    let mut seg = o["segments"][0].clone();
    assert!(near(&seg["precision_lower95"], 0.05));
    seg["precision_lower95"] = json!(0.05);
    assert_eq!(
        seg,
        json!({"start": 0, "end": 2, "threshold": 0.7, "oracle_threshold": 0.7, "tp": 1, "fp": 0,
               "accepted": 1, "positives": 2, "precision": 1.0, "recall": 0.5, "precision_lower95": 0.05,
               "meets": true})
    );
    // Segment 1 accepts nothing at inf: no precision, no bound. Pooled: TP 1, FP 0,
    // 1 accepted, positives 2.
    assert_eq!(
        (&o["segments"][1]["precision"], &o["segments"][1]["precision_lower95"]),
        (&Value::Null, &Value::Null)
    );
    assert_eq!(
        (
            &o["pooled_tp"],
            &o["pooled_fp"],
            &o["pooled_accepted"],
            &o["pooled_positives"]
        ),
        (&json!(1), &json!(0), &json!(1), &json!(2))
    );
    assert_eq!(
        (&o["pooled_precision"], &o["pooled_recall"]),
        (&json!(1.0), &json!(0.5))
    );
    assert!(near(&o["pooled_precision_lower95"], 0.05));
    // Calibration threshold 0.9 (c0's 0.9 correct after c1's 0.95 wrong: 1 >= 0.5 x 2),
    // for both segments: accepts nothing in segment 0 -> recall 0; MSE (0.9 - 0.7)^2.
    let c = &methods["calibration-threshold"];
    assert_eq!(c["segments"][0]["threshold"], 0.9);
    assert_eq!(c["segments"][1]["threshold"], 0.9);
    assert_eq!(
        (c["pct_segs"].as_f64(), c["avg_recall"].as_f64()),
        (Some(100.0), Some(0.0))
    );
    assert!(near(&c["threshold_mse"], 0.04));
    // Pooled: segment 1 accepts d3's 0.9 (wrong): TP 0, FP 1 -> precision 0, bound 0.
    assert_eq!(
        (&c["pooled_precision"], &c["pooled_precision_lower95"]),
        (&json!(0.0), &json!(0.0))
    );
    // Quantile transfer: q = 4/5 everywhere; segment 0 (0.1 .. 0.7) -> 0.6, accepting
    // d0 (T) and d1 (F): precision 1/2 meets 0.5, recall 1/2. MSE (0.6 - 0.7)^2.
    let q = &methods["quantile-transfer"];
    assert!(near(&q["segments"][0]["threshold"], 0.6) && near(&q["segments"][1]["threshold"], 0.5));
    assert_eq!(
        (q["segments"][0]["tp"].as_u64(), q["segments"][0]["fp"].as_u64()),
        (Some(1), Some(1))
    );
    assert!(near(&q["threshold_mse"], 0.01));
    // Online, a window of 2 over d0, d1, ... (crates/qtvpr/src/operations/evaluate/online.rs):
    // d0 alone -> 0.54, accepting d0 (T); d1 with d0 -> 0.6, accepting d1 (F).
    // Segment 0: TP 1, FP 1 at the threshold of its last query, 0.6; segment 1 ends at
    // d3: 0.5.
    let o = &methods["quantile-transfer-online"];
    assert!(near(&o["segments"][0]["threshold"], 0.6) && near(&o["segments"][1]["threshold"], 0.5));
    assert_eq!(
        (o["segments"][0]["tp"].as_u64(), o["segments"][0]["fp"].as_u64()),
        (Some(1), Some(1))
    );
    assert_eq!(
        (o["pct_segs"].as_f64(), o["avg_recall"].as_f64()),
        (Some(100.0), Some(0.5))
    );
    // Schubert on segment 0: median 0.4, MAD 0.2 -> 0.4 + (0.2 / 0.675) z; calibrated:
    // median 0.35, MAD 0.2.
    assert!(near(
        &methods["schubert"]["segments"][0]["threshold"],
        0.4 + 0.2 / 0.675 * Z
    ));
    assert!(near(
        &methods["schubert-calibrated"]["segments"][1]["threshold"],
        0.35 + 0.2 / 0.675 * Z
    ));
    // Both Schubert fits lie above every deployment score (1.81 and 1.41 on segments 0
    // and 1; 1.76 calibrated): nothing accepted, so segment 0 meets by convention and
    // %Segs is 100 on no decision; the count and the undefined precision say so.
    for name in ["schubert", "schubert-calibrated"] {
        let m = &methods[name];
        assert_eq!(
            (&m["pct_segs"], &m["pooled_accepted"], &m["pooled_precision"]),
            (&json!(100.0), &json!(0), &Value::Null),
            "{name}"
        );
    }
    // Semantics §14's reliability bins (the decisions of table_and_csv below):
    // confidences 0.2712 (d0, right), 0.1005 (d1), 0.0874 (d2) and 0.4856 (d3, wrong),
    // one in each of bins 2, 1, 0 and 4; the ECE, the mean of their |p - c|,
    // (0.7288 + 0.1005 + 0.0874 + 0.4856) / 4 = 0.35056, is computed from them.
    let c = &out["confidence"]["signals"]["confidence"];
    let bins: Vec<(f64, u64, f64, f64)> = c["bins"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| {
            let f = |k: &str| b[k].as_f64().unwrap();
            (
                f("lower"),
                b["n"].as_u64().unwrap(),
                f("mean_confidence"),
                f("hit_rate"),
            )
        })
        .collect();
    let want = [
        (0.0, 0.087_356_873_6),
        (0.1, 0.100_488_901_9),
        (0.2, 0.271_208_775_8),
        (0.4, 0.485_593_591_1),
    ];
    assert_eq!(bins.len(), want.len(), "{bins:?}");
    for (got, (lower, mean)) in bins.iter().zip(want) {
        assert_eq!((got.0, got.1), (lower, 1));
        assert!((got.2 - mean).abs() < 1e-9, "{got:?}");
        assert_eq!(got.3, if lower == 0.2 { 1.0 } else { 0.0 });
    }
    assert!((c["ece"].as_f64().unwrap() - 0.350_557_647_7).abs() < 1e-9);
}

#[test]
fn table_and_csv() {
    let case = Case::new();
    let table = case.ok(&["--format", "table", "--method", "oracle,calibration-threshold,schubert"]);
    let lines: Vec<&str> = table.lines().collect();
    assert!(lines[0].contains("queries 0..2 calibrate; 2 segments of 2"), "{table}");
    // The orientation assumed: the tiny ground truth cannot tell (queries d2..d4 and
    // database image 1 have no positive), so no warning, and the line says it is assumed.
    assert_eq!(
        lines[2],
        "orientation: |DB| 3 x |Q| 7 (DB-major; pass --query-major for VPR-Bench files), assumed (the ground \
         truth cannot tell: queries without a positive: 3 of 7; database images without one: 1 of 3)"
    );
    let lines = &lines[2..];
    assert_eq!(
        lines[2],
        "| method | %Segs | AvgR@50P | segments counted | skipped (no positives) | threshold MSE vs oracle \
         | matches accepted | pooled precision | its 95% lower bound |"
    );
    // Pooled: the oracle accepts one correct decision (bound 0.05^1); the calibration
    // threshold one wrong one (precision 0, bound 0); Schubert none (its %Segs of 100
    // rests on nothing: no precision). Schubert's MSE: segment 0 only (segment 1 is
    // skipped), (0.4 + 0.2 / 0.675 z - 0.7)^2 = 1.10842^2 = 1.2286.
    assert_eq!(
        lines[4],
        "| oracle | 100.0 | 0.500 | 1 | 1 | 0.00e0 | 1 | 1.000 | 0.050 |"
    );
    assert_eq!(
        lines[5],
        "| calibration-threshold | 100.0 | 0.000 | 1 | 1 | 4.00e-2 | 1 | 0.000 | 0.000 |"
    );
    assert_eq!(
        lines[6],
        "| schubert | 100.0 | 0.000 | 1 | 1 | 1.23e0 | 0 | n/a | n/a |"
    );
    let lines = &lines[1..];
    // Semantics §14's signals. The calibration's best matches: query 0 right (PA-score
    // sqrt(0.2 / 1.4) = 0.37796), query 1 wrong (sqrt(0.1 / 1.2) = 0.28868): a
    // violator, one block of 1 of 2, centre 0.33332, value 2/4, from its lower bound
    // 1 - sqrt(0.95) = 0.02532 at PA-score 1. Deployment queries 2..6: (s1, PA-score,
    // c) = (0.7, 0.65465, right), (0.6, 0.89443, wrong), (0.5, 0.91287, wrong), (0.9,
    // 0.35355, wrong); confidences 0.2712, 0.1005, 0.0874, 0.4856. AUROC: every signal
    // 2 of 3 pairs; Brier (0.7288^2 + 0.1005^2 + 0.0874^2 + 0.4856^2) / 4 = 0.19617;
    // ECE: one decision per bin, 0.35056.
    assert_eq!(lines[7], "| signal | AUROC | Brier | ECE |");
    assert_eq!(lines[9], "| score | 0.667 | | |");
    assert_eq!(lines[10], "| margin | 0.667 | | |");
    assert_eq!(lines[11], "| pa_score | 0.667 | | |");
    // The consistency (semantics §15) has no AUROC on |DB| = 3, too small for the
    // sequence gate's +-3 rows.
    assert_eq!(lines[12], "| consistency | n/a | | |");
    assert_eq!(lines[13], "| confidence | 0.667 | 0.196 | 0.351 |");
    assert_eq!(lines.len(), 14);

    let csv = case.ok(&["--format", "csv", "--method", "oracle", "--k", "1,2"]);
    let rows: Vec<&str> = csv.lines().collect();
    assert!(rows[0].starts_with("k,calibration_queries,deployment_start,"), "{csv}");
    // Two settings (an ablation): the deployment set becomes the last floor(0.5 x 7) = 3
    // queries, one segment of 2 (d2, d3 in the original numbering: no positives).
    assert_eq!(rows.len(), 3, "{csv}");
    // No segment counted: no %Segs, AvgR or MSE; nothing accepted: 0, no precision,
    // recall 0, no bound.
    assert!(
        rows[0].contains(",threshold_mse,pooled_accepted,pooled_precision,pooled_recall,"),
        "{csv}"
    );
    assert!(rows[1].starts_with("1,2,4,3,2,1,oracle,,,0,1,,0,,0,,"), "{csv}");
    assert!(rows[2].starts_with("2,2,4,3,2,1,oracle,"), "{csv}");
    // Nothing accepted (the oracle of a segment without positives is reject-all): no
    // bound; no deployment query with a hard match: no R@1.
    // The signals: queries 4 and 5 are both wrong (no AUROC); confidences 0.08736 and
    // 0.48559, so Brier (0.08736^2 + 0.48559^2) / 2 = 0.12171 and ECE (0.08736 +
    // 0.48559) / 2 = 0.28648; no R@1 (nothing has a hard match).
    assert!(
        rows[0].ends_with(",auroc_score,auroc_margin,auroc_pa_score,auroc_consistency,auroc_confidence,brier,ece"),
        "{csv}"
    );
    let cells: Vec<&str> = rows[1].rsplitn(8, ',').collect();
    assert_eq!(cells[2..7], ["", "", "", "", ""], "{csv}");
    let (ece, brier): (f64, f64) = (cells[0].parse().unwrap(), cells[1].parse().unwrap());
    assert!(
        (brier - 0.121_716_18).abs() < 1e-6 && (ece - 0.286_475_2).abs() < 1e-6,
        "{csv}"
    );
}

#[test]
fn ablation_json() {
    let case = Case::new();
    let text = case.ok(&["--method", "oracle,schubert", "--k", "1,2", "--cal-queries", "1,2"]);
    let out: Value = serde_json::from_str(&text).unwrap();
    fn keys(v: &Value) -> Vec<&str> {
        let mut k: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
        k.sort_unstable();
        k
    }
    assert_eq!(keys(&out), ["ablation", "dataset", "orientation"]);
    let runs = out["ablation"].as_array().unwrap();
    // Calibration sizes outer, k inner; every run deploys on the last floor(0.5 x 7) = 3.
    let settings: Vec<(u64, u64)> = runs
        .iter()
        .map(|r| {
            (
                r["params"]["calibration_queries"].as_u64().unwrap(),
                r["params"]["k"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(settings, [(1, 1), (1, 2), (2, 1), (2, 2)]);
    for r in runs {
        assert_eq!(keys(r), ["confidence", "methods", "params", "recall_at_1"]);
        assert_eq!(
            (&r["params"]["deployment_start"], &r["params"]["deploy_fraction"]),
            (&json!(4), &json!(0.5))
        );
        // The oracle and per-segment Schubert see the deployment set only.
        assert_eq!(r["methods"], runs[0]["methods"]);
    }
}

#[test]
fn query_major_and_soft_ground_truth() {
    let case = Case::new();
    let base: Value = serde_json::from_str(&case.ok(&["--method", "oracle"])).unwrap();
    // The same case stored query-major (7 x 3).
    npy_f64(
        &case.path("S_t.npy"),
        &[
            &[0.9, 0.1, 0.3],
            &[0.2, 0.95, 0.4],
            &[0.7, 0.3, 0.2],
            &[0.1, 0.6, 0.5],
            &[0.5, 0.4, 0.3],
            &[0.2, 0.9, 0.1],
            &[0.3, 0.3, 0.3],
        ],
    );
    npy_bool(
        &case.path("GT_t.npy"),
        &[
            &[1, 0, 0],
            &[0, 0, 1],
            &[1, 0, 0],
            &[0, 0, 1],
            &[0, 0, 0],
            &[0, 0, 0],
            &[0, 0, 0],
        ],
    );
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"));
    let out = cmd
        .args(["evaluate", "--format", "json", "--query-major", "--method", "oracle"])
        .args(["--cal-queries", "2", "--segment-size", "2", "--precision", "0.5"])
        .arg("--similarity")
        .arg(case.path("S_t.npy"))
        .arg("--gt")
        .arg(case.path("GT_t.npy"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let t: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(t["methods"], base["methods"]);
    // tau = 1 on the calibration set: c1's best match 0.95 (db1, wrong) tops c0's 0.9
    // (correct), so no group is valid -> reject-all (null), and no MSE.
    let hard: Value =
        serde_json::from_str(&case.ok(&["--method", "calibration-threshold", "--precision", "1"])).unwrap();
    let c = &hard["methods"]["calibration-threshold"];
    assert_eq!(c["segments"][0]["threshold"], Value::Null);
    assert_eq!(c["threshold_mse"], Value::Null);
    // Soft ground truth marking (db1, c1) tolerable: c1 makes no decision, so the
    // calibration threshold is c0's 0.9, for both segments.
    npy_bool(
        &case.path("soft.npy"),
        &[&[1, 0, 1, 0, 0, 0, 0], &[0, 1, 0, 0, 0, 0, 0], &[0, 1, 0, 1, 0, 0, 0]],
    );
    let soft = case.path("soft.npy");
    let out: Value = serde_json::from_str(&case.ok(&[
        "--method",
        "calibration-threshold",
        "--gt-soft",
        soft.to_str().unwrap(),
        "--precision",
        "1",
    ]))
    .unwrap();
    let c = &out["methods"]["calibration-threshold"];
    assert_eq!(
        (&c["segments"][0]["threshold"], &c["segments"][1]["threshold"]),
        (&json!(0.9), &json!(0.9))
    );
}

#[test]
fn embedded_demo_data_prints_a_table() {
    let out = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .arg("evaluate")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    // 111 queries: floor(11.1) = 11 calibrate; segments of ceil(1.11) = 2: 50 of them.
    assert!(
        text.contains("111 database images x 111 queries; queries 0..11 calibrate; 50 segments of 2"),
        "{text}"
    );
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| method") && !l.starts_with("| signal"))
        .collect();
    // Every method, the gates' five included (single matching); then the five signals
    // of semantics §14 and §15. The 11 calibration queries' best matches are all right:
    // one block, and yet the map ranks as the PA-score does (tests/test_confidence.py
    // checks these figures against the NumPy reference).
    assert_eq!(rows.len(), 16, "{text}");
    assert_eq!(rows[13], "| pa_score | 0.729 | | |", "{text}");
    assert!(rows[14].starts_with("| consistency | "), "{text}");
    assert_eq!(rows[15], "| confidence | 0.729 | 0.133 | 0.041 |", "{text}");
    assert!(rows[1].starts_with("| quantile-transfer-online | "), "{text}");
    assert!(rows[3].starts_with("| margin | "), "{text}");
    assert!(rows[6].starts_with("| sequence | "), "{text}");
    assert!(rows[10].starts_with("| oracle | 100.0 |"), "{text}");
}

#[test]
fn plots_are_written() {
    let case = Case::new();
    let dir = case.path("figs");
    case.ok(&["--plot", dir.to_str().unwrap()]);
    for name in ["thresholds.svg", "precision_recall.svg", "scores.svg"] {
        let svg = std::fs::read_to_string(dir.join(name)).unwrap();
        assert!(svg.starts_with("<svg"), "{name}");
        // Text is real SVG text, with the legend's method names.
        assert!(svg.contains("<text") && svg.contains("quantile-transfer"), "{name}");
        assert!(svg.contains("quantile-transfer-online"), "{name}");
    }
    // The Schubert fits accept nothing (hand_computed_json): no operating point, and a
    // legend that says why, where the others give their precision and count.
    let svg = std::fs::read_to_string(dir.join("precision_recall.svg")).unwrap();
    assert!(
        svg.contains("schubert: no match accepted, so no precision (not drawn)"),
        "{svg}"
    );
    assert!(
        svg.contains("oracle: precision 1.000, recall 0.500 (1 accepted: TP 1, FP 0)"),
        "{svg}"
    );
    case.ok(&["--plot", dir.to_str().unwrap(), "--k", "1,2,3"]);
    let svg = std::fs::read_to_string(dir.join("ablation_k.svg")).unwrap();
    assert!(svg.contains("Sensitivity to k"));
    assert!(!dir.join("ablation_cal.svg").exists());
}

/// The count labels of a reliability diagram, in drawing order (plotters writes each
/// text on a line of its own).
fn reliability_counts(svg: &str) -> Vec<&str> {
    svg.lines().filter(|l| l.starts_with("n = ")).collect()
}

#[test]
fn reliability_diagram_has_a_point_per_bin() {
    let case = Case::new();
    let dir = case.path("figs");
    case.ok(&["--plot", dir.to_str().unwrap()]);
    // Four non-empty bins (hand_computed_json), one decision each. One circle per point
    // and one in the legend.
    let svg = std::fs::read_to_string(dir.join("reliability.svg")).unwrap();
    assert_eq!(reliability_counts(&svg), ["n = 1"; 4], "{svg}");
    assert_eq!(svg.matches("<circle").count(), 5, "{svg}");
    assert!(svg.contains("ECE 0.351, Brier 0.196"), "{svg}");
    assert!(svg.contains("perfect calibration"), "{svg}");

    // The embedded data: 100 decisions in bins 7, 8 and 9 (16, 43 and 41 of them).
    std::fs::remove_dir_all(&dir).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .args(["evaluate", "--plot", dir.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(dir.join("reliability.svg")).unwrap();
    assert_eq!(reliability_counts(&svg), ["n = 16", "n = 43", "n = 41"], "{svg}");
    assert_eq!(svg.matches("<circle").count(), 4, "{svg}");
    assert!(svg.contains("ECE 0.041, Brier 0.133"), "{svg}");

    // Multi matching has no confidence: no diagram, the other figures as before.
    std::fs::remove_dir_all(&dir).unwrap();
    case.ok(&["--plot", dir.to_str().unwrap(), "--matching", "multi"]);
    assert!(dir.join("thresholds.svg").exists() && dir.join("precision_recall.svg").exists());
    assert!(!dir.join("reliability.svg").exists());
}

#[test]
fn plots_name_the_file_and_explain_the_markers() {
    // The x axis names the similarity file, not the temporary directory it is in.
    let case = Case::new();
    let dir = case.path("figs");
    case.ok(&["--plot", dir.to_str().unwrap()]);
    let svg = std::fs::read_to_string(dir.join("thresholds.svg")).unwrap();
    assert!(svg.contains("of 7: S.npy)"), "no file name in the x label");
    assert!(
        !svg.contains(case.dir.path().to_str().unwrap()),
        "the x label carries the whole path"
    );

    // The embedded data has segments where the oracle rejects all (and none where a
    // method does): the legend says what the cross means, the axis names the band.
    let out = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .args(["evaluate", "--plot", dir.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(dir.join("thresholds.svg")).unwrap();
    assert!(svg.contains("oracle reject-all: no threshold reaches precision 1 in the segment"));
    // (plotters writes each text on a line of its own.)
    let texts: Vec<&str> = svg.lines().filter(|l| !l.starts_with('<')).collect();
    assert!(texts.contains(&"reject-all"), "no reject-all tick label");
    assert!(
        !svg.contains("of the method in that colour"),
        "a legend entry for no marker"
    );
}

#[test]
fn bad_input() {
    let case = Case::new();
    case.fails(&["--method", "oracle,magic"], &["--method", "unknown method 'magic'"]);
    case.fails(&["--k", "0"], &["k must be >= 1, got 0"]);
    case.fails(&["--precision", "1.5"], &["precision must be in (0, 1]"]);
    case.fails(
        &["--cal-queries", "7"],
        &["the calibration set must have between 1 and 6 of the 7 queries, got 7"],
    );
    case.fails(
        &["--segment-size", "6"],
        &["segment size 6 is larger than the 5 deployment queries"],
    );
    case.fails(&["--deploy-fraction", "0.9"], &["overlap"]);
    // A cal fraction of 0.1 leaves floor(0.7) = 0 calibration queries.
    case.fails(
        &["--cal-fraction", "0.1"],
        &["the calibration set must have between 1 and 6 of the 7 queries, got 0"],
    );
    npy_bool(&case.path("GT_narrow.npy"), &[&[1, 0], &[0, 0], &[0, 1]]);
    case.fails(
        &["--gt", case.path("GT_narrow.npy").to_str().unwrap()],
        &["ground truth shape 3x2 does not match similarity shape 3x7"],
    );
    npy_f64(&case.path("S_nan.npy"), &[&[0.1, f64::NAN], &[0.2, 0.3]]);
    case.fails(
        &["--similarity", case.path("S_nan.npy").to_str().unwrap()],
        &["--similarity", "S_nan.npy"],
    );
    // --plot into a path that is a file.
    std::fs::write(case.path("not_a_dir"), "x").unwrap();
    case.fails(&["--plot", case.path("not_a_dir").to_str().unwrap()], &["--plot"]);
}

/// The embedded deployment traverse (data/corridor, 111 database images x 100 queries,
/// query j matching database images j+9 ..= j+13) and its transpose, as a VPR-Bench
/// user would have it (100 x 111, query-major), both written into `dir`: `S.npy`,
/// `GT.npy` (|DB| x |Q|) and `S_t.npy`, `GT_t.npy` (|Q| x |DB|).
fn corridor_pair(dir: &std::path::Path) {
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/corridor");
    let read = |name: &str| npyz::NpyFile::new(std::fs::File::open(data.join(name)).unwrap()).unwrap();
    let s = read("deploy_S.npy");
    assert_eq!(s.shape(), [111, 100]);
    let s: Vec<f64> = s.into_vec().unwrap();
    let gt: Vec<bool> = read("deploy_GT.npy").into_vec().unwrap();
    let rows = |n: usize, m: usize, at: &dyn Fn(usize, usize) -> usize| -> Vec<Vec<usize>> {
        (0..n).map(|i| (0..m).map(|j| at(i, j)).collect()).collect()
    };
    for (suffix, n, m, at) in [
        (
            "",
            111,
            100,
            &(|i: usize, j: usize| i * 100 + j) as &dyn Fn(usize, usize) -> usize,
        ),
        ("_t", 100, 111, &|i: usize, j: usize| j * 100 + i),
    ] {
        let index = rows(n, m, at);
        let s_rows: Vec<Vec<f64>> = index.iter().map(|r| r.iter().map(|&k| s[k]).collect()).collect();
        let gt_rows: Vec<Vec<u8>> = index
            .iter()
            .map(|r| r.iter().map(|&k| u8::from(gt[k])).collect())
            .collect();
        npy_f64(
            &dir.join(format!("S{suffix}.npy")),
            &s_rows.iter().map(Vec::as_slice).collect::<Vec<_>>(),
        );
        npy_bool(
            &dir.join(format!("GT{suffix}.npy")),
            &gt_rows.iter().map(Vec::as_slice).collect::<Vec<_>>(),
        );
    }
}

fn cli(dir: &std::path::Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn a_transposed_pair_read_without_query_major_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    corridor_pair(dir.path());
    // Read as is, the query-major pair is 100 "database images" x 111 "queries": every
    // one of the 100 (the real queries) has a positive, and 9 of the 111 (database
    // images 0..=8, before the first deployment query's matches) have none:
    // 9 >= 0.05 * 111, so the ground truth contradicts the layout.
    let out = cli(
        dir.path(),
        &[
            "evaluate",
            "--format",
            "json",
            "--similarity",
            "S_t.npy",
            "--gt",
            "GT_t.npy",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "warning: the layout is contradicted by the ground truth: 9 of the 111 queries have no positive in it \
         while every one of the 100 database images has one; a VPR traverse is usually the other way round, so \
         the matrices may be query-major (|Q| x |DB|, as VPR-Bench stores them); if so, pass --query-major\n"
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        v["orientation"],
        json!({"db": 100, "queries": 111, "query_major": false,
            "layout": "contradicted by the ground truth (queries without a positive: 9 of 111, while every \
                       database image has one)",
            "evidence": {
            "labelled_queries": 111, "queries_without_positive": 9, "db_without_positive": 0,
            "verdict": "contradicts"}})
    );
    assert_eq!(v["params"]["database_size"], 100);

    // With --query-major: 111 x 100, every query has a positive and 9 of the 111
    // database images none: consistent, no warning. The same as the |DB| x |Q| pair.
    let out = cli(
        dir.path(),
        &[
            "evaluate",
            "--format",
            "json",
            "--similarity",
            "S_t.npy",
            "--gt",
            "GT_t.npy",
            "--query-major",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8_lossy(&out.stderr), "");
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let consistent = json!({"labelled_queries": 100, "queries_without_positive": 0, "db_without_positive": 9,
                            "verdict": "consistent"});
    assert_eq!(
        v["orientation"],
        json!({"db": 111, "queries": 100, "query_major": true,
               "layout": "confirmed by the ground truth (every query has a positive; database images without \
                          one: 9 of 111)",
               "evidence": consistent})
    );
    let out = cli(
        dir.path(),
        &[
            "evaluate",
            "--similarity",
            "S.npy",
            "--gt",
            "GT.npy",
            "--format",
            "table",
        ],
    );
    assert_eq!(String::from_utf8_lossy(&out.stderr), "");
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(
        text.lines().nth(2),
        Some(
            "orientation: |DB| 111 x |Q| 100 (DB-major; pass --query-major for VPR-Bench files), confirmed by \
             the ground truth (every query has a positive; database images without one: 9 of 111)"
        ),
        "{text}"
    );

    // threshold on one matrix split: the ground truth of every query is the evidence.
    let out = cli(
        dir.path(),
        &[
            "threshold",
            "--similarity",
            "S_t.npy",
            "--cal-gt",
            "GT_t.npy",
            "--cal-queries",
            "10",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .starts_with("warning: the layout is contradicted by the ground truth: 9 of the 111 queries"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["orientation"]["evidence"]["verdict"], "contradicts");
    assert_eq!([&v["orientation"]["db"], &v["orientation"]["queries"]], [100, 111]);
}

#[test]
fn shapes_that_fit_only_the_other_way_round_say_so() {
    let dir = tempfile::tempdir().unwrap();
    corridor_pair(dir.path());
    // The matrix query-major, its ground truth not: one of the two is transposed.
    let out = cli(dir.path(), &["evaluate", "--similarity", "S_t.npy", "--gt", "GT.npy"]);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "error: --similarity S_t.npy / --gt GT.npy: ground truth shape 111x100 does not match similarity shape \
         100x111; the ground truth is the similarity's transpose (|Q| x |DB| against |DB| x |Q|): one of the two \
         is stored query-major and the other not, and --query-major reads both query-major; transpose the one \
         that is\n"
    );
    // 105 calibration queries of 100, but within the 111 database images: a query-major
    // traverse of 111 queries read as |DB| x |Q|?
    let out = cli(
        dir.path(),
        &[
            "evaluate",
            "--similarity",
            "S.npy",
            "--gt",
            "GT.npy",
            "--cal-queries",
            "105",
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "error: --similarity S.npy / --gt GT.npy: the calibration set must have between 1 and 99 of the 100 \
         queries, got 105; the similarity has 111 database images but only 100 queries: if it is query-major \
         (|Q| x |DB|, as VPR-Bench stores them), pass --query-major\n"
    );
    let out = cli(
        dir.path(),
        &[
            "threshold",
            "--similarity",
            "S.npy",
            "--cal-gt",
            "GT.npy",
            "--cal-queries",
            "105",
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.ends_with(
            "queries, got 105; the similarity has 111 database images but only 100 queries: if it is \
                       query-major (|Q| x |DB|, as VPR-Bench stores them), pass --query-major\n"
        ),
        "{err}"
    );
    // Beyond both: no hint.
    let out = cli(
        dir.path(),
        &[
            "evaluate",
            "--similarity",
            "S.npy",
            "--gt",
            "GT.npy",
            "--cal-queries",
            "200",
        ],
    );
    assert!(String::from_utf8_lossy(&out.stderr).ends_with("of the 100 queries, got 200\n"));
}

/// The polylines of an SVG written by plotters, in order, as (stroke colour, number of
/// points), and the texts between them: `Err(text)` for a text, `Ok(polyline)` else.
fn svg_elements(svg: &str) -> Vec<Result<(String, usize), String>> {
    let attr = |line: &str, name: &str| -> Option<String> {
        let start = line.find(&format!(" {name}=\""))? + name.len() + 3;
        Some(line[start..start + line[start..].find('"')?].to_string())
    };
    svg.lines()
        .filter_map(|line| {
            if line.starts_with("<polyline") {
                let points = attr(line, "points").unwrap_or_default();
                Some(Ok((
                    attr(line, "stroke").unwrap_or_default(),
                    points.split_whitespace().count(),
                )))
            } else if !line.starts_with('<') && !line.trim().is_empty() {
                Some(Err(line.trim().to_string()))
            } else {
                None
            }
        })
        .collect()
}

#[test]
fn gated_threshold_lines_are_dashed_and_the_others_solid() {
    // The embedded data: quantile-transfer-margin's thresholds are quantile transfer's,
    // so its line lies on quantile transfer's and must be dashed for both to show.
    let dir = tempfile::tempdir().unwrap();
    let out = cli(dir.path(), &["evaluate", "--plot", "figs", "--format", "json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(dir.path().join("figs/thresholds.svg")).unwrap();
    let elements = svg_elements(&svg);
    // A legend entry is its swatch, drawn just before the method's name (the last run of
    // polylines of one colour before the text), then the name: one segment for a solid
    // line, several for a dashed one.
    let mut swatches: Vec<(String, Vec<(String, usize)>)> = vec![];
    let mut since_text: Vec<(String, usize)> = vec![];
    for e in &elements {
        match e {
            Ok(p) => since_text.push(p.clone()),
            Err(text) => {
                let mut run = std::mem::take(&mut since_text);
                let last = run.last().map(|(c, _)| c.clone());
                let keep = run.iter().rev().take_while(|(c, _)| Some(c) == last.as_ref()).count();
                swatches.push((text.clone(), run.split_off(run.len() - keep)));
            }
        }
    }
    let swatch = |name: &str| -> Vec<(String, usize)> {
        swatches
            .iter()
            .find(|(text, _)| text == name)
            .unwrap_or_else(|| panic!("no legend entry {name}"))
            .1
            .clone()
    };
    let colour = |name: &str| swatch(name)[0].0.clone();
    // (`margin`, whose score threshold is -inf, has no line and no entry.)
    for name in ["quantile-transfer", "quantile-transfer-margin", "schubert"] {
        let s = swatch(name);
        assert!(s.iter().all(|(c, n)| *c == s[0].0 && *n == 2), "{name}: {s:?}");
        let gated = name.ends_with("margin");
        assert_eq!(s.len() > 1, gated, "{name}'s swatch: {s:?}");
    }
    // The plotted lines (every polyline of the method's colour): quantile transfer's is
    // one polyline through every segment's ends (about 100 points); its gated twin's is
    // dashes of 2 points (3 where a dash turns a corner), many more than the legend's.
    let lines = |name: &str| -> Vec<usize> {
        let c = colour(name);
        elements
            .iter()
            .filter_map(|e| e.as_ref().ok())
            .filter(|(s, _)| *s == c)
            .map(|(_, n)| *n)
            .collect()
    };
    assert_ne!(colour("quantile-transfer"), colour("quantile-transfer-margin"));
    let solid = lines("quantile-transfer");
    assert!(solid.iter().any(|&n| n > 10), "quantile-transfer: {solid:?}");
    let dashed = lines("quantile-transfer-margin");
    assert!(
        dashed.iter().all(|&n| n <= 3) && dashed.len() > 20,
        "quantile-transfer-margin: {dashed:?}"
    );
    for name in [
        "quantile-transfer-online",
        "schubert",
        "schubert-calibrated",
        "calibration-threshold",
    ] {
        let l = lines(name);
        assert!(l.iter().any(|&n| n > 10), "{name}: {l:?}");
    }
}

/// The value of attribute `name` in one line of an SVG written by plotters.
fn svg_attr(line: &str, name: &str) -> Option<String> {
    let start = line.find(&format!(" {name}=\""))? + name.len() + 3;
    Some(line[start..start + line[start..].find('"')?].to_string())
}

/// The texts of an SVG written by plotters with the `x` of each (the text is on the
/// line after its `<text` element).
fn svg_texts(svg: &str) -> Vec<(f64, String)> {
    let lines: Vec<&str> = svg.lines().collect();
    lines
        .windows(2)
        .filter(|w| w[0].starts_with("<text"))
        .map(|w| (svg_attr(w[0], "x").unwrap().parse().unwrap(), w[1].trim().to_string()))
        .collect()
}

#[test]
fn the_three_quantile_transfer_lines_all_show() {
    // The embedded data: quantile-transfer-online's segment thresholds (its last
    // query's, whose window is the segment) and quantile-transfer-margin's are
    // quantile transfer's. Each line must leave the one beneath it visible: quantile
    // transfer's is drawn first and wider than the two drawn over it, online's is solid
    // and the gated one dashed on top of it (many short polylines).
    let dir = tempfile::tempdir().unwrap();
    let out = cli(dir.path(), &["evaluate", "--plot", "figs"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(dir.path().join("figs/thresholds.svg")).unwrap();
    // (colour, stroke width, points) of every polyline, in drawing order.
    let lines: Vec<(String, u32, usize)> = svg
        .lines()
        .filter(|l| l.starts_with("<polyline"))
        .map(|l| {
            (
                svg_attr(l, "stroke").unwrap(),
                svg_attr(l, "stroke-width").unwrap().parse().unwrap(),
                svg_attr(l, "points").unwrap().split_whitespace().count(),
            )
        })
        .collect();
    // The colours of crates/qtvpr-cli/src/plot/mod.rs: #1F77B4 quantile-transfer,
    // #17BECF online, #2CA02C margin. A plotted line has more than 2 points, or is one
    // of many dashes; a legend swatch is the last polyline of its colour.
    let first = |c: &str| lines.iter().position(|l| l.0 == c).unwrap();
    let widths = |c: &str| -> Vec<u32> { lines.iter().filter(|l| l.0 == c).map(|l| l.1).collect() };
    let (qt, online, gated) = ("#1F77B4", "#17BECF", "#2CA02C");
    assert!(
        first(qt) < first(online) && first(online) < first(gated),
        "drawing order"
    );
    let (w_qt, w_online, w_gated) = (widths(qt), widths(online), widths(gated));
    assert!(
        w_qt.iter().all(|&w| w > w_online[0] && w > w_gated[0]),
        "{w_qt:?} {w_online:?} {w_gated:?}"
    );
    let long = |c: &str| lines.iter().filter(|l| l.0 == c && l.2 > 10).count();
    assert!(long(online) >= 1, "online is solid");
    assert_eq!(long(gated), 0, "the gated line is dashed");
}

#[test]
fn ablation_points_sit_at_their_k() {
    // The embedded data, k = 1, 2, 3: each of quantile transfer's points (circles,
    // #1F77B4) of the %Segs panel is at the x of its k's tick label, and the axis is
    // log k: the label of 2 sits ln 2 / ln 3 = 0.631 of the way from 1 to 3.
    let dir = tempfile::tempdir().unwrap();
    let out = cli(dir.path(), &["evaluate", "--plot", "figs", "--k", "1,2,3"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(dir.path().join("figs/ablation_k.svg")).unwrap();
    let texts = svg_texts(&svg);
    let tick = |k: &str| {
        texts
            .iter()
            .find(|t| t.1 == k)
            .unwrap_or_else(|| panic!("no tick {k}"))
            .0
    };
    let (x1, x2, x3) = (tick("1"), tick("2"), tick("3"));
    let ratio = (x2 - x1) / (x3 - x1);
    assert!((ratio - 2f64.ln() / 3f64.ln()).abs() < 0.01, "{x1} {x2} {x3}");
    // The chart's circles (the legend's are below y = 500), left panel (x < 600).
    let xs: Vec<f64> = svg
        .lines()
        .filter(|l| l.starts_with("<circle") && svg_attr(l, "fill").as_deref() == Some("#1F77B4"))
        .filter(|l| svg_attr(l, "cy").unwrap().parse::<f64>().unwrap() < 500.0)
        .map(|l| svg_attr(l, "cx").unwrap().parse().unwrap())
        .filter(|&x: &f64| x < 600.0)
        .collect();
    assert_eq!(xs.len(), 3, "{xs:?}");
    for (x, k) in xs.iter().zip([x1, x2, x3]) {
        assert!((x - k).abs() <= 1.0, "a point at {x}, its k at {k}");
    }
}

#[test]
fn scores_figure_shows_right_and_wrong_and_each_threshold() {
    // Full segments d0..d3 (single): best matches 0.7 T, 0.6 F, 0.5 F, 0.9 F, in 40
    // bins of 0.5..0.9 (0.01 wide): one right bar, three wrong ones (bins 0, 10, 39).
    // Legend, 3 decimals (the axis's 1 plus 2): Schubert's segment thresholds 1.808 and
    // 1.406, lower median 1.406; the oracle's 0.7 (segment 0: 0.7 T then 0.6 F at tau
    // 0.5) and reject-all (segment 1 has no positive), lower median 0.7.
    let case = Case::new();
    let dir = case.path("figs");
    case.ok(&["--plot", dir.to_str().unwrap()]);
    let svg = std::fs::read_to_string(dir.join("scores.svg")).unwrap();
    let bars = |fill: &str| {
        svg.lines()
            .filter(|l| l.starts_with("<rect") && svg_attr(l, "fill").as_deref() == Some(fill))
            .filter(|l| svg_attr(l, "opacity").as_deref() == Some("0.85"))
            .count()
    };
    assert_eq!((bars("#4DAF4A"), bars("#E41A1C")), (1, 3), "{svg}");
    let texts: Vec<String> = svg_texts(&svg).into_iter().map(|t| t.1).collect();
    for want in [
        "schubert: 1.406 (median of its 2 segments)",
        "oracle: 0.700 (median of its 2 segments)",
        "margin: no score threshold (the gate alone)",
        "right best matches (up)",
    ] {
        assert!(texts.iter().any(|t| t == want), "no {want:?} in {texts:?}");
    }
    // A gated method's line is its threshold; the note says its gates decide too.
    let note = "it accepts scores at or right of it that its gates (if any) pass;";
    assert!(texts.iter().any(|t| t.contains(note)), "no {note:?} in {texts:?}");
    // Segments of one: the oracle's thresholds are 0.7 (d0), then reject-all (d1's
    // best match is wrong; d2, d3 and d4 have no positive): median reject-all, no line.
    case.ok(&[
        "--plot",
        dir.to_str().unwrap(),
        "--segment-size",
        "1",
        "--method",
        "oracle",
    ]);
    let svg = std::fs::read_to_string(dir.join("scores.svg")).unwrap();
    assert!(
        svg.contains("oracle: reject-all in most of its 5 segments (not drawn)"),
        "{svg}"
    );
    // No dashed black line: the only black polylines are the axes and the zero line.
    let black = svg
        .lines()
        .filter(|l| l.starts_with("<polyline") && svg_attr(l, "stroke").as_deref() == Some("#000000"))
        .filter(|l| svg_attr(l, "stroke-width").as_deref() == Some("2"))
        .count();
    assert_eq!(black, 0, "{svg}");
    // Multi matching: every candidate, named as such.
    case.ok(&["--plot", dir.to_str().unwrap(), "--matching", "multi"]);
    let svg = std::fs::read_to_string(dir.join("scores.svg")).unwrap();
    assert!(svg.contains("right candidates (up)"), "{svg}");
}
