//! The margin gate (semantics §13) on real VPR-Bench matrices in `../shared/data`: `m*`
//! against a brute-force semantics §3 on the calibration margins; the batch transfer,
//! `Online` and `evaluate` against the definition, query by query; a calibration file
//! keeps its gate; multi matching is refused everywhere.
#![cfg(feature = "npy")]

use qtvpr_testkit::data;
use std::sync::Arc;

use ndarray::{ArrayView2, s};
use qtvpr::best_match;
use qtvpr::npy::{read_ground_truth, read_scores};
use qtvpr::{
    Calibration, Defaults, Gate, GroundTruth, Matching, Method, Online, OnlineParams, Params, Protocol, Score,
    ScoresView, Split, Truth, evaluate, margins,
};

/// Semantics §3 by brute force: of the thresholds `t` among `values` whose accepted set
/// `{value >= t}` has precision >= tau, the highest of those of maximum TP (> 0);
/// `+inf` when there is none.
fn brute_force_gate(decisions: &[(f64, bool)], tau: f64) -> f64 {
    let mut best = (0usize, f64::INFINITY);
    for &(t, _) in decisions {
        let accepted = decisions.iter().filter(|(v, _)| *v >= t);
        let (tp, n) = accepted.fold((0, 0), |(tp, n), (_, ok)| (tp + usize::from(*ok), n + 1));
        let valid = tp > 0 && tp as f64 >= tau * n as f64 - 1e-12;
        if valid && (tp > best.0 || (tp == best.0 && t > best.1)) {
            best = (tp, t);
        }
    }
    best.1
}

/// The calibration decisions of single matching with their margins: each query's best
/// match, soft-only ones left out.
fn calibration_decisions<T: Score>(s: ArrayView2<'_, T>, gt: &GroundTruth) -> Vec<(f64, bool)> {
    let m = margins(s).unwrap();
    (0..s.ncols())
        .filter_map(|j| {
            let b = best_match(s.column(j));
            match gt.view()[[b, j]] {
                Truth::Ignored => None,
                t => Some((m[j], t == Truth::True)),
            }
        })
        .collect()
}

/// Returns how many accepted decisions the gate rejected.
fn check<T: Score>(s: ArrayView2<'_, T>, gt: &GroundTruth, n_cal: usize) -> usize {
    let gt_cal = GroundTruth::from_truth(gt.view().slice(s![.., ..n_cal]).to_owned());
    let (s_cal, s_val) = (s.slice(s![.., ..n_cal]), s.slice(s![.., n_cal..]));
    let cal = Arc::new(Calibration::new(s_cal, &gt_cal, Matching::Single).unwrap());
    let decisions = calibration_decisions(s_cal, &gt_cal);
    let val_margins = margins(s_val).unwrap();
    let mut rejected_by_gate = 0;
    for tau in [1.0, 0.9] {
        let m_star = cal.gate(tau).unwrap();
        assert_eq!(m_star, brute_force_gate(&decisions, tau), "tau {tau}");

        // The batch transfer: the ungated thresholds, m* and every query's margin.
        let params = Params {
            k: 10,
            precision: tau,
            segment_size: Some(10),
            gate: Gate::Margin,
            sequence_gate: Default::default(),
        };
        let gated = cal.transfer(s_val, &params).unwrap();
        let plain = cal
            .transfer(
                s_val,
                &Params {
                    gate: Gate::None,
                    ..params
                },
            )
            .unwrap();
        assert_eq!(gated.segments, plain.segments);
        assert_eq!((gated.gate, plain.gate), (Some(m_star), None));
        assert_eq!(gated.query_margins.as_deref(), Some(&val_margins[..]));
        assert!(plain.query_margins.is_none());

        // Online: accept = score >= threshold and margin >= m*, with both in the record.
        let p = OnlineParams {
            k: 10,
            precision: tau,
            window: 7,
            min_window: 1,
            gate: Gate::Margin,
            sequence_gate: Default::default(),
        };
        let online = Online::new(Arc::clone(&cal), p).unwrap().push_many(s_val).unwrap();
        let ungated = Online::new(Arc::clone(&cal), OnlineParams { gate: Gate::None, ..p })
            .unwrap()
            .push_many(s_val)
            .unwrap();
        for (j, (d, u)) in online.iter().zip(&ungated).enumerate() {
            assert_eq!((d.margin, d.gate), (Some(val_margins[j]), Some(m_star)), "query {j}");
            assert_eq!((u.margin, u.gate), (None, None));
            assert_eq!((d.threshold, d.best, d.score), (u.threshold, u.best, u.score));
            let accept = d.score >= d.threshold && val_margins[j] >= m_star;
            assert_eq!(d.accept(), accept, "query {j}");
            rejected_by_gate += usize::from(u.accept() && !accept);
        }
    }

    // A calibration file keeps its gate, and its params are the defaults.
    let defaults = Defaults {
        gate: Gate::Margin,
        ..Defaults::default()
    };
    let loaded = Calibration::from_bytes(&cal.to_bytes(&defaults).unwrap(), "cal.npz").unwrap();
    assert_eq!(loaded.defaults().gate, Gate::Margin);
    let p = Params::resolve(loaded.defaults(), None, None, None, None, Default::default()).unwrap();
    assert_eq!(loaded.transfer(s_val, &p).unwrap().gate, Some(cal.gate(1.0).unwrap()));
    rejected_by_gate
}

