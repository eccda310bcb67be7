//! One recorded traverse split by `--cal-queries` / `--cal-fraction` (issue 49, item 8):
//! `calibrate --similarity` calibrates on its first queries as `threshold --similarity`
//! does, and `stream --val` skips them, with the same options, help and errors in all
//! three commands (`SplitArgs`, the core's `QuerySplit`).

use std::path::Path;

use ndarray::{Array2, Axis, concatenate};
use qtvpr::npy::{read_ground_truth, read_scores, write_npy};
use qtvpr::{ScoresView, Truth};

use crate::common::{assert_clean_failure, npy_bool, ok_in, run_in};

/// The embedded Corridor traverse as one recording in `dir`: `S.npy` (111 x 111, the 11
/// calibration queries then the 100 deployment queries) and `GT.npy`, and the two
/// halves as they are stored (`cal_S.npy`, `cal_GT.npy`, `deploy_S.npy`).
fn one_traverse(dir: &Path) {
    let corridor = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/corridor");
    let scores = |name: &str| match read_scores(&corridor.join(name)).unwrap().view() {
        ScoresView::F64(v) => v.to_owned(),
        ScoresView::F32(_) => unreachable!("the embedded scores are float64"),
    };
    let truth = |name: &str| -> Array2<u8> {
        let gt = read_ground_truth(&corridor.join(name), None).unwrap();
        gt.view().mapv(|t| u8::from(t == Truth::True))
    };
    let (s_cal, s_dep) = (scores("cal_S.npy"), scores("deploy_S.npy"));
    let s = concatenate(Axis(1), &[s_cal.view(), s_dep.view()]).unwrap();
    let gt = concatenate(Axis(1), &[truth("cal_GT.npy").view(), truth("deploy_GT.npy").view()]).unwrap();
    write_npy(&dir.join("S.npy"), s.view()).unwrap();
    let rows: Vec<Vec<u8>> = gt.rows().into_iter().map(|r| r.to_vec()).collect();
    npy_bool(&dir.join("GT.npy"), &rows.iter().map(Vec::as_slice).collect::<Vec<_>>());
    for name in ["cal_S.npy", "cal_GT.npy", "deploy_S.npy"] {
        std::fs::copy(corridor.join(name), dir.join(name)).unwrap();
    }
}

#[test]
fn calibrate_and_stream_split_one_traverse_as_threshold_does() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_traverse(d);
    // The first 11 queries (--cal-queries 11, or floor(0.1 x 111) = 11) are the
    // calibration traverse cal_S.npy: the same calibration as from the two files.
    ok_in(
        d,
        &[
            "calibrate",
            "--cal",
            "cal_S.npy",
            "--cal-gt",
            "cal_GT.npy",
            "--window",
            "28",
            "-o",
            "two.npz",
        ],
    );
    for (flag, value) in [("--cal-queries", "11"), ("--cal-fraction", "0.1")] {
        ok_in(
            d,
            &[
                "calibrate",
                "--similarity",
                "S.npy",
                "--cal-gt",
                "GT.npy",
                flag,
                value,
                "--window",
                "28",
                "-o",
                "one.npz",
            ],
        );
        let (one, two) = (
            std::fs::read(d.join("one.npz")).unwrap(),
            std::fs::read(d.join("two.npz")).unwrap(),
        );
        assert!(one == two, "{flag}: the calibration files differ");
        // stream skips the 11 calibration columns of the one traverse: its lines are
        // those of the 100 deployment queries streamed alone, from query 0.
        let alone = ok_in(d, &["stream", "--calibration", "two.npz", "--val", "deploy_S.npy"]);
        let skipped = ok_in(
            d,
            &["stream", "--calibration", "one.npz", "--val", "S.npy", flag, value],
        );
        assert_eq!(skipped.lines().count(), 100);
        assert!(skipped.starts_with("{\"query\":0,"), "{skipped}");
        assert_eq!(skipped, alone, "{flag}");
    }
    // threshold splits the same way: its thresholds are those of the two files.
    let split = ok_in(
        d,
        &[
            "threshold",
            "--similarity",
            "S.npy",
            "--cal-gt",
            "GT.npy",
            "--cal-queries",
            "11",
        ],
    );
    let two = ok_in(
        d,
        &[
            "threshold",
            "--cal",
            "cal_S.npy",
            "--cal-gt",
            "cal_GT.npy",
            "--val",
            "deploy_S.npy",
        ],
    );
    let segments = |text: &str| serde_json::from_str::<serde_json::Value>(text).unwrap()["segments"].clone();
    assert_eq!(segments(&split), segments(&two));
}

