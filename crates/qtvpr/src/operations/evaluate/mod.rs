//! semantics §8: the evaluation protocol of the paper's Table I.
//!
//! One similarity matrix with ground truth for every query is split in query order:
//! the first queries calibrate, the deployment set is cut into full segments of
//! consecutive queries (a shorter remainder is dropped), and every method of
//! [`Method`] gives each segment a threshold. Each segment's decisions at that
//! threshold are counted against the segment's own ground truth, which answers the
//! practical question: *would this threshold have kept me at the target precision on
//! this stretch of the traverse, and how much recall did it leave me?*
//!
//! Nothing here re-implements an earlier section: decisions and counts are
//! the per-column candidates of section 2, the oracle is the section-3 sweep, quantile transfer is
//! [`Calibration::transfer`] with one batch per segment (sections 4-6), and the
//! baselines are [`crate::rules::baselines`] (section 7). Segments are independent, so each
//! method's thresholds and counts are computed for all segments in parallel.
//!
//! [`Protocol::deploy_fraction`] pins the deployment set to the last queries, so that
//! the calibration size can vary while the deployment set stays the same; [`ablation`]
//! runs the protocol once per `k` and calibration size on such a fixed deployment set
//! (the paper's Fig. 5).
//!
//! Every result derives `serde::Serialize` under the `serde` feature; the keys are
//! listed in [`crate::files::report`].

mod online;
mod protocol;
mod results;

pub use protocol::{
    ABLATION_DEPLOY_FRACTION, DEFAULT_CAL_FRACTION, DEFAULT_SEGMENT_FRACTION, Layout, Method, Protocol, Split,
};
pub use results::{Ablation, Evaluation, MethodResult, PrPoint, SCORE_HISTOGRAM_BINS, ScoreHistogram, SegmentResult};

use std::ops::Range;
use std::sync::Arc;

use ndarray::{ArrayView2, s};
use rayon::prelude::*;

use crate::error::Result;
use crate::error::names::Input;
use crate::gates::margin;
use crate::gates::sequence::of_best_matches;
use crate::gates::{self, GateSignals};
use crate::input::params::Gate;
use crate::input::params::{Options, Params};
use crate::input::{GroundTruth, Score, check_gt_shape, validate_scores};
use crate::operations::calibration::Calibration;
use crate::operations::source::ScoreSource;
use crate::platform::threads;
use crate::rules::baselines::schubert;
use crate::rules::best_threshold::subset_threshold;
use crate::rules::decisions::{Candidates, Matching, best_match};
use crate::signals::confidence::{self, ConfidenceMap, Signal, Signals};
use online::online_segments;
use results::{score, summarise};

/// Run the protocol on the similarity `scores` (|DB| x |Q|: a matrix, or descriptors,
/// whose similarity is computed in memory, as the protocol reads all of it) with ground
/// truth `gt` for every query.
///
/// `methods` are evaluated in the order given (a repeated method once); the oracle
/// threshold of every segment is computed whether or not [`Method::Oracle`] is asked
/// for, since every method reports it. `protocol` is the [`Protocol`] (`&protocol`),
/// with an optional progress callback ([`Options::progress`]) called as
/// `progress(done, total)` after each method: `done` of the `total` distinct methods
/// are evaluated.
///
/// # Errors
/// Invalid parameters or split ([`Protocol::layout`]), empty or non-finite scores, a
/// range of descriptor queries that is empty or beyond |Q|, or ground truth of
/// another shape.
pub fn evaluate<'s, 'd: 's, 'p>(
    scores: impl Into<ScoreSource<'s, 'd>>,
    gt: &GroundTruth,
    protocol: impl Into<Options<'p, Protocol>>,
    methods: &[Method],
) -> Result<Evaluation> {
    let options = protocol.into();
    options.params.validate()?;
    scores
        .into()
        .with_matrix(|s| with_scores!(s, |s| evaluate_matrix(s, gt, &options, methods)))
}