/// The protocol's gated methods, segment by segment, against the definition.
fn check_evaluate<T: Score>(s: ArrayView2<'_, T>, gt: &GroundTruth) {
    let protocol = Protocol::default();
    let e = evaluate(s, gt, &protocol, &Method::ALL).unwrap();
    let layout = e.layout;
    let n_cal = layout.calibration_queries;
    let gt_cal = GroundTruth::from_truth(gt.view().slice(s![.., ..n_cal]).to_owned());
    let m_star = Calibration::new(s.slice(s![.., ..n_cal]), &gt_cal, Matching::Single)
        .unwrap()
        .gate(1.0)
        .unwrap();
    let start = layout.deployment_start;
    let all = margins(s).unwrap();
    let qt = e.method(Method::QuantileTransfer).unwrap();
    for method in [Method::Margin, Method::QuantileTransferMargin] {
        let r = e.method(method).unwrap();
        for (g, q) in r.segments.iter().zip(&qt.segments) {
            let threshold = if method == Method::Margin {
                f64::NEG_INFINITY
            } else {
                q.threshold
            };
            assert_eq!((g.threshold, g.gate), (threshold, Some(m_star)));
            let (mut tp, mut fp) = (0, 0);
            for j in start + g.start..start + g.end {
                let b = best_match(s.column(j));
                let accept = s[[b, j]].to_f64() >= threshold && all[j] >= m_star;
                match (accept, gt.view()[[b, j]]) {
                    (true, Truth::True) => tp += 1,
                    (true, Truth::False) => fp += 1,
                    _ => {}
                }
            }
            assert_eq!((g.counts.tp, g.counts.fp), (tp, fp), "{method} segment {}", g.start);
            assert_eq!(g.counts.positives, q.counts.positives);
        }
    }
    // The margin has no score threshold: it is left out of the threshold MSE.
    assert_eq!(e.method(Method::Margin).unwrap().threshold_mse, None);
    let qtm = e.method(Method::QuantileTransferMargin).unwrap();
    assert_eq!(qtm.threshold_mse, qt.threshold_mse);
    assert!(qt.segments.iter().all(|g| g.gate.is_none()));
}

/// Every check on one matrix; the number of decisions its gate rejected.
fn run(dir: &str, technique: &str, n_cal: usize) -> usize {
    let (Some(scores), Some(gt)) = (
        data::shared(&format!("{dir}/S_{technique}.npy")),
        data::shared(&format!("{dir}/GT.npy")),
    ) else {
        return 0;
    };
    let scores = read_scores(&scores).unwrap();
    let gt = read_ground_truth(&gt, None).unwrap();
    match scores.view() {
        ScoresView::F32(v) => {
            check_evaluate(v, &gt);
            check(v, &gt, n_cal)
        }
        ScoresView::F64(v) => {
            check_evaluate(v, &gt);
            check(v, &gt, n_cal)
        }
    }
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor and -spedtest: the gate on 4 real matrices, f32 and f64"]
fn corridor_and_spedtest() {
    let rejected = run("vprbench-corridor", "NetVLAD", 11)
        + run("vprbench-corridor", "CoHOG", 11)
        + run("vprbench-spedtest", "CALC", 60)
        + run("vprbench-spedtest", "AMOSNet", 60);
    if data::shared("").is_some() {
        assert!(rejected > 0, "the gate rejected no decision on four real matrices");
    }
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor (HOG): multi matching refused on a real matrix"]
fn multi_matching_has_no_gate() {
    let Some(path) = data::shared("vprbench-corridor/S_HOG.npy") else {
        return;
    };
    let scores = read_scores(&path).unwrap();
    let gt = read_ground_truth(&data::shared("vprbench-corridor/GT.npy").unwrap(), None).unwrap();
    match scores.view() {
        ScoresView::F32(s) => refused_in_multi_matching(s, &gt),
        ScoresView::F64(s) => refused_in_multi_matching(s, &gt),
    }
}

fn refused_in_multi_matching<T: Score>(s: ArrayView2<'_, T>, gt: &GroundTruth) {
    let gt_cal = GroundTruth::from_truth(gt.view().slice(s![.., ..11]).to_owned());
    let cal = Arc::new(Calibration::new(s.slice(s![.., ..11]), &gt_cal, Matching::Multi).unwrap());
    let why = "gate margin needs single matching: it gates each query's best match, and multi matching \
               accepts every database entry at or above the threshold";
    let params = Params {
        gate: Gate::Margin,
        ..Params::default()
    };
    assert_eq!(
        cal.transfer(s.slice(s![.., 11..]), &params).unwrap_err().to_string(),
        why
    );
    assert_eq!(cal.gate(1.0).unwrap_err().to_string(), why);
    let p = OnlineParams {
        k: 10,
        precision: 1.0,
        window: 5,
        min_window: 1,
        gate: Gate::Margin,
        sequence_gate: Default::default(),
    };
    assert_eq!(Online::new(Arc::clone(&cal), p).err().unwrap().to_string(), why);
    let file = Defaults {
        gate: Gate::Margin,
        ..Defaults::default()
    };
    assert_eq!(cal.to_bytes(&file).unwrap_err().to_string(), why);
    let protocol = Protocol {
        matching: Matching::Multi,
        calibration: Split::Count(11),
        ..Protocol::default()
    };
    assert_eq!(
        evaluate(s, gt, &protocol, &[Method::Margin]).unwrap_err().to_string(),
        why
    );
    // "All methods" in multi matching are those that apply.
    assert!(!Method::all_for(Matching::Multi).contains(&Method::QuantileTransferMargin));
    let e = evaluate(s, gt, &protocol, &Method::all_for(Matching::Multi)).unwrap();
    // Less the five gated methods: two of the margin gate, three of the sequence gate.
    assert_eq!(e.methods.len(), Method::ALL.len() - 5);
}