#[test]
fn the_split_is_refused_alike_in_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_traverse(d);
    ok_in(
        d,
        &[
            "calibrate",
            "--cal",
            "cal_S.npy",
            "--cal-gt",
            "cal_GT.npy",
            "--window",
            "28",
            "-o",
            "cal.npz",
        ],
    );
    let commands: [&[&str]; 3] = [
        &["threshold", "--similarity", "S.npy", "--cal-gt", "GT.npy", "-o", "out"],
        &["calibrate", "--similarity", "S.npy", "--cal-gt", "GT.npy", "-o", "out"],
        &["stream", "--calibration", "cal.npz", "--val", "S.npy", "-o", "out"],
    ];
    let out = d.join("out");
    for command in commands {
        let run = |extra: &[&str]| run_in(d, &[command, extra].concat());
        // Checked before any file is read: the same words, naming the option.
        assert_clean_failure(
            &run(&["--cal-queries", "0"]),
            d,
            &[&out],
            &["error: --cal-queries: cal queries must be >= 1, got 0"],
        );
        assert_clean_failure(
            &run(&["--cal-fraction", "1.5"]),
            d,
            &[&out],
            &["error: --cal-fraction: cal fraction must be in (0, 1), got 1.5"],
        );
        // Beyond the matrix's 111 queries: named with the option and the file.
        assert_clean_failure(
            &run(&["--cal-queries", "111"]),
            d,
            &[&out],
            &[
                "--cal-queries of --",
                " S.npy: the calibration set must have between 1 and 110 of the 111 queries, got 111",
            ],
        );
        // Both at once: clap's usage error (exit 2).
        let both = run(&["--cal-queries", "11", "--cal-fraction", "0.1"]);
        assert_eq!(both.status.code(), Some(2));
        assert!(
            String::from_utf8_lossy(&both.stderr).contains("cannot be used with"),
            "{command:?}"
        );
    }
    // stream: a split that skips other columns than the calibration's 11.
    assert_clean_failure(
        &run_in(
            d,
            &[
                "stream",
                "--calibration",
                "cal.npz",
                "--val",
                "S.npy",
                "--cal-queries",
                "10",
                "-o",
                "out",
            ],
        ),
        d,
        &[&out],
        &[
            "error: --cal-queries of --val S.npy / --calibration cal.npz: the split makes the first 10 queries the \
           calibration queries, but the calibration holds 11: skip the queries it was calibrated on",
        ],
    );
    // calibrate: --similarity needs the split; --cal is a calibration traverse already.
    let no_split = run_in(
        d,
        &["calibrate", "--similarity", "S.npy", "--cal-gt", "GT.npy", "-o", "out"],
    );
    assert_eq!(no_split.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&no_split.stderr).contains("--cal-queries <N>"),
        "{no_split:?}"
    );
    let cal_split = run_in(
        d,
        &[
            "calibrate",
            "--cal",
            "cal_S.npy",
            "--cal-gt",
            "cal_GT.npy",
            "--cal-queries",
            "5",
            "-o",
            "out",
        ],
    );
    assert_eq!(cal_split.status.code(), Some(2));
    assert!(!out.exists());
}

#[test]
fn the_split_options_are_explained_once() {
    // The same help text in every command that reads a traverse (clap's long help).
    let help = |command: &str| -> String {
        let out = run_in(Path::new("."), &[command, "--help"]);
        let text = String::from_utf8(out.stdout).unwrap();
        let start = text
            .find("      --cal-queries <N>")
            .unwrap_or_else(|| panic!("{command}: no --cal-queries"));
        let end = start + text[start..].find("      --cal-fraction <F>").unwrap();
        let end = end + text[end..].find("\n\n").unwrap();
        text[start..end].to_string()
    };
    let threshold = help("threshold");
    assert!(threshold.contains("stream` skips them"), "{threshold}");
    assert_eq!(help("calibrate"), threshold);
    assert_eq!(help("stream"), threshold);
}
