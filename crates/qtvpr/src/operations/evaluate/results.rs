//! semantics §8.3-§8.6: what the protocol reports, per segment, per method and for a
//! whole run, and how a method's segments are counted and summarised.

use std::ops::Range;

use rayon::prelude::*;

use super::protocol::{Layout, Method};
use crate::gates::{GateSignals, Gates};
use crate::platform::threads;
use crate::rules::decisions::{Candidates, Counts};

/// Tolerance of the "meets the target" test (semantics §8.3).
pub(super) const EPS: f64 = 1e-12;

/// One segment under one method (semantics §8.6).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SegmentResult {
    /// First query of the segment, counted from the first deployment query.
    pub start: usize,
    /// One past its last query.
    pub end: usize,
    /// The method's threshold (`inf` is reject-all).
    pub threshold: f64,
    /// The oracle's threshold of the segment (`inf` when no threshold meets the target).
    pub oracle_threshold: f64,
    /// A method with the margin gate: `m*` (semantics §13), the margin a best match
    /// needs besides its score; `None` (and left out of the JSON) for the other methods.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub gate: Option<f64>,
    /// A method with the sequence gate: its level (semantics §15), the consistency a
    /// best match needs; `None` (and left out of the JSON) for the other methods.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub consistency_level: Option<f64>,
    /// TP, FP and positives at `threshold` (serialised with the figures derived from
    /// them: precision, recall and the precision's lower bound).
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub counts: Counts,
    /// Whether the precision is at least tau (less 1e-12).
    pub meets: bool,
}

/// A method's results over every full segment (semantics §8).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MethodResult {
    /// Which method (serialised as the key of this result).
    #[cfg_attr(feature = "serde", serde(skip))]
    pub method: Method,
    /// %Segs: 100 x segments that meet / segments counted; `None` when none is counted.
    pub pct_segs: Option<f64>,
    /// AvgR@tauP: the mean over counted segments of their recall if they meet, else 0;
    /// `None` when none is counted.
    pub avg_recall: Option<f64>,
    /// Segments with at least one positive.
    pub segments_counted: usize,
    /// Segments without positives, left out of both figures.
    pub segments_skipped: usize,
    /// Mean squared difference from the oracle's threshold over the counted segments
    /// where both are finite; `None` when there is no such segment.
    pub threshold_mse: Option<f64>,
    /// [`MethodResult::pooled`], serialised as `pooled_tp`, ..., `pooled_precision_lower95`.
    #[cfg_attr(
        feature = "serde",
        serde(flatten, serialize_with = "crate::rules::decisions::serialize::pooled")
    )]
    pooled: Counts,
    /// Every full segment, in order.
    pub segments: Vec<SegmentResult>,
}

impl MethodResult {
    /// TP, FP and positives summed over every full segment (skipped ones included): the
    /// method's operating point on the whole deployment set.
    pub fn pooled(&self) -> Counts {
        self.pooled
    }

    /// The lower median of the segments' thresholds (semantics §8.7): the one at
    /// position `(n - 1) / 2` of the `n` thresholds sorted ascending, reject-all (`inf`)
    /// last. `inf` when most segments reject all, `-inf` for a method without a score
    /// threshold (the margin gate alone); `None` when there is no segment.
    pub fn median_threshold(&self) -> Option<f64> {
        let mut t: Vec<f64> = self.segments.iter().map(|g| g.threshold).collect();
        t.sort_by(f64::total_cmp);
        t.get(t.len().saturating_sub(1) / 2).copied()
    }
}

/// How many bins [`Evaluation::score_histogram`] is asked for by the figures.
pub const SCORE_HISTOGRAM_BINS: usize = 40;

/// The scores of the deployment set's candidates, right and wrong, counted over equal
/// bins (semantics §8.7): [`Evaluation::score_histogram`].
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ScoreHistogram {
    /// The `bins + 1` bin edges, ascending: bin `i` holds the scores `s` with
    /// `edges[i] <= s < edges[i + 1]`, the last bin its upper edge too.
    pub edges: Vec<f64>,
    /// Per bin, the candidates that are correct (a hard match).
    pub right: Vec<usize>,
    /// Per bin, the candidates that are wrong (not a match at all).
    pub wrong: Vec<usize>,
}

