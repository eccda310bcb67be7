//! Every `.npz` the CLI is handed (issue 35): the hostile set of the core's tests
//! (`crates/qtvpr-testkit/src/zip.rs`) as a calibration file and as a ground truth,
//! a calibration too large for an address-space cap, and the outputs' edges (a closed
//! standard output, an empty deployment input, a file overwritten keeps its mode).

use std::path::Path;
use std::process::Output;

use ndarray::{Array2, array};
use qtvpr::npy::{NpyArray, write_npy, write_npz};
use qtvpr::{Calibration, Defaults, GroundTruth, Matching};

use crate::common::zip::{Member, Members, hostile, npy_header, unzip, zip};
use crate::common::{ok_in, run_in};

/// A 3x4 calibration's `.npy` members and a VPR_Tutorial ground truth's, and the files
/// they come from (`cal.npy`, `gt.npz`, `cal.npz`) with a deployment `val.npy`, in `dir`.
fn valid(dir: &Path) -> (Members, Members) {
    let (s, hard, soft) = crate::common::zip::traverse();
    write_npy(&dir.join("cal.npy"), s.view()).unwrap();
    write_npy(&dir.join("val.npy"), array![[0.5, 0.1], [0.2, 0.9], [0.3, 0.3]].view()).unwrap();
    write_npz(
        &dir.join("gt.npz"),
        &[
            ("GThard", NpyArray::Bool(hard.view())),
            ("GTsoft", NpyArray::Bool(soft.view())),
        ],
    )
    .unwrap();
    let gt = GroundTruth::new(hard.view()).unwrap().with_soft(soft.view()).unwrap();
    let cal = Calibration::new(s.view(), &gt, Matching::Single).unwrap();
    let bytes = cal.to_bytes(&Defaults::default()).unwrap();
    std::fs::write(dir.join("cal.npz"), &bytes).unwrap();
    (unzip(&bytes), unzip(&std::fs::read(dir.join("gt.npz")).unwrap()))
}

/// `stream` on `valid`'s calibration file and deployment matrix.
const STREAM: [&str; 7] = [
    "stream",
    "--calibration",
    "cal.npz",
    "--val",
    "val.npy",
    "--window",
    "2",
];

/// Exit 2 with one line that holds every needle, no panic.
fn refused(out: &Output, needles: &[&str], what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{what}: {:?} {stderr}", out.status);
    assert_eq!(stderr.lines().count(), 1, "{what}: {stderr}");
    assert!(!stderr.contains("panicked"), "{what}: {stderr}");
    for needle in needles {
        assert!(stderr.contains(needle), "{what}: {needle:?} not in {stderr}");
    }
}

/// The hostile set, as `stream --calibration` and as `threshold --cal-gt` and
/// `evaluate --gt`: exit 2, one line naming the file and the member, never a panic.
#[test]
fn every_hostile_npz_exits_2_as_calibration_and_as_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (cal, tutorial) = valid(d);
    // The files are good to begin with.
    ok_in(d, &STREAM);
    ok_in(
        d,
        &[
            "threshold",
            "--cal",
            "cal.npy",
            "--cal-gt",
            "gt.npz",
            "--val",
            "val.npy",
        ],
    );
    let members = |m: &[(String, Vec<u8>)]| m.iter().map(|(n, d)| (n.clone(), d.clone())).collect::<Vec<_>>();
    for (set, descr) in [(members(&cal), "<f8"), (members(&tutorial), "|b1")] {
        let refs: Vec<(&str, &[u8])> = set.iter().map(|(n, d)| (n.as_str(), d.as_slice())).collect();
        for h in hostile(&refs, descr, (3, 4), 24) {
            std::fs::write(d.join("h.npz"), &h.bytes).unwrap();
            let runs: Vec<Vec<&str>> = if descr == "<f8" {
                vec![vec![
                    "stream",
                    "--calibration",
                    "h.npz",
                    "--val",
                    "val.npy",
                    "--window",
                    "2",
                ]]
            } else {
                vec![
                    vec!["threshold", "--cal", "cal.npy", "--cal-gt", "h.npz", "--val", "val.npy"],
                    vec![
                        "evaluate",
                        "--similarity",
                        "cal.npy",
                        "--gt",
                        "h.npz",
                        "--cal-queries",
                        "2",
                    ],
                ]
            };
            for args in runs {
                refused(
                    &run_in(d, &args),
                    &["h.npz", &h.error],
                    &format!("{args:?}, {}", h.case),
                );
            }
        }
    }
}

/// `qtvpr-cli` with `args` in `dir`, under `ulimit -v 1000000` (1 GB of address space)
/// when `cap`, its standard output redirected as `redirect` says (e.g. `>&-`).
fn run_shell(dir: &Path, cap: bool, redirect: &str, args: &[&str]) -> Output {
    crate::common::run_in_shell(dir, if cap { crate::common::CAP } else { "" }, redirect, args)
}

