//! Online thresholds (semantics §11) on real VPR-Bench matrices in `../shared/data`:
//! every query's threshold equals the batch transfer of just its window's columns, bit
//! for bit, in both matching modes, for f32 and f64 input; and a calibration saved and
//! loaded gives the same decisions.
#![cfg(feature = "npy")]

use qtvpr_testkit::data;
use std::sync::Arc;

use ndarray::{ArrayView2, s};
use qtvpr::ScoresView;
use qtvpr::npy::{read_ground_truth, read_scores};
use qtvpr::{Calibration, Defaults, Gate, GroundTruth, Matching, Online, OnlineParams, Params, Score};

/// Calibrate on the first `n_cal` queries, stream the rest through `Online`, and check
/// every decision against `transfer` on the window's columns.
fn check<T: Score>(s: ArrayView2<'_, T>, gt: &GroundTruth, n_cal: usize, matching: Matching, p: OnlineParams) {
    let gt_cal = GroundTruth::from_truth(gt.view().slice(s![.., ..n_cal]).to_owned());
    let cal = Arc::new(Calibration::new(s.slice(s![.., ..n_cal]), &gt_cal, matching).unwrap());
    let s_val = s.slice(s![.., n_cal..]);
    let decisions = Online::new(Arc::clone(&cal), p).unwrap().push_many(s_val).unwrap();
    let params = Params {
        k: p.k,
        precision: p.precision,
        segment_size: None,
        gate: Gate::None,
        sequence_gate: Default::default(),
    };
    for (j, d) in decisions.iter().enumerate() {
        if j + 1 < p.min_window {
            assert_eq!(d.quantile, 1.0);
            continue;
        }
        let window = cal
            .transfer(s_val.slice(s![.., (j + 1).saturating_sub(p.window)..=j]), &params)
            .unwrap();
        let g = window.segments[0];
        assert_eq!(
            (d.quantile.to_bits(), d.threshold.to_bits()),
            (g.quantile.to_bits(), g.threshold.to_bits()),
            "query {j}: {d:?} vs {g:?}"
        );
    }
    // Save, load, and stream again: the same decisions.
    let bytes = cal.to_bytes(&Defaults::default()).unwrap();
    let loaded = Arc::new(Calibration::from_bytes(&bytes, "cal.npz").unwrap());
    assert_eq!(Online::new(loaded, p).unwrap().push_many(s_val).unwrap(), decisions);
}

fn run(dir: &str, technique: &str, n_cal: usize) {
    let (Some(scores), Some(gt)) = (
        data::shared(&format!("{dir}/S_{technique}.npy")),
        data::shared(&format!("{dir}/GT.npy")),
    ) else {
        return;
    };
    let scores = read_scores(&scores).unwrap();
    let gt = read_ground_truth(&gt, None).unwrap();
    for matching in [Matching::Single, Matching::Multi] {
        for (window, min_window, precision) in [(1, 1, 1.0), (11, 1, 1.0), (7, 4, 0.9), (1000, 1, 1.0)] {
            let p = OnlineParams {
                k: 10,
                precision,
                window,
                min_window,
                gate: Gate::None,
                sequence_gate: Default::default(),
            };
            match scores.view() {
                ScoresView::F32(v) => check(v, &gt, n_cal, matching, p),
                ScoresView::F64(v) => check(v, &gt, n_cal, matching, p),
            }
        }
    }
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (NetVLAD, f64): Online = the batch of each window"]
fn corridor_float64() {
    run("vprbench-corridor", "NetVLAD", 11);
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (CoHOG, f32): Online = the batch of each window"]
fn corridor_float32() {
    run("vprbench-corridor", "CoHOG", 11);
}

#[test]
#[ignore = "needs ../shared/data vprbench-spedtest (CALC, f32): Online = the batch of each window"]
fn spedtest_float32() {
    run("vprbench-spedtest", "CALC", 60);
}