/// One point of a precision-recall curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrPoint {
    /// Accept scores `>=` this.
    pub threshold: f64,
    /// Precision there.
    pub precision: f64,
    /// Recall there.
    pub recall: f64,
}

/// The result of [`evaluate`](super::evaluate).
#[derive(Debug, Clone)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Evaluation {
    /// The protocol's parameters and how they split the queries (serialised as `params`).
    #[cfg_attr(feature = "serde", serde(rename = "params"))]
    pub layout: Layout,
    /// R@1 of the deployment set's full segments: the fraction of its queries with at
    /// least one hard match whose best match (the first maximum of the column) is a hard
    /// match. It counts best matches whatever the matching mode; a best match that is
    /// soft but not hard is a miss. `None` when no such query has a hard match.
    ///
    /// VPR-Bench's "recall at 100% precision" divides by the queries whose best match is
    /// correct instead of the queries with a match: with single matching at tau = 1 it
    /// is the recall reported here divided by `recall_at_1`.
    pub recall_at_1: Option<f64>,
    /// One result per method asked for, in the order asked (duplicates removed);
    /// serialised as an object keyed by method name.
    #[cfg_attr(feature = "serde", serde(serialize_with = "serialize_methods"))]
    pub methods: Vec<MethodResult>,
    /// In single matching with |DB| >= 2, semantics §14's signals over the full
    /// segments' decisions (soft-only best matches left out): the AUROC of the best
    /// score, the margin and the confidence, and the confidence's Brier score and ECE.
    /// Serialised as `confidence`, left out otherwise.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub confidence: Option<crate::signals::confidence::Signals>,
    /// The candidates of the full segments' queries, for the precision-recall curve.
    #[cfg_attr(feature = "serde", serde(skip))]
    pub(super) deployment: Candidates,
}

impl Evaluation {
    /// The result of `method`, if it was asked for.
    pub fn method(&self, method: Method) -> Option<&MethodResult> {
        self.methods.iter().find(|m| m.method == method)
    }

    /// The precision-recall curve of the deployment set (every full segment pooled,
    /// one threshold for all), from the highest threshold down, evaluated at the end of
    /// each group of equal scores as in semantics §3.
    ///
    /// To keep a plot light, a point is kept only when precision or recall has moved
    /// by at least `1 / resolution` since the last kept point (the first and last
    /// points are always kept); `resolution = usize::MAX` keeps every point.
    pub fn precision_recall_curve(&self, resolution: usize) -> Vec<PrPoint> {
        let c = &self.deployment;
        let mut all: Vec<(f64, bool)> = (0..c.ncols())
            .flat_map(|j| {
                let (s, ok) = c.column(j);
                s.iter().copied().zip(ok.iter().copied())
            })
            .collect();
        threads::install(|| all.par_sort_unstable_by(|a, b| b.0.total_cmp(&a.0)));
        let positives = c.positives(0..c.ncols());
        let step = 1.0 / resolution as f64;
        let mut curve: Vec<PrPoint> = Vec::new();
        let (mut tp, mut fp) = (0usize, 0usize);
        for (i, &(score, correct)) in all.iter().enumerate() {
            if correct {
                tp += 1;
            } else {
                fp += 1;
            }
            let last = i + 1 == all.len();
            if !last && all[i + 1].0 == score {
                continue;
            }
            let counts = Counts { tp, fp, positives };
            let p = PrPoint {
                threshold: score,
                precision: counts.precision(),
                recall: counts.recall(),
            };
            let keep = curve.last().is_none_or(|q| {
                last || (p.precision - q.precision).abs() >= step || (p.recall - q.recall).abs() >= step
            });
            if keep {
                curve.push(p);
            }
        }
        curve
    }

