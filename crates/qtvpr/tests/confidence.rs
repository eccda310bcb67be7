//! Semantics §14 on real data: the embedded VPR-Bench Corridor matrices (`data/corridor`,
//! AMOSNet, float64). The expected blocks were computed outside the library, by the
//! NumPy reference (`py/qtvpr/reference.py`): PA-scores from `np.sort`, the two pooling
//! passes as separate loops in exact integer comparisons, and each Clopper-Pearson
//! bound by its own bisection.
#![cfg(feature = "npy")]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use qtvpr::npy::{read_ground_truth, read_scores};
use qtvpr::{Calibration, Gate, Matching, Online, OnlineParams, Params, Score};

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
    // The 100 deployment queries as a calibration: 83 best matches are right. Their
    // PA-scores lie in [0.964, 0.99996]: AMOSNet's scores are close to 1.
    let cal = calibration("deploy_S.npy", "deploy_GT.npy", Matching::Single);
    let map = cal.confidence_map().unwrap();
    // (centre, n, x, Clopper-Pearson lower bound), by ascending confidence.
    let want = [
        (0.999_953_119_130_735_6, 2, 0, 0.0),
        (0.999_615_800_864_814_6, 2, 1, 0.025_320_565_519_103_61), // 1 - sqrt(0.95)
        (0.999_130_857_079_570_5, 6, 4, 0.271_338_372_519_752_35),
        (0.997_262_411_462_848_8, 21, 15, 0.512_611_208_301_130_5),
        (0.995_185_342_819_018_6, 13, 11, 0.589_901_395_166_184),
        (0.992_913_055_641_084_2, 17, 15, 0.673_806_936_916_521_6),
        (0.989_716_457_042_989_8, 12, 11, 0.661_319_331_565_967_8),
        (0.985_079_121_383_379_5, 16, 15, 0.736_042_602_711_431_5),
        (0.975_029_549_984_444, 11, 11, 0.761_595_809_619_147_3), // 0.05^(1/11)
    ];
    let got = map.blocks();
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (b, &(centre, n, x, lower)) in got.iter().zip(&want) {
        assert!((b.pa_score - centre).abs() < 1e-12, "{b:?}");
        assert_eq!((b.n, b.x), (n, x), "{b:?}");
        // At its centre the map is the block's Laplace value, with its bound.
        assert!((map.confidence(b.pa_score) - (x + 1) as f64 / (n + 2) as f64).abs() < 1e-12);
        assert!((map.confidence_lower95(b.pa_score) - lower).abs() < 1e-9, "{b:?}");
    }
    // Between centres, linear; beyond the first, on to its lower bound 0 at PA-score
    // 1; beyond the last, on to 11 of 11's upper bound, 1, at 0.
    assert!((map.confidence(0.99) - 0.855_809_000_628_199_2).abs() < 1e-9);
    assert!((map.confidence(0.5) - 0.960_553_463_777_429).abs() < 1e-9);
    assert_eq!((map.confidence(1.0), map.confidence(0.0)), (0.0, 1.0));
    // The bound is not monotone where a block is small: 15 of 17 is surer than 11 of 12.
    assert!(map.confidence_lower95(0.9925) > map.confidence_lower95(0.989));
}

#[test]
fn corridor_calibration_is_one_block_and_still_ranks() {
    // The embedded calibration's 11 best matches are all right: one block, 11 of 11,
    // value 12/13, bound 0.05^(1/11) = exp(-2.995732 / 11) = 0.761596.
    let cal = calibration("cal_S.npy", "cal_GT.npy", Matching::Single);
    let map = cal.confidence_map().unwrap();
    assert_eq!(map.blocks().len(), 1);
    assert_eq!((map.blocks()[0].n, map.blocks()[0].x), (11, 11));
    assert!((map.confidence_lower95(0.0) - 0.761_595_809_6).abs() < 1e-9);
    // One block, and yet no two PA-scores share a confidence: from the bound at 1,
    // through 12/13 at the centre, to 1 at 0.
    assert!((map.confidence(1.0) - 0.761_595_809_6).abs() < 1e-9);
    assert!((map.confidence(0.99) - 0.923_133_589_086_206_6).abs() < 1e-9);
    assert!((map.confidence(0.5) - 0.961_178_580_346_569).abs() < 1e-9);
    assert!(map.confidence(0.999) < map.confidence(0.998));
}