/// A calibration of 60 x 1,000,000 float64 zeros (480 MB; 0.5 MB deflated) whose
/// members agree: a valid file that does not fit under a 1 GB cap with its sorted
/// profiles. Loading it is "cannot allocate", exit 2, never an abort; the same matrix
/// as `--cal` (mapped) and as ground truth.
#[test]
fn a_calibration_too_large_for_memory_is_an_error_not_an_abort() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (db, queries) = (1_000_000usize, 60usize);
    let mut s = npy_header("<f8", &format!("({db}, {queries})"));
    s.resize(s.len() + db * queries * 8, 0);
    let mut gt = npy_header("|b1", &format!("({db}, {queries})"));
    gt.resize(gt.len() + db * queries, 0);
    let meta = r#"{"format": "qtvpr-calibration", "version": 1, "matching": "single", "params": {"k": 1, "precision": 1.0, "window": null}}"#;
    let mut m = npy_header(&format!("<U{}", meta.len()), "()");
    m.extend(meta.chars().flat_map(|c| (c as u32).to_le_bytes()));
    let big = zip(&[
        Member::deflated("s.npy", &s),
        Member::deflated("gt.npy", &gt),
        Member::stored("meta.npy", &m),
    ]);
    assert!(big.len() < 1 << 20, "{}", big.len());
    std::fs::write(d.join("big.npz"), big).unwrap();
    std::fs::write(d.join("big_s.npy"), &s).unwrap();
    drop((s, gt));
    write_npy(&d.join("val.npy"), Array2::<f64>::zeros((3, 2)).view()).unwrap();
    let stream = [
        "stream",
        "--calibration",
        "big.npz",
        "--val",
        "val.npy",
        "--window",
        "2",
    ];
    refused(
        &run_shell(d, true, "", &stream),
        &["big.npz", "cannot allocate"],
        "stream",
    );
    let threshold = ["threshold", "--cal", "big.npz", "--val", "val.npy"];
    refused(
        &run_shell(d, true, "", &threshold),
        &["big.npz", "cannot allocate"],
        "threshold",
    );
}

/// `>&-`: an error (exit 2, one line), not a silent exit 0 with every line lost.
#[test]
fn a_closed_standard_output_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    valid(d);
    for args in [&STREAM[..], &["threshold", "--cal", "cal.npz", "--val", "val.npy"][..]] {
        let out = run_shell(d, false, ">&-", args);
        refused(&out, &["standard output: is closed"], &format!("{args:?}"));
        // Redirected to a file: exit 0, every line there.
        assert!(run_shell(d, false, ">out.txt", args).status.success(), "{args:?}");
        assert!(!std::fs::read(d.join("out.txt")).unwrap().is_empty(), "{args:?}");
    }
}

/// A deployment input of no query is refused by `stream` as by `threshold`.
#[test]
fn an_empty_deployment_input_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    valid(d);
    write_npy(&d.join("empty.npy"), Array2::<f64>::zeros((3, 0)).view()).unwrap();
    for command in ["stream", "threshold"] {
        let args = match command {
            "stream" => &[
                "stream",
                "--calibration",
                "cal.npz",
                "--val",
                "empty.npy",
                "--window",
                "2",
            ][..],
            _ => &["threshold", "--cal", "cal.npz", "--val", "empty.npy"][..],
        };
        let out = run_in(d, args);
        refused(
            &out,
            &["--val empty.npy", "deployment similarity is empty (shape 3x0)"],
            command,
        );
        assert!(out.stdout.is_empty(), "{command}");
    }
}

/// An output overwritten keeps its mode (a private 0600 file stays private) and a new
/// one gets the plain-create mode.
#[test]
fn an_overwritten_output_keeps_its_mode() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    valid(d);
    let mode = |name: &str| std::fs::metadata(d.join(name)).unwrap().permissions().mode() & 0o7777;
    for (name, args) in [
        (
            "out.json",
            &["threshold", "--cal", "cal.npz", "--val", "val.npy", "-o", "out.json"][..],
        ),
        (
            "new.npz",
            &["calibrate", "--cal", "cal.npy", "--cal-gt", "gt.npz", "-o", "new.npz"][..],
        ),
    ] {
        ok_in(d, args);
        let fresh = mode(name);
        for private in [0o600, 0o640] {
            std::fs::set_permissions(d.join(name), std::fs::Permissions::from_mode(private)).unwrap();
            ok_in(d, args);
            assert_eq!(mode(name), private, "{name}");
        }
        std::fs::remove_file(d.join(name)).unwrap();
        ok_in(d, args);
        assert_eq!(mode(name), fresh, "{name}");
    }
}