    /// The scores of the deployment set's candidates (every full segment's; in single
    /// matching each query's best match) counted over `bins` equal bins from the lowest
    /// candidate score to the highest, right (a hard match) and wrong apart (semantics
    /// §8.7). A soft-only candidate is no decision (semantics §2) and is in neither.
    /// When every candidate has the same score the bins span that score +- 0.5.
    /// `None` when there is no candidate or `bins` is 0.
    pub fn score_histogram(&self, bins: usize) -> Option<ScoreHistogram> {
        let c = &self.deployment;
        let all = (0..c.ncols()).flat_map(|j| {
            let (s, ok) = c.column(j);
            s.iter().copied().zip(ok.iter().copied())
        });
        let (lo, hi) = all.clone().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (s, _)| {
            (a.min(s), b.max(s))
        });
        if bins == 0 || lo > hi {
            return None;
        }
        let (lo, hi) = if lo == hi { (lo - 0.5, hi + 0.5) } else { (lo, hi) };
        let mut edges: Vec<f64> = (0..bins).map(|i| lo + (hi - lo) * (i as f64 / bins as f64)).collect();
        edges.push(hi);
        let (mut right, mut wrong) = (vec![0; bins], vec![0; bins]);
        for (s, correct) in all {
            // The bin whose edges (as reported) hold `s`: the last edge <= s, the last
            // bin for `hi`. A search, not `(s - lo) / width`, whose rounding can put a
            // score on an edge into the bin below it.
            let i = edges[1..bins].partition_point(|&e| e <= s);
            if correct {
                right[i] += 1;
            } else {
                wrong[i] += 1;
            }
        }
        Some(ScoreHistogram { edges, right, wrong })
    }
}

/// The result of [`ablation`](super::ablation).
#[derive(Debug, Clone)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Ablation {
    /// One evaluation per setting: calibration sizes in the outer loop, `k` in the inner
    /// one, each in the order given (serialised as `ablation`).
    #[cfg_attr(feature = "serde", serde(rename = "ablation"))]
    pub runs: Vec<Evaluation>,
}

/// Count every segment at its threshold and summarise (semantics §8). With `gates`
/// (the method's gates at their levels, and what every deployment query shows them), a
/// query that a gate does not pass accepts nothing (semantics §13, §15: the accept rule
/// of [`Gates::threshold`]).
pub(super) fn score(
    method: Method,
    deployment: &Candidates,
    ranges: &[Range<usize>],
    thresholds: &[f64],
    oracle: &[f64],
    tau: f64,
    gates: Option<(Gates, &[GateSignals])>,
) -> MethodResult {
    let segments: Vec<SegmentResult> = threads::install(|| {
        (ranges, thresholds, oracle)
            .into_par_iter()
            .map(|(r, &threshold, &oracle_threshold)| {
                let counts = match gates {
                    None => deployment.counts(r.clone(), threshold),
                    Some((gates, signals)) => r
                        .clone()
                        .map(|j| deployment.counts(j..j + 1, gates.threshold(threshold, &signals[j])))
                        .sum(),
                };
                SegmentResult {
                    start: r.start,
                    end: r.end,
                    threshold,
                    oracle_threshold,
                    gate: gates.and_then(|g| g.0.margin_level()),
                    consistency_level: gates.and_then(|g| g.0.consistency_level()),
                    counts,
                    meets: counts.precision() >= tau - EPS,
                }
            })
            .collect()
    });
    summarise(method, segments)
}

/// %Segs, AvgR@tauP and the threshold MSE of a method's segments (semantics §8-§8).
pub(super) fn summarise(method: Method, segments: Vec<SegmentResult>) -> MethodResult {
    let counted: Vec<&SegmentResult> = segments.iter().filter(|g| g.counts.positives > 0).collect();
    let n = counted.len();
    let (pct_segs, avg_recall) = if n == 0 {
        (None, None)
    } else {
        let meet = counted.iter().filter(|g| g.meets).count();
        let recall: f64 = counted
            .iter()
            .map(|g| if g.meets { g.counts.recall() } else { 0.0 })
            .sum();
        (Some(100.0 * meet as f64 / n as f64), Some(recall / n as f64))
    };
    let squares: Vec<f64> = counted
        .iter()
        .filter(|g| g.threshold.is_finite() && g.oracle_threshold.is_finite())
        .map(|g| (g.threshold - g.oracle_threshold).powi(2))
        .collect();
    let threshold_mse = (!squares.is_empty()).then(|| squares.iter().sum::<f64>() / squares.len() as f64);
    let pooled = segments.iter().map(|g| g.counts).sum();
    MethodResult {
        method,
        pct_segs,
        avg_recall,
        segments_counted: n,
        segments_skipped: segments.len() - n,
        threshold_mse,
        pooled,
        segments,
    }
}