#[test]
fn every_decision_carries_its_confidence() {
    // Calibrate on the deployment half (whose map has nine blocks) and decide the
    // embedded calibration's queries: online (gated or not) and in a batch alike, each
    // carries the map's value at its PA-score.
    let cal = Arc::new(calibration("deploy_S.npy", "deploy_GT.npy", Matching::Single));
    let s = read_scores(&corridor("cal_S.npy")).unwrap();
    let pa_scores: Vec<f64> = qtvpr::with_scores!(s.view(), |v| {
        v.columns()
            .into_iter()
            .map(|c| {
                let mut c: Vec<f64> = c.iter().map(|x| x.to_f64()).collect();
                c.sort_by(f64::total_cmp);
                qtvpr::pa_score(c[c.len() - 1], c[c.len() - 2])
            })
            .collect()
    });
    let map = cal.confidence_map().unwrap();
    for gate in [Gate::None, Gate::Margin] {
        let p = OnlineParams {
            k: 5,
            precision: 1.0,
            window: 4,
            min_window: 1,
            gate,
            sequence_gate: Default::default(),
        };
        let mut online = Online::new(Arc::clone(&cal), p).unwrap();
        let decisions = qtvpr::with_scores!(s.view(), |v| online.push_many(v)).unwrap();
        let params = Params {
            k: 5,
            precision: 1.0,
            segment_size: Some(4),
            gate,
            sequence_gate: Default::default(),
        };
        let batch = qtvpr::with_scores!(s.view(), |v| cal.transfer(v, &params)).unwrap();
        let (c, lower) = (
            batch.query_confidences.unwrap(),
            batch.query_confidences_lower95.unwrap(),
        );
        for (j, d) in decisions.iter().enumerate() {
            assert_eq!(d.confidence, map.confidence(pa_scores[j]), "{gate} {j}");
            assert_eq!(d.confidence_lower95, map.confidence_lower95(pa_scores[j]));
            assert_eq!((c[j], lower[j]), (d.confidence, d.confidence_lower95));
            assert_eq!(d.margin.is_some(), gate == Gate::Margin);
        }
        // The 11 PA-scores, all distinct, give 11 distinct confidences.
        let mut distinct: Vec<f64> = decisions.iter().map(|d| d.confidence).collect();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup();
        assert_eq!(distinct.len(), 11);
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
        sequence_gate: Default::default(),
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
        sequence_gate: Default::default(),
    };
    let batch = qtvpr::with_scores!(s.view(), |v| cal.transfer(v, &params)).unwrap();
    assert!(batch.query_confidences.is_none() && batch.query_confidences_lower95.is_none());
}

#[test]
fn a_calibration_query_of_extreme_scores_leaves_the_map_finite() {
    // Issue 49: a score at or below about -9e307 overflowed 2 - 2 s, the PA-score of
    // its column was inf / inf = NaN, and NaN centres made every confidence NaN. With
    // d = sqrt((1 - s) / 2): column 2 (all -f64::MAX, best row 0, wrong) has PA-score 1;
    // the others d1 / d2 over a second-best of 0.5 (d = 0.5): 0.98 gives d = 0.1, PA
    // 0.2 (right); 0.92, d = 0.2, PA 0.4 (right); 0.68, d = 0.4, PA 0.8 (row 2, wrong).
    let m = -f64::MAX;
    let s = ndarray::array![[0.98, 0.5, m, 0.5], [0.5, 0.92, m, 0.0], [0.0, 0.0, m, 0.68]];
    let gt = ndarray::array![
        [true, false, false, true],
        [false, true, false, false],
        [false, false, true, false]
    ];
    let gt = qtvpr::GroundTruth::new(gt.view()).unwrap();
    let cal = Arc::new(Calibration::new(s.view(), &gt, Matching::Single).unwrap());
    // By descending PA-score: 1 and 0.8 wrong, 0.4 and 0.2 right. x / n pools the two
    // wrong (0 >= 0) and the two right (1 >= 1); Laplace keeps 1/4 < 3/4 apart. Blocks
    // by ascending confidence: centre 0.9, 0 of 2; centre 0.3, 2 of 2.
    let map = cal.confidence_map().unwrap();
    let blocks: Vec<(usize, usize)> = map.blocks().iter().map(|b| (b.n, b.x)).collect();
    assert_eq!(blocks, [(2, 0), (2, 2)]);
    assert!((map.blocks()[0].pa_score - 0.9).abs() < 1e-12);
    assert!((map.blocks()[1].pa_score - 0.3).abs() < 1e-12);
    // A deployment query of 0.82 over 0.5 (d = 0.3 over 0.5, PA 0.6), halfway between
    // the centres: (1/4 + 3/4) / 2 = 1/2. Another of -f64::MAX twice: PA 1, beyond the
    // first centre, at its lower bound for 0 of 2: 0.
    let p = OnlineParams {
        k: 1,
        precision: 1.0,
        window: 2,
        min_window: 1,
        gate: Gate::None,
        sequence_gate: Default::default(),
    };
    let mut online = Online::new(cal, p).unwrap();
    let d = online.push(ndarray::array![0.82, 0.5, 0.0].view()).unwrap();
    assert!((d.confidence - 0.5).abs() < 1e-12, "{}", d.confidence);
    let d = online.push(ndarray::array![m, m, m].view()).unwrap();
    assert_eq!(d.confidence, 0.0);
}