/// [`evaluate`] of a matrix.
fn evaluate_matrix<T: Score>(
    s: ArrayView2<'_, T>,
    gt: &GroundTruth,
    options: &Options<'_, Protocol>,
    methods: &[Method],
) -> Result<Evaluation> {
    let protocol = &options.params;
    validate_scores(Input::Similarity, s)?;
    check_gt_shape(gt, Input::Similarity, s.dim())?;
    let layout = protocol.layout(s.nrows(), s.ncols())?;
    let mut unique: Vec<Method> = Vec::with_capacity(methods.len());
    for &m in methods {
        if !unique.contains(&m) {
            unique.push(m);
        }
    }

    let (tau, size) = (protocol.precision, layout.segment_size);
    let cal = s![.., ..layout.calibration_queries];
    let dep = s![
        ..,
        layout.deployment_start..layout.deployment_start + layout.segments * size
    ];
    let (s_cal, gt_cal) = (s.slice(cal), gt.view().slice_move(cal));
    let (s_dep, gt_dep) = (s.slice(dep), gt.view().slice_move(dep));
    let ranges: Vec<Range<usize>> = (0..layout.segments).map(|i| i * size..(i + 1) * size).collect();

    let deployment = Candidates::new(s_dep, gt_dep, protocol.matching);
    // R@1 is the recall of single-match decisions with nothing rejected.
    let all = 0..deployment.ncols();
    let best_matches = match protocol.matching {
        Matching::Single => deployment.counts(all, f64::NEG_INFINITY),
        Matching::Multi => Candidates::new(s_dep, gt_dep, Matching::Single).counts(all, f64::NEG_INFINITY),
    };
    let recall_at_1 = (best_matches.positives > 0).then(|| best_matches.recall());
    let oracle: Vec<f64> = threads::install(|| {
        ranges
            .par_iter()
            .map(|r| subset_threshold(&deployment, &r.clone().collect::<Vec<_>>(), tau))
            .collect()
    });
    // The gates of the gated methods (semantics §13, §15), checked before any work.
    let gate = unique.iter().fold(Gate::None, |g, m| g.union(m.gate()));
    let gated = gate.is_on();
    gates::check(gate, &protocol.sequence_gate, protocol.matching, s.nrows())?;
    let needs_calibration = unique.iter().any(|m| {
        m.is_gated()
            || matches!(
                m,
                Method::QuantileTransfer | Method::QuantileTransferOnline | Method::CalibrationThreshold
            )
    });
    let calibration = needs_calibration
        .then(|| Calibration::with_labels(s_cal, gt_cal, protocol.matching).map(Arc::new))
        .transpose()?;
    // The gate's margins (of scores validated above) and m*, and the quantile-transfer
    // thresholds: each found once for the methods that share them.
    let confident = protocol.matching == Matching::Single && s.nrows() >= 2;
    let dep_margins = (gate.margin() || confident).then(|| margin::of_columns(s_dep));
    // Semantics §15: every deployment query's consistency, over the whole traverse in
    // column order (the calibration queries are its first queries), for the sequence
    // methods and as a signal (where the database can tell a line from chance).
    let sequence = &protocol.sequence_gate;
    let consistent = protocol.matching == Matching::Single && sequence.check(Matching::Single, s.nrows()).is_ok();
    let dep_consistencies = (gate.sequence() || (confident && consistent)).then(|| {
        let best: Vec<usize> = s.columns().into_iter().map(best_match).collect();
        let first = layout.deployment_start;
        of_best_matches(sequence, &best)[first..first + layout.segments * size].to_vec()
    });
    let gates = if gated {
        let cal = calibration.as_ref().expect("built for the gate");
        let signals: Vec<GateSignals> = (0..layout.segments * size)
            .map(|j| GateSignals {
                margin: dep_margins.as_ref().filter(|_| gate.margin()).map(|m| m[j]),
                consistency: dep_consistencies.as_ref().filter(|_| gate.sequence()).map(|c| c[j]),
            })
            .collect();
        Some((cal.gates(gate, sequence, tau)?, signals))
    } else {
        None
    };
    // Semantics §14: the calibration's map, from its own PA-scores and decisions, and
    // the signals of the full segments' decisions.
    let confidence = dep_margins.as_ref().filter(|_| confident).map(|margins| {
        let cal = Candidates::new(s_cal, gt_cal, Matching::Single);
        let map = ConfidenceMap::fit(confidence::pairs(&confidence::pa_scores_of_columns(s_cal), &cal));
        let pa_scores = confidence::pa_scores_of_columns(s_dep);
        let decisions: Vec<Signal> = (0..deployment.ncols())
            .filter_map(|j| {
                let (scores, correct) = deployment.column(j);
                correct.first().map(|&correct| Signal {
                    score: scores[0],
                    margin: margins[j],
                    pa_score: pa_scores[j],
                    consistency: dep_consistencies.as_ref().map(|c| c[j]),
                    correct,
                })
            })
            .collect();
        Signals::of(&decisions, &map)
    });
    let transferred = if unique.iter().any(|m| m.transfers()) {
        let params = Params {
            k: protocol.k,
            precision: tau,
            segment_size: Some(size),
            ..Params::default()
        };
        let cal = calibration.as_ref().expect("built for quantile transfer");
        let segments = cal.transfer(s_dep, &params)?.segments;
        Some(segments.iter().map(|g| g.threshold).collect::<Vec<f64>>())
    } else {
        None
    };

    let mut results = Vec::with_capacity(unique.len());
    for &method in &unique {
        // Every method but the online one gives each segment one threshold.
        let scored = |thresholds: &[f64]| {
            let gates = gates
                .as_ref()
                .filter(|_| method.is_gated())
                .map(|(g, signals)| (g.only(method.gate()), signals.as_slice()));
            score(method, &deployment, &ranges, thresholds, &oracle, tau, gates)
        };
        let result = match method {
            Method::QuantileTransfer
            | Method::QuantileTransferMargin
            | Method::QuantileTransferSequence
            | Method::QuantileTransferMarginSequence => {
                scored(transferred.as_deref().expect("transferred for quantile transfer"))
            }
            // A gate alone: every score passes, the gates decide.
            Method::Margin | Method::Sequence => scored(&vec![f64::NEG_INFINITY; ranges.len()]),
            Method::Schubert => scored(&threads::install(|| {
                ranges
                    .par_iter()
                    .map(|r| schubert(s_dep.slice(s![.., r.clone()])))
                    .collect::<Vec<f64>>()
            })),
            Method::SchubertCalibrated => scored(&vec![schubert(s_cal); ranges.len()]),
            Method::CalibrationThreshold => {
                let cal = calibration.as_ref().expect("built for the calibration threshold");
                scored(&vec![cal.threshold(tau)?; ranges.len()])
            }
            Method::Oracle => scored(&oracle),
            // Decided query by query: its segments are counted as it goes.
            Method::QuantileTransferOnline => {
                let cal = calibration.as_ref().expect("built for online quantile transfer");
                summarise(
                    method,
                    online_segments(cal, s_dep, &deployment, &ranges, &oracle, protocol)?,
                )
            }
        };
        results.push(result);
        options.report(results.len(), unique.len());
    }
    Ok(Evaluation {
        layout,
        recall_at_1,
        methods: results,
        confidence,
        deployment,
    })
}

