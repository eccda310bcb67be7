//! Semantics §14 on real data: the embedded VPR-Bench Corridor matrices (`data/corridor`,
//! AMOSNet, float64). The expected blocks were computed outside the library: margins by
//! NumPy (`(s1 - s2) / std`), the pool-adjacent-violators fit by a separate loop in
//! exact integer comparisons, and each Clopper-Pearson bound by bisection (60 steps, in
//! exact rational arithmetic) of `P(Binomial(n, p) >= x) = 0.05` for `p`.
#![cfg(feature = "npy")]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use qtvpr::npy::{read_ground_truth, read_scores};
use qtvpr::{Calibration, Gate, Matching, Online, OnlineParams, Params};

fn corridor(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/corridor")
        .join(name)
}

fn calibration(s: &str, gt: &str, matching: Matching) -> Calibration {
    let s = read_scores(&corridor(s)).unwrap();
    let gt = read_ground_truth(&corridor(gt), None).unwrap();
    qtvpr::with_scores!(s.view(), |v| Calibration::new(v, &gt, matching)).unwrap()
}

#[test]
fn corridor_blocks_by_hand() {
    // The 100 deployment queries as a calibration: 83 best matches are right.
    let cal = calibration("deploy_S.npy", "deploy_GT.npy", Matching::Single);
    let map = cal.confidence_map().unwrap();
    // (lowest margin, n, x, Clopper-Pearson lower bound).
    let want = [
        (0.001_885_275_068_079_086_5, 2, 0, 0.0),
        (0.012_858_028_793_346_37, 2, 1, 0.025_320_565_519_103_61), // 1 - sqrt(0.95)
        (0.018_834_932_764_100_636, 31, 24, 0.617_389_769_083_018),
        (0.143_073_607_179_773_13, 25, 20, 0.624_594_864_875_121_8),
        (0.242_488_391_311_626_33, 28, 26, 0.791_795_286_820_588),
        (0.458_727_958_161_801_84, 12, 12, 0.779_077_808_054_444), // 0.05^(1/12)
    ];
    let got = map.blocks();
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (b, &(margin, n, x, lower)) in got.iter().zip(&want) {
        assert!((b.margin - margin).abs() < 1e-12 * margin, "{b:?}");
        assert_eq!((b.n, b.x), (n, x), "{b:?}");
        assert_eq!(map.confidence(b.margin), x as f64 / n as f64);
        assert!((map.confidence_lower95(b.margin) - lower).abs() < 1e-9, "{b:?}");
    }
    // Between blocks: the block below; below them all: the first; far above: the last.
    assert_eq!(map.confidence(0.2), 0.8);
    assert_eq!(map.confidence(0.0), 0.0);
    assert_eq!(map.confidence(50.0), 1.0);
    // The bound is not monotone where a block is small: 26 of 28 is surer than 12 of 12.
    assert!(map.confidence_lower95(0.3) > map.confidence_lower95(1.0));
}

#[test]
fn corridor_calibration_is_one_block() {
    // The embedded calibration's 11 best matches are all right: one block, 11 of 11,
    // bound 0.05^(1/11) = exp(-2.995732 / 11) = 0.761596.
    let cal = calibration("cal_S.npy", "cal_GT.npy", Matching::Single);
    let map = cal.confidence_map().unwrap();
    assert_eq!(map.blocks().len(), 1);
    assert_eq!((map.blocks()[0].n, map.blocks()[0].x), (11, 11));
    assert!((map.confidence_lower95(0.0) - 0.761_595_809_6).abs() < 1e-9);
}

#[test]
fn every_decision_carries_its_confidence() {
    // Calibrate on the deployment half (whose map has six blocks) and decide the
    // embedded calibration's queries: online (gated or not) and in a batch alike, each
    // carries the map's value at its margin.
    let cal = Arc::new(calibration("deploy_S.npy", "deploy_GT.npy", Matching::Single));
    let s = read_scores(&corridor("cal_S.npy")).unwrap();
    let margins = qtvpr::with_scores!(s.view(), |v| qtvpr::margins(v)).unwrap();
    let map = cal.confidence_map().unwrap();
    for gate in [Gate::None, Gate::Margin] {
        let p = OnlineParams {
            k: 5,
            precision: 1.0,
            window: 4,
            min_window: 1,
            gate,
        };
        let mut online = Online::new(Arc::clone(&cal), p).unwrap();
        let decisions = qtvpr::with_scores!(s.view(), |v| online.push_many(v)).unwrap();
        let params = Params {
            k: 5,
            precision: 1.0,
            segment_size: Some(4),
            gate,
        };
        let batch = qtvpr::with_scores!(s.view(), |v| cal.transfer(v, &params)).unwrap();
        let (c, lower) = (
            batch.query_confidences.unwrap(),
            batch.query_confidences_lower95.unwrap(),
        );
        for (j, d) in decisions.iter().enumerate() {
            assert_eq!(d.confidence, map.confidence(margins[j]), "{gate} {j}");
            assert_eq!(d.confidence_lower95, map.confidence_lower95(margins[j]));
            assert_eq!((c[j], lower[j]), (d.confidence, d.confidence_lower95));
            assert_eq!(d.margin.is_some(), gate == Gate::Margin);
        }
        // Margins 0.0026 .. 0.98 span the map: not every query has the same value.
        assert!(decisions.iter().any(|d| d.confidence < 0.8) && decisions.iter().any(|d| d.confidence == 1.0));
        #[cfg(feature = "serde")]
        {
            let json = serde_json::to_value(decisions[0]).unwrap();
            assert_eq!(json["confidence"].as_f64(), Some(decisions[0].confidence));
        }
    }
}

#[test]
fn multi_matching_has_none() {
    let cal = Arc::new(calibration("cal_S.npy", "cal_GT.npy", Matching::Multi));
    assert!(
        cal.confidence_map()
            .unwrap_err()
            .to_string()
            .starts_with("confidence needs single matching")
    );
    let p = OnlineParams {
        k: 5,
        precision: 1.0,
        window: 4,
        min_window: 1,
        gate: Gate::None,
    };
    let s = read_scores(&corridor("deploy_S.npy")).unwrap();
    let mut online = Online::new(Arc::clone(&cal), p).unwrap();
    let d = qtvpr::with_scores!(s.view(), |v| online.push(v.column(0))).unwrap();
    assert!(d.confidence.is_nan() && d.confidence_lower95.is_nan());
    #[cfg(feature = "serde")]
    {
        let json = serde_json::to_value(d).unwrap();
        assert!(json["confidence"].is_null() && json["confidence_lower95"].is_null());
    }
    let params = Params {
        k: 5,
        precision: 1.0,
        segment_size: Some(20),
        gate: Gate::None,
    };
    let batch = qtvpr::with_scores!(s.view(), |v| cal.transfer(v, &params)).unwrap();
    assert!(batch.query_confidences.is_none() && batch.query_confidences_lower95.is_none());
}