/// Method results as an object keyed by method name, in order (`serialize_with` of
/// [`Evaluation::methods`]).
#[cfg(feature = "serde")]
fn serialize_methods<S: serde::Serializer>(methods: &[MethodResult], serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_map(methods.iter().map(|m| (m.method.as_str(), m)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::GroundTruth;
    #[cfg(feature = "serde")]
    use crate::operations::evaluate::ablation;
    use crate::operations::evaluate::evaluate;
    use crate::operations::evaluate::protocol::{Protocol, Split};
    use crate::operations::evaluate::tests::{protocol, run, tiny};
    use ndarray::array;

    #[test]
    fn no_counted_segment_gives_no_figures() {
        // Columns c0, c1, d2, d3 only: the one segment (d2, d3) has no positives.
        let (s, gt) = tiny();
        let cols = [0, 1, 4, 5];
        let s = s.select(ndarray::Axis(1), &cols);
        let gt = GroundTruth::from_truth(gt.view().select(ndarray::Axis(1), &cols));
        let e = evaluate(s.view(), &gt, &protocol(), &[Method::Oracle, Method::Schubert]).unwrap();
        for m in &e.methods {
            assert_eq!((m.segments_counted, m.segments_skipped), (0, 1));
            assert_eq!((m.pct_segs, m.avg_recall, m.threshold_mse), (None, None, None));
        }
    }

    #[test]
    fn pct_segs_avg_recall_and_mse_by_hand() {
        // |DB| = 2, |Q| = 5: c0, then four deployment queries in segments of one, tau = 1,
        // with a fixed threshold 0.5 (calibration-threshold: c0's best match 0.8 is correct,
        // so t = 0.8; the arithmetic below uses that).
        //        c0   d0   d1   d2   d3
        // db0   0.8  0.9  0.7  0.85 0.1
        // db1   0.1  0.2  0.3  0.9  0.2
        // GT:   db0  db0  db0  db0  none
        // d0: best 0.9 (db0, T) accepted -> TP 1, meets, recall 1; oracle 0.9.
        // d1: best 0.7 (T) < 0.8 -> nothing accepted, meets, recall 0; oracle 0.7.
        // d2: best 0.9 (db1, F) accepted -> FP 1, fails; oracle inf (no valid group).
        // d3: no positive -> skipped.
        // Counted 3, meet 2 -> %Segs 66.67; AvgR (1 + 0 + 0) / 3; MSE over d0, d1 (d2's
        // oracle is inf): ((0.8 - 0.9)^2 + (0.8 - 0.7)^2) / 2 = 0.01.
        let s = array![[0.8, 0.9, 0.7, 0.85, 0.1], [0.1, 0.2, 0.3, 0.9, 0.2]];
        let gt = GroundTruth::new(array![[1u8, 1, 1, 1, 0], [0, 0, 0, 0, 0]].view()).unwrap();
        let p = Protocol {
            calibration: Split::Count(1),
            segment: Split::Count(1),
            ..Protocol::default()
        };
        let e = evaluate(s.view(), &gt, &p, &[Method::CalibrationThreshold]).unwrap();
        let c = &e.methods[0];
        assert_eq!((c.segments_counted, c.segments_skipped), (3, 1));
        assert_eq!(c.pct_segs, Some(100.0 * 2.0 / 3.0));
        assert_eq!(c.avg_recall, Some(1.0 / 3.0));
        assert!((c.threshold_mse.unwrap() - 0.01).abs() < 1e-15);
        let pooled = c.pooled();
        assert_eq!((pooled.tp, pooled.fp, pooled.positives), (1, 1, 3));
    }

    #[test]
    fn precision_recall_curve_of_the_deployment_set() {
        // Full segments d0..d3 (single): best matches 0.7 T, 0.6 F, 0.5 F, 0.9 F; 2 positives.
        // Descending: 0.9 F (P 0, R 0), 0.7 T (P 1/2, R 1/2), 0.6 F (1/3, 1/2), 0.5 F (1/4, 1/2).
        let e = run(&[Method::Oracle]);
        let curve = e.precision_recall_curve(usize::MAX);
        let got: Vec<(f64, f64, f64)> = curve.iter().map(|p| (p.threshold, p.precision, p.recall)).collect();
        assert_eq!(
            got,
            vec![
                (0.9, 0.0, 0.0),
                (0.7, 0.5, 0.5),
                (0.6, 1.0 / 3.0, 0.5),
                (0.5, 0.25, 0.5)
            ]
        );
        // At a resolution of 2 (steps of 0.5), 0.6 moves precision by 1/6 only: dropped;
        // the last point is always kept.
        let thin: Vec<f64> = e.precision_recall_curve(2).iter().map(|p| p.threshold).collect();
        assert_eq!(thin, vec![0.9, 0.7, 0.5]);
    }

    #[test]
    fn score_histogram_of_the_deployment_set() {
        // Full segments d0..d3 (single): best matches 0.7 T, 0.6 F, 0.5 F, 0.9 F.
        // 4 bins of 0.5..0.9: edges 0.5, 0.6, 0.7, 0.8, 0.9; 0.5 F in bin 0, 0.6 F in
        // bin 1 (on its lower edge), 0.7 T in bin 2, nothing in bin 3 but 0.9 F (the top
        // edge, in the last bin).
        let e = run(&[Method::Oracle]);
        let h = e.score_histogram(4).unwrap();
        assert_eq!(h.edges, [0.5, 0.6, 0.7, 0.8, 0.9]);
        assert_eq!((h.right, h.wrong), (vec![0, 0, 1, 0], vec![1, 1, 0, 1]));
        // 2 bins: [0.5, 0.7) holds 0.5 F and 0.6 F; [0.7, 0.9] holds 0.7 T and 0.9 F.
        let h = e.score_histogram(2).unwrap();
        assert_eq!(h.edges, [0.5, 0.7, 0.9]);
        assert_eq!((h.right, h.wrong), (vec![0, 1], vec![2, 1]));
        assert_eq!(e.score_histogram(0), None);

        // Soft-only best matches are no decision: d1's best match (db1, 0.6) made soft
        // leaves 0.7 T, 0.5 F, 0.9 F; 2 bins of 0.5..0.9 (0.7 on the inner edge).
        let (s, gt) = tiny();
        let mut soft = ndarray::Array2::<u8>::zeros((3, 7));
        soft[[1, 3]] = 1;
        let gt = GroundTruth::from_truth(gt.view().to_owned())
            .with_soft(soft.view())
            .unwrap();
        let e = evaluate(s.view(), &gt, &protocol(), &[Method::Oracle]).unwrap();
        let h = e.score_histogram(2).unwrap();
        assert_eq!((h.right, h.wrong), (vec![0, 1], vec![1, 1]));
        // Multi matching: all 12 entries of d0..d3 (none ignored), 2 of them hard
        // (d0 0.7, d1 0.5); 2 bins of 0.1..0.9, edges 0.1, 0.5, 0.9:
        // d0 0.7 T, 0.3, 0.2; d1 0.1, 0.6, 0.5 T; d2 0.5, 0.4, 0.3; d3 0.2, 0.9, 0.1.
        // [0.1, 0.5): 0.3 0.2 0.1 0.4 0.3 0.2 0.1 -> 7 wrong; [0.5, 0.9]: 0.7 T, 0.5 T,
        // 0.6, 0.5, 0.9 -> 2 right, 3 wrong.
        let (s, gt) = tiny();
        let multi = Protocol {
            matching: crate::rules::decisions::Matching::Multi,
            ..protocol()
        };
        let h = evaluate(s.view(), &gt, &multi, &[Method::Oracle])
            .unwrap()
            .score_histogram(2)
            .unwrap();
        assert_eq!(h.edges, [0.1, 0.5, 0.9]);
        assert_eq!((h.right, h.wrong), (vec![0, 2], vec![7, 3]));
    }

    #[test]
    fn a_score_histogram_of_one_score_spans_it() {
        // One deployment query, best match 0.7 (T): one score, so 0.2..1.2 in 2 bins;
        // 0.7 sits on the inner edge, in bin 1.
        let s = array![[0.8, 0.7], [0.1, 0.2]];
        let gt = GroundTruth::new(array![[1u8, 1], [0, 0]].view()).unwrap();
        let p = Protocol {
            calibration: Split::Count(1),
            segment: Split::Count(1),
            ..Protocol::default()
        };
        let h = evaluate(s.view(), &gt, &p, &[Method::Oracle])
            .unwrap()
            .score_histogram(2)
            .unwrap();
        assert_eq!(h.edges.len(), 3);
        assert!((h.edges[0] - 0.2).abs() < 1e-15 && h.edges[1] == 0.7 && (h.edges[2] - 1.2).abs() < 1e-15);
        assert_eq!((h.right, h.wrong), (vec![0, 1], vec![0, 0]));
    }

    #[test]
    fn median_threshold_is_the_lower_median() {
        // Schubert's two segments: 1.808 and 1.406 (a_method_that_accepts_nothing...):
        // sorted 1.406, 1.808; the lower median (position (2 - 1) / 2 = 0) is 1.406.
        let e = run(&[Method::Schubert, Method::Margin]);
        let t = e.methods[0].median_threshold().unwrap();
        assert!((t - 1.406).abs() < 1e-3, "{t}");
        // The margin gate alone has no score threshold: -inf in every segment.
        assert_eq!(e.methods[1].median_threshold(), Some(f64::NEG_INFINITY));
        // Reject-all sorts last: (0.3, inf, inf) -> inf; (0.3, 0.5, inf) -> 0.5.
        let mut m = e.methods[0].clone();
        let with = |m: &mut MethodResult, ts: &[f64]| {
            m.segments = ts
                .iter()
                .map(|&t| SegmentResult {
                    threshold: t,
                    ..m.segments[0]
                })
                .collect();
            m.median_threshold()
        };
        assert_eq!(with(&mut m, &[f64::INFINITY, 0.3, f64::INFINITY]), Some(f64::INFINITY));
        assert_eq!(with(&mut m, &[f64::INFINITY, 0.5, 0.3]), Some(0.5));
        assert_eq!(with(&mut m, &[]), None);
    }

    #[test]
    fn a_method_that_accepts_nothing_has_no_precision() {
        // Schubert's thresholds: segment 0 (d0, d1) 1.808 (mod.rs' schubert test); segment
        // 1 (d2, d3) scores ascending (0.1, 0.2, 0.3, 0.4, 0.5, 0.9): mu = 0.35, |S - mu|
        // sorted (0.05, 0.05, 0.15, 0.15, 0.25, 0.55), median 0.15, t = 0.35 + 0.15 /
        // 0.675 * z = 1.406. Both above every score: nothing accepted. Segment 0 meets
        // by the paper's convention and segment 1 has no positive: %Segs 100 on no
        // decision, which its count (0) and its undefined precision say.
        let e = run(&[Method::Schubert]);
        let m = &e.methods[0];
        assert_eq!(m.pct_segs, Some(100.0));
        let pooled = m.pooled();
        assert_eq!((pooled.accepted(), pooled.measured_precision()), (0, None));
        assert_eq!(pooled.precision_lower95(), None);
        // The oracle accepts d0's 0.7 (TP): 1 accepted, precision 1 measured.
        let o = run(&[Method::Oracle]).methods[0].pooled();
        assert_eq!((o.accepted(), o.measured_precision()), (1, Some(1.0)));
    }

    #[test]
    fn pooled_counts_and_their_lower_bound() {
        // Oracle: segment 0 TP 1, FP 0, positives 2; segment 1 (d2 0.5, d3 0.9 wrong, no
        // positives) at inf accepts nothing. Pooled: TP 1, FP 0, positives 2; precision 1,
        // recall 1/2, lower bound 0.05^(1/1) = 0.05.
        let e = run(&[Method::Oracle]);
        let p = e.methods[0].pooled();
        assert_eq!((p.tp, p.fp, p.positives), (1, 0, 2));
        assert!((p.precision_lower95().unwrap() - 0.05).abs() < 1e-12);
        // Nothing accepted in segment 1: no bound there.
        assert_eq!(e.methods[0].segments[1].counts.precision_lower95(), None);
    }

    #[cfg(feature = "serde")]
    #[test]
    fn serialised_keys() {
        let e = run(&[Method::Oracle, Method::Schubert]);
        // The tiny case (3 x 7, tiny()'s ground truth) as read: queries 4..6 of 7 have no
        // positive (3 >= 0.05 * 7) and database image 1 none either: cannot tell.
        let (_, gt) = tiny();
        let orientation = crate::Orientation::of((3, 7), Some(&gt), false);
        let v = serde_json::to_value(crate::files::report::Report {
            dataset: Some("tiny"),
            orientation: Some(orientation),
            result: &e,
        })
        .unwrap();
        let keys = |v: &serde_json::Value| {
            let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
            k.sort();
            k
        };
        assert_eq!(
            keys(&v),
            [
                "confidence",
                "dataset",
                "methods",
                "orientation",
                "params",
                "recall_at_1"
            ]
        );
        assert_eq!(
            v["orientation"],
            serde_json::json!({"db": 3, "queries": 7, "query_major": false,
                "layout": "assumed (the ground truth cannot tell: queries without a positive: 3 of 7; database \
                           images without one: 1 of 3)",
                "evidence": {
                "labelled_queries": 7, "queries_without_positive": 3, "db_without_positive": 1,
                "verdict": "cannot-tell"}})
        );
        // Semantics §14's signals, in single matching.
        assert_eq!(keys(&v["confidence"]), ["signals"]);
        assert_eq!(
            keys(&v["confidence"]["signals"]),
            ["confidence", "consistency", "margin", "pa_score", "score"]
        );
        assert_eq!(
            keys(&v["confidence"]["signals"]["confidence"]),
            ["auroc", "bins", "brier", "ece"]
        );
        assert_eq!(keys(&v["confidence"]["signals"]["score"]), ["auroc"]);
        assert_eq!(
            keys(&v["params"]),
            [
                "calibration",
                "calibration_queries",
                "database_size",
                "deploy_fraction",
                "deployment_queries",
                "deployment_start",
                "k",
                "matching",
                "precision",
                "queries",
                "segment",
                "segment_size",
                "segments",
                "sequence_gate"
            ]
        );
        assert_eq!(v["params"]["calibration"], serde_json::json!({"count": 2}));
        assert_eq!(v["params"]["matching"], "single");
        assert_eq!(v["params"]["database_size"], 3);
        assert_eq!(keys(&v["methods"]), ["oracle", "schubert"]);
        let oracle = &v["methods"]["oracle"];
        assert_eq!(
            keys(oracle),
            [
                "avg_recall",
                "pct_segs",
                "pooled_accepted",
                "pooled_fp",
                "pooled_positives",
                "pooled_precision",
                "pooled_precision_lower95",
                "pooled_recall",
                "pooled_tp",
                "segments",
                "segments_counted",
                "segments_skipped",
                "threshold_mse"
            ]
        );
        assert!((oracle["pooled_precision_lower95"].as_f64().unwrap() - 0.05).abs() < 1e-12);
        let seg = &oracle["segments"][1];
        assert_eq!(
            keys(seg),
            [
                "accepted",
                "end",
                "fp",
                "meets",
                "oracle_threshold",
                "positives",
                "precision",
                "precision_lower95",
                "recall",
                "start",
                "threshold",
                "tp"
            ]
        );
        // Reject-all is null in JSON; so are a precision and its bound over nothing
        // accepted, which still meets (the paper's convention).
        assert_eq!(
            (seg["threshold"].is_null(), seg["precision_lower95"].is_null()),
            (true, true)
        );
        assert_eq!(
            (&seg["accepted"], &seg["precision"], &seg["meets"]),
            (
                &serde_json::json!(0),
                &serde_json::Value::Null,
                &serde_json::json!(true)
            )
        );
        // Schubert accepts nothing anywhere (a_method_that_accepts_nothing_has_no_precision).
        let schubert = &v["methods"]["schubert"];
        assert_eq!(
            (&schubert["pooled_accepted"], &schubert["pooled_precision"]),
            (&serde_json::json!(0), &serde_json::Value::Null)
        );
        assert_eq!(v["recall_at_1"], 0.5);
        let (s, gt) = tiny();
        let a = ablation(s.view(), &gt, &protocol(), &[1, 2], &[], &[Method::Oracle]).unwrap();
        let v = serde_json::to_value(crate::files::report::Report {
            dataset: None,
            orientation: None,
            result: &a,
        })
        .unwrap();
        assert_eq!(keys(&v), ["ablation", "dataset"]);
        assert_eq!(
            keys(&v["ablation"][1]),
            ["confidence", "methods", "params", "recall_at_1"]
        );
        assert_eq!(v["ablation"][1]["params"]["k"], 2);
    }
}