/// Run the protocol once per combination of `ks` and `calibration` sizes (the paper's
/// Fig. 5: %Segs and AvgR@tauP against `k` and against the calibration size).
///
/// Every run is one of [`Protocol::ablation`]: `base` with its `k` and calibration
/// replaced, an empty list keeping `base`'s value. So that the figures of different settings are comparable, every run
/// deploys on the same queries: the last `floor(f |Q|)` with `f = base.deploy_fraction`,
/// or [`ABLATION_DEPLOY_FRACTION`] (the last 50%) when that is `None`. The calibration
/// set is always the first queries, and may not reach into the deployment set.
///
/// `base` may carry a progress callback ([`Options::progress`]), called as
/// `progress(done, total)` after each method of each run: `done` of the `total` method
/// evaluations of the whole ablation are finished.
///
/// # Errors
/// As [`evaluate`]; every setting is checked ([`Protocol::layout`]) before the first
/// one runs.
pub fn ablation<'s, 'd: 's, 'p>(
    scores: impl Into<ScoreSource<'s, 'd>>,
    gt: &GroundTruth,
    base: impl Into<Options<'p, Protocol>>,
    ks: &[usize],
    calibration: &[Split],
    methods: &[Method],
) -> Result<Ablation> {
    let options = base.into();
    let protocols = options.params.ablation(ks, calibration)?;
    let source = scores.into();
    let (n_db, n_q) = source.dim();
    for p in &protocols {
        p.layout(n_db, n_q)?;
    }
    let n = protocols.len();
    // Descriptors are turned into their similarity once, for every run.
    let runs = source.with_matrix(|s| {
        protocols
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let progress = |done, total| options.report(i * total + done, n * total);
                evaluate(s, gt, Options::new(*p).progress(&progress), methods)
            })
            .collect::<Result<_>>()
    })?;
    Ok(Ablation { runs })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rules::baselines::SCHUBERT_Z;
    use ndarray::{Array2, array};

    /// |DB| = 3, |Q| = 7 (the reference's TINY case): calibration c0, c1, then
    /// deployment d0..d4.
    ///
    /// ```text
    ///        c0   c1    d0   d1   d2   d3   d4
    /// db0   0.9  0.2   0.7  0.1  0.5  0.2  0.3
    /// db1   0.1  0.95  0.3  0.6  0.4  0.9  0.3
    /// db2   0.3  0.4   0.2  0.5  0.3  0.1  0.3
    /// ```
    /// GT: c0 -> db0, c1 -> db2, d0 -> db0, d1 -> db2; d2..d4 have no match.
    pub(super) fn tiny() -> (Array2<f64>, GroundTruth) {
        let s = array![
            [0.9, 0.2, 0.7, 0.1, 0.5, 0.2, 0.3],
            [0.1, 0.95, 0.3, 0.6, 0.4, 0.9, 0.3],
            [0.3, 0.4, 0.2, 0.5, 0.3, 0.1, 0.3],
        ];
        let gt =
            GroundTruth::new(array![[1u8, 0, 1, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 0], [0, 1, 0, 1, 0, 0, 0],].view())
                .unwrap();
        (s, gt)
    }

    /// tau = 0.5, two calibration queries, segments of two: (0, 2) = d0 d1 and
    /// (2, 4) = d2 d3; d4 is the dropped remainder.
    pub(super) fn protocol() -> Protocol {
        Protocol {
            calibration: Split::Count(2),
            segment: Split::Count(2),
            precision: 0.5,
            ..Protocol::default()
        }
    }

    pub(super) fn run(methods: &[Method]) -> Evaluation {
        let (s, gt) = tiny();
        evaluate(s.view(), &gt, &protocol(), methods).unwrap()
    }

    #[test]
    fn progress_after_each_distinct_method() {
        // Schubert, the oracle and Schubert again: two distinct methods, so 1 then 2 of 2;
        // the results are those of `evaluate`.
        let (s, gt) = tiny();
        let methods = [Method::Schubert, Method::Oracle, Method::Schubert];
        let calls = std::cell::RefCell::new(vec![]);
        let record = |d, t| calls.borrow_mut().push((d, t));
        let e = evaluate(s.view(), &gt, Options::new(protocol()).progress(&record), &methods).unwrap();
        assert_eq!(calls.take(), [(1, 2), (2, 2)]);
        assert_eq!(e.methods, run(&methods).methods);
        // Rejected input (tau = 0): no call.
        let bad = Protocol {
            precision: 0.0,
            ..protocol()
        };
        assert!(evaluate(s.view(), &gt, Options::new(bad).progress(&record), &methods).is_err());
        assert_eq!(calls.take(), []);
    }

    #[test]
    fn layout_of_the_tiny_case() {
        let e = run(&[Method::Oracle]);
        assert_eq!(
            e.layout,
            Layout {
                protocol: protocol(),
                database_size: 3,
                queries: 7,
                calibration_queries: 2,
                deployment_start: 2,
                deployment_queries: 5,
                segment_size: 2,
                segments: 2
            }
        );
    }

    #[test]
    fn oracle_and_a_skipped_segment() {
        // Segment 0 (single): d0's best match 0.7 (db0, correct), d1's 0.6 (db1, wrong);
        // positives 2. Sweep at tau 0.5: 0.7 (1, 0) valid; 0.6 (1, 1): 1 >= 0.5 * 2 valid;
        // TP* = 1, first reached at 0.7 -> oracle 0.7: TP 1, FP 0, recall 1/2, meets.
        // Segment 1: d2, d3 have no match -> positives 0 -> skipped; oracle inf.
        // %Segs = 100 * 1/1 = 100; AvgR = 0.5 / 1; MSE over segment 0 = 0.
        let e = run(&[Method::Oracle]);
        let o = &e.methods[0];
        assert_eq!((o.segments_counted, o.segments_skipped), (1, 1));
        assert_eq!(
            (o.pct_segs, o.avg_recall, o.threshold_mse),
            (Some(100.0), Some(0.5), Some(0.0))
        );
        let g = o.segments[0];
        assert_eq!((g.start, g.end, g.threshold, g.oracle_threshold), (0, 2, 0.7, 0.7));
        assert_eq!((g.counts.tp, g.counts.fp, g.counts.positives, g.meets), (1, 0, 2, true));
        assert_eq!(o.segments[1].oracle_threshold, f64::INFINITY);
        assert_eq!(o.segments[1].counts.positives, 0);
    }

    #[test]
    fn calibration_threshold_is_reused_for_every_segment() {
        // Calibration (single): c0 best 0.9 (db0, correct), c1 best 0.95 (db1, wrong).
        // Sweep: 0.95 (0, 1) TP 0 invalid; 0.9 (1, 1): 1 >= 0.5 * 2 valid -> t = 0.9.
        // Segment 0 at 0.9 accepts nothing: precision 1 (meets), recall 0.
        // Segment 1 accepts d3's 0.9 (inclusive, wrong): FP 1, precision 0 -- but skipped.
        // %Segs 100, AvgR 0; MSE over segment 0: (0.9 - 0.7)^2 = 0.04.
        let e = run(&[Method::CalibrationThreshold]);
        let c = &e.methods[0];
        assert_eq!(
            c.segments.iter().map(|g| g.threshold).collect::<Vec<_>>(),
            vec![0.9, 0.9]
        );
        assert_eq!((c.segments[0].counts.tp, c.segments[0].counts.fp), (0, 0));
        assert_eq!((c.segments[1].counts.fp, c.segments[1].meets), (1, false));
        assert_eq!((c.pct_segs, c.avg_recall), (Some(100.0), Some(0.0)));
        assert!((c.threshold_mse.unwrap() - 0.04).abs() < 1e-15);
    }

    #[test]
    fn quantile_transfer_per_segment() {
        // k = 10 clips to 2: every deployment query's subset is {c0, c1}, threshold 0.9 (as
        // above). Sample (0.1, 0.2, 0.3, 0.4, 0.9, 0.95): c(<= 0.9) = 5 -> q = 4/5 for all.
        // Segment 0 scores ascending (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): h = 5 * 0.8 = 4 -> 0.6;
        // it accepts 0.7 (T) and 0.6 (F): precision 1/2 >= 0.5 meets, recall 1/2.
        // Segment 1 ascending (0.1, 0.2, 0.3, 0.4, 0.5, 0.9): h = 4 -> 0.5.
        // %Segs 100, AvgR 0.5 / 1, MSE (0.6 - 0.7)^2 = 0.01.
        let e = run(&[Method::QuantileTransfer]);
        let q = &e.methods[0];
        let t: Vec<f64> = q.segments.iter().map(|g| g.threshold).collect();
        assert!((t[0] - 0.6).abs() < 1e-15 && (t[1] - 0.5).abs() < 1e-15, "{t:?}");
        assert_eq!((q.segments[0].counts.tp, q.segments[0].counts.fp), (1, 1));
        assert_eq!((q.pct_segs, q.avg_recall), (Some(100.0), Some(0.5)));
        assert!((q.threshold_mse.unwrap() - 0.01).abs() < 1e-15);
    }

    #[test]
    fn schubert_per_segment_and_calibrated() {
        // Segment 0 scores (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): mu = (0.3 + 0.5) / 2 = 0.4;
        // |S - mu| = (0.3, 0.2, 0.1, 0.1, 0.2, 0.3) -> median (0.2 + 0.2) / 2 = 0.2;
        // t = 0.4 + (0.2 / 0.675) * z = 1.808... accepts nothing: meets, recall 0.
        // Calibration (0.1, 0.2, 0.3, 0.4, 0.9, 0.95): mu = (0.3 + 0.4) / 2 = 0.35;
        // |S - mu| sorted (0.05, 0.05, 0.15, 0.25, 0.55, 0.6) -> median 0.2;
        // t = 0.35 + (0.2 / 0.675) * z for both segments.
        let e = run(&[Method::Schubert, Method::SchubertCalibrated]);
        let (sch, cal) = (&e.methods[0], &e.methods[1]);
        let near = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(near(sch.segments[0].threshold, 0.4 + 0.2 / 0.675 * SCHUBERT_Z));
        assert_eq!((sch.pct_segs, sch.avg_recall), (Some(100.0), Some(0.0)));
        for g in &cal.segments {
            assert!(near(g.threshold, 0.35 + 0.2 / 0.675 * SCHUBERT_Z));
        }
    }

    #[test]
    fn recall_at_1_counts_best_matches_in_both_modes() {
        // Full segments d0..d3: best matches d0 0.7 (db0, hard), d1 0.6 (db1, wrong),
        // d2 0.5 (db0, no match), d3 0.9 (db1, no match). Queries with a hard match: d0, d1
        // -> R@1 = 1 / 2, in multi mode too (it is about best matches).
        for matching in [Matching::Single, Matching::Multi] {
            let (s, gt) = tiny();
            let p = Protocol { matching, ..protocol() };
            let e = evaluate(s.view(), &gt, &p, &[Method::Oracle]).unwrap();
            assert_eq!(e.recall_at_1, Some(0.5), "{matching:?}");
        }
        // Columns c0, c1, d2, d3: the deployment queries have no hard match -> None.
        let (s, gt) = tiny();
        let cols = [0, 1, 4, 5];
        let s = s.select(ndarray::Axis(1), &cols);
        let gt = GroundTruth::from_truth(gt.view().select(ndarray::Axis(1), &cols));
        let e = evaluate(s.view(), &gt, &protocol(), &[Method::Oracle]).unwrap();
        assert_eq!(e.recall_at_1, None);
    }

    /// The k and calibration-size ablation: one run per setting on the last half.
    #[test]
    fn ablation_runs_every_setting_on_one_deployment_set() {
        // |Q| = 7: the last floor(0.5 * 7) = 3 queries (columns 4..7 = d2, d3, d4) deploy
        // in segments of one; calibration 1 or 2 first queries; k 1 or 5.
        let (s, gt) = tiny();
        let base = Protocol {
            segment: Split::Count(1),
            precision: 0.5,
            ..Protocol::default()
        };
        let a = ablation(
            s.view(),
            &gt,
            &base,
            &[1, 5],
            &[Split::Count(1), Split::Count(2)],
            &[Method::QuantileTransfer, Method::Oracle],
        )
        .unwrap();
        let settings: Vec<(usize, Split)> = a
            .runs
            .iter()
            .map(|r| (r.layout.protocol.k, r.layout.protocol.calibration))
            .collect();
        assert_eq!(
            settings,
            vec![
                (1, Split::Count(1)),
                (5, Split::Count(1)),
                (1, Split::Count(2)),
                (5, Split::Count(2))
            ]
        );
        for r in &a.runs {
            let l = r.layout;
            assert_eq!(l.protocol.deploy_fraction, Some(ABLATION_DEPLOY_FRACTION));
            assert_eq!((l.deployment_start, l.deployment_queries, l.segments), (4, 3, 3));
            // Each run is the protocol with that setting.
            let one = evaluate(s.view(), &gt, &l.protocol, &[Method::QuantileTransfer, Method::Oracle]).unwrap();
            assert_eq!(r.methods, one.methods);
        }
        // An empty list keeps the base value; a deploy fraction given is kept.
        let a = ablation(
            s.view(),
            &gt,
            &Protocol {
                calibration: Split::Count(2),
                deploy_fraction: Some(0.6),
                ..base
            },
            &[3],
            &[],
            &[Method::Oracle],
        )
        .unwrap();
        assert_eq!(a.runs.len(), 1);
        let p = a.runs[0].layout.protocol;
        assert_eq!((p.k, p.calibration, p.deploy_fraction), (3, Split::Count(2), Some(0.6)));
        // A bad setting fails before any run: 5 calibration queries reach into the last 3.
        let err = ablation(
            s.view(),
            &gt,
            &base,
            &[1],
            &[Split::Count(1), Split::Count(5)],
            &[Method::Oracle],
        );
        assert_eq!(
            err.unwrap_err().to_string(),
            "the calibration set (5 queries) and the deployment set (3 queries) overlap: \
             together they exceed the 7 queries"
        );
    }

    #[test]
    fn repeated_methods_are_reported_once() {
        let e = run(&[Method::Oracle, Method::Schubert, Method::Oracle]);
        let names: Vec<&str> = e.methods.iter().map(|m| m.method.as_str()).collect();
        assert_eq!(names, vec!["oracle", "schubert"]);
    }
}
