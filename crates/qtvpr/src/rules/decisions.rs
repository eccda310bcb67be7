//! semantics §2: which candidates a matrix offers, which are correct, and the
//! TP/FP/precision/recall of a threshold.
//!
//! Both matching modes reduce to the same shape: per query column, a list of
//! `(score, correct)` candidates sorted by descending score. In single mode the list
//! holds the column's best match (or nothing, when that match is ignored); in multi
//! mode it holds every non-ignored entry. Sorting once per column here lets every
//! later sweep over a subset of columns merge short sorted lists instead of sorting.

use std::ops::Range;

use ndarray::{ArrayView1, ArrayView2};
use rayon::prelude::*;

use crate::input::{Score, Truth};
use crate::platform::threads;

/// How a query's matches are decided (semantics §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize), serde(rename_all = "lowercase"))]
pub enum Matching {
    /// Single-best-match VPR: one decision per query, on its best-scoring database image.
    #[default]
    Single,
    /// Multi-match VPR: every non-ignored entry of the matrix is a candidate.
    Multi,
}

impl Matching {
    /// The name used on the command line and in JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Matching::Single => "single",
            Matching::Multi => "multi",
        }
    }
}

impl std::str::FromStr for Matching {
    type Err = crate::error::Error;
    fn from_str(s: &str) -> crate::error::Result<Self> {
        match s {
            "single" => Ok(Matching::Single),
            "multi" => Ok(Matching::Multi),
            _ => Err(crate::error::Error::param(
                "matching",
                format!("must be 'single' or 'multi', got '{s}'"),
            )),
        }
    }
}

/// The index of the first maximum of a column: the match a deployed matcher picks.
pub fn best_match<T: Score>(column: ArrayView1<'_, T>) -> usize {
    let mut best = 0;
    let mut best_score = f64::NEG_INFINITY;
    for (i, s) in column.iter().enumerate() {
        let s = s.to_f64();
        if s > best_score {
            best = i;
            best_score = s;
        }
    }
    best
}

/// The first row of `column` whose score equals `value` (so -0.0 and 0.0 are one
/// value), 0 if none: [`best_match`] once the maximum is known, as it is at the end of
/// a sorted copy of the column (a push). The search carries no running maximum from
/// score to score, which made [`best_match`]'s loop a tenth of a push at paper scale.
pub(crate) fn first_at<T: Score>(column: ArrayView1<'_, T>, value: f64) -> usize {
    column.iter().position(|v| v.to_f64() == value).unwrap_or(0)
}

/// Per-column sorted candidate lists and positive counts of a matrix.
#[derive(Debug, Clone)]
pub(crate) struct Candidates {
    /// Column `j`'s candidates are `scores[offsets[j]..offsets[j + 1]]`.
    offsets: Vec<usize>,
    /// Candidate scores, descending within each column.
    scores: Vec<f64>,
    /// Whether each candidate is correct.
    correct: Vec<bool>,
    /// Number of positives contributed by each column.
    positives: Vec<usize>,
}

impl Candidates {
    /// Collect the candidates of every column of `s` (|DB| x |Q|) under `gt` (same shape).
    pub(crate) fn new<T: Score>(s: ArrayView2<'_, T>, gt: ArrayView2<'_, Truth>, matching: Matching) -> Self {
        threads::install(|| {
            let per_column: Vec<(Vec<(f64, bool)>, usize)> = (0..s.ncols())
                .into_par_iter()
                .map(|j| column_candidates(s.column(j), gt.column(j), matching))
                .collect();
            let mut offsets = Vec::with_capacity(per_column.len() + 1);
            offsets.push(0);
            let total = per_column.iter().map(|(c, _)| c.len()).sum();
            let mut scores = Vec::with_capacity(total);
            let mut correct = Vec::with_capacity(total);
            let mut positives = Vec::with_capacity(per_column.len());
            for (cands, pos) in per_column {
                scores.extend(cands.iter().map(|c| c.0));
                correct.extend(cands.iter().map(|c| c.1));
                offsets.push(scores.len());
                positives.push(pos);
            }
            Self {
                offsets,
                scores,
                correct,
                positives,
            }
        })
    }

    /// No columns: where [`Candidates::append`] starts.
    pub(crate) fn none() -> Self {
        Self {
            offsets: vec![0],
            scores: Vec::new(),
            correct: Vec::new(),
            positives: Vec::new(),
        }
    }

    /// The candidates of `more`'s columns after those of `self` (a calibration collected
    /// a few columns at a time).
    pub(crate) fn append(&mut self, more: Candidates) {
        let base = self.scores.len();
        self.offsets.extend(more.offsets[1..].iter().map(|o| base + o));
        self.scores.extend(more.scores);
        self.correct.extend(more.correct);
        self.positives.extend(more.positives);
    }

    /// Column `j`'s candidates: scores (descending) and correctness.
    pub(crate) fn column(&self, j: usize) -> (&[f64], &[bool]) {
        let r = self.offsets[j]..self.offsets[j + 1];
        (&self.scores[r.clone()], &self.correct[r])
    }

    /// Number of columns.
    pub(crate) fn ncols(&self) -> usize {
        self.positives.len()
    }

    /// Positives of a set of columns.
    pub(crate) fn positives(&self, columns: impl IntoIterator<Item = usize>) -> usize {
        columns.into_iter().map(|j| self.positives[j]).sum()
    }

    /// TP and FP of the columns in `range` at threshold `t` (accept `s >= t`).
    pub(crate) fn tp_fp(&self, range: Range<usize>, t: f64) -> (usize, usize) {
        let (mut tp, mut fp) = (0, 0);
        for j in range {
            let (scores, correct) = self.column(j);
            let accepted = scores.partition_point(|&s| s >= t);
            let c = correct[..accepted].iter().filter(|&&c| c).count();
            tp += c;
            fp += accepted - c;
        }
        (tp, fp)
    }
}

fn column_candidates<T: Score>(
    s: ArrayView1<'_, T>,
    gt: ArrayView1<'_, Truth>,
    matching: Matching,
) -> (Vec<(f64, bool)>, usize) {
    match matching {
        Matching::Single => {
            let positive = usize::from(gt.iter().any(|&t| t == Truth::True));
            let b = best_match(s);
            let cands = match gt[b] {
                Truth::Ignored => vec![],
                t => vec![(s[b].to_f64(), t == Truth::True)],
            };
            (cands, positive)
        }
        Matching::Multi => {
            let positives = gt.iter().filter(|&&t| t == Truth::True).count();
            let mut cands: Vec<(f64, bool)> = s
                .iter()
                .zip(gt.iter())
                .filter(|(_, t)| **t != Truth::Ignored)
                .map(|(s, t)| (s.to_f64(), *t == Truth::True))
                .collect();
            radsort::sort_by_key(&mut cands, |c| -c.0); // descending by score
            (cands, positives)
        }
    }
}

/// Decision counts of a set of queries at one threshold (semantics §2).
///
/// Serialised (feature `serde`) as `tp`, `fp`, `accepted` (TP + FP), `positives` and
/// the figures derived from them: `precision` ([`Counts::measured_precision`]: `null`
/// when nothing is accepted), `recall` and `precision_lower95` (semantics §9).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Counts {
    /// Accepted and correct.
    pub tp: usize,
    /// Accepted and not correct.
    pub fp: usize,
    /// Positives of the mode (queries with a hard match, or hard-true entries).
    pub positives: usize,
}

/// Counts of disjoint sets of decisions add up.
impl std::iter::Sum for Counts {
    fn sum<I: Iterator<Item = Counts>>(iter: I) -> Counts {
        iter.fold(
            Counts {
                tp: 0,
                fp: 0,
                positives: 0,
            },
            |a, c| Counts {
                tp: a.tp + c.tp,
                fp: a.fp + c.fp,
                positives: a.positives + c.positives,
            },
        )
    }
}

impl Counts {
    /// The decisions accepted: TP + FP.
    pub fn accepted(&self) -> usize {
        self.tp + self.fp
    }

    /// `TP / (TP + FP)`; `None` when nothing is accepted, as every output reports it: a
    /// precision that rests on no decision is undefined, not 1 (semantics §2).
    pub fn measured_precision(&self) -> Option<f64> {
        (self.accepted() > 0).then(|| self.precision())
    }

    /// `TP / (TP + FP)`, taken as 1 when nothing is accepted: the paper's convention,
    /// by which a segment that accepts nothing meets any target (semantics §8.3). What
    /// is reported is [`Counts::measured_precision`].
    pub fn precision(&self) -> f64 {
        if self.tp + self.fp == 0 {
            1.0
        } else {
            self.tp as f64 / (self.tp + self.fp) as f64
        }
    }

    /// `TP / positives`, 0 when there are no positives.
    pub fn recall(&self) -> f64 {
        if self.positives == 0 {
            0.0
        } else {
            self.tp as f64 / self.positives as f64
        }
    }

    /// The one-sided 95% Clopper-Pearson lower bound on the precision: the 0.05
    /// quantile of Beta(TP, FP + 1). With probability at least 95%, a matcher whose
    /// true precision is below this bound would have produced fewer than TP correct
    /// decisions out of TP + FP.
    ///
    /// "100% precision" on 2 accepted decisions is weak evidence: the bound is then
    /// 0.05^(1/2) = 0.22, and 0.05^(1/n) for n accepted decisions without a false
    /// positive in general. 0 when TP = 0 (no evidence of any precision); `None` when
    /// nothing is accepted (TP + FP = 0: the precision of 1 is a convention, not a
    /// measurement).
    pub fn precision_lower95(&self) -> Option<f64> {
        use statrs::distribution::{Beta, ContinuousCDF};
        if self.tp + self.fp == 0 {
            return None;
        }
        if self.tp == 0 {
            return Some(0.0);
        }
        // Both shapes are >= 1, which Beta::new accepts.
        let beta = Beta::new(self.tp as f64, (self.fp + 1) as f64).expect("shapes are positive and finite");
        Some(beta.inverse_cdf(0.05))
    }
}

/// Count the decisions of every query of `s` at threshold `t`, which may be infinite
/// (`+inf` accepts nothing) but not NaN: every comparison with NaN is false, so it
/// would silently accept nothing.
///
/// # Errors
/// As [`crate::best_threshold()`]: empty, non-finite or mismatched input; and
/// [`crate::error::Error::InvalidParameter`] for a NaN threshold.
pub fn counts<T: Score>(
    s: ArrayView2<'_, T>,
    gt: &crate::input::GroundTruth,
    matching: Matching,
    t: f64,
) -> crate::error::Result<Counts> {
    if t.is_nan() {
        return Err(crate::error::Error::param(
            "threshold",
            "must be a real number other than NaN, got nan",
        ));
    }
    crate::input::validate_scores(crate::error::names::Input::Similarity, s)?;
    crate::input::check_gt_shape(gt, crate::error::names::Input::Similarity, s.dim())?;
    let cands = Candidates::new(s, gt.view(), matching);
    Ok(cands.counts(0..cands.ncols(), t))
}

impl Candidates {
    /// Counts of the columns in `range` at threshold `t`.
    pub(crate) fn counts(&self, range: Range<usize>, t: f64) -> Counts {
        let (tp, fp) = self.tp_fp(range.clone(), t);
        Counts {
            tp,
            fp,
            positives: self.positives(range),
        }
    }
}

/// The serialisation of [`Counts`] (semantics §9): under its own keys, or under the
/// `pooled_` keys of a method's counts over a deployment set.
#[cfg(feature = "serde")]
pub(crate) mod serialize {
    use serde::ser::{Serialize, SerializeMap, Serializer};

    use super::Counts;

    /// The keys of [`Counts`] and the figures derived from it.
    const COUNTS: [&str; 7] = [
        "tp",
        "fp",
        "accepted",
        "positives",
        "precision",
        "recall",
        "precision_lower95",
    ];

    /// The same, for counts pooled over a deployment set.
    const POOLED: [&str; 7] = [
        "pooled_tp",
        "pooled_fp",
        "pooled_accepted",
        "pooled_positives",
        "pooled_precision",
        "pooled_recall",
        "pooled_precision_lower95",
    ];

    fn counts<S: Serializer>(c: &Counts, keys: &[&'static str; 7], serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(keys.len()))?;
        map.serialize_entry(keys[0], &c.tp)?;
        map.serialize_entry(keys[1], &c.fp)?;
        map.serialize_entry(keys[2], &c.accepted())?;
        map.serialize_entry(keys[3], &c.positives)?;
        map.serialize_entry(keys[4], &c.measured_precision())?;
        map.serialize_entry(keys[5], &c.recall())?;
        map.serialize_entry(keys[6], &c.precision_lower95())?;
        map.end()
    }

    impl Serialize for Counts {
        fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
            counts(self, &COUNTS, serializer)
        }
    }

    /// [`Counts`] with `pooled_` keys (`serialize_with` of a method's pooled counts).
    pub(crate) fn pooled<S: Serializer>(c: &Counts, serializer: S) -> Result<S::Ok, S::Error> {
        counts(c, &POOLED, serializer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::GroundTruth;
    use ndarray::array;

    #[test]
    fn best_match_takes_the_first_maximum() {
        // 0.9 occurs at rows 1 and 2: the first wins.
        assert_eq!(best_match(array![0.5, 0.9, 0.9].view()), 1);
        assert_eq!(best_match(array![-3.0f32, -4.0].view()), 0);
        // The search for the maximum of a sorted copy finds the same row, zeros of
        // either sign being one value (the maximum of [-0.0, 0.0] sorted is 0.0).
        let columns = [
            vec![0.5, 0.9, 0.9],
            vec![-0.0, -1.0, 0.0],
            vec![0.0, -0.0],
            vec![-2.0, -1.0, -1.0, -3.0],
            vec![0.25],
        ];
        for c in columns {
            let mut sorted = c.clone();
            sorted.sort_by(f64::total_cmp);
            let c = ndarray::ArrayView1::from(&c);
            assert_eq!(first_at(c, sorted[sorted.len() - 1]), best_match(c), "{c}");
        }
        assert_eq!(first_at(array![0.5, 0.9].view(), 2.0), 0);
    }

    #[test]
    fn single_mode_soft_only_best_match_makes_no_decision() {
        // Column: scores [0.9, 0.5]; hard GT [F, T]; soft [T, T]. The best match (row 0)
        // is soft but not hard, so ignored: no decision. The column still has a hard
        // match, so positives = 1: TP 0, FP 0, precision 1 (nothing accepted), recall 0.
        let s = array![[0.9], [0.5]];
        let gt = GroundTruth::new(array![[false], [true]].view())
            .unwrap()
            .with_soft(array![[1u8], [1]].view())
            .unwrap();
        let c = counts(s.view(), &gt, Matching::Single, 0.0).unwrap();
        assert_eq!((c.tp, c.fp, c.positives), (0, 0, 1));
        assert_eq!((c.precision(), c.recall()), (1.0, 0.0));
    }

    #[test]
    fn counts_in_both_modes() {
        // Columns: q0 = [0.9 T, 0.2 F, 0.4 F], q1 = [0.3 F, 0.8 F, 0.1 T], q2 = [0.1 F, 0.2 F, 0.6 F].
        let s = array![[0.9, 0.3, 0.1], [0.2, 0.8, 0.2], [0.4, 0.1, 0.6]];
        let gt = GroundTruth::new(array![[1, 0, 0], [0, 0, 0], [0, 1, 0]].view()).unwrap();
        // Single at t = 0.5: best matches q0 -> 0.9 (T, accepted), q1 -> 0.8 (F, accepted),
        // q2 -> 0.6 (F, accepted). Positives: q0 and q1 have a hard match = 2.
        assert_eq!(
            counts(s.view(), &gt, Matching::Single, f64::NAN)
                .unwrap_err()
                .to_string(),
            "threshold must be a real number other than NaN, got nan"
        );
        // +inf accepts nothing: precision 1 by the paper's convention (what `meets`
        // reads), undefined as reported; recall 0.
        let c = counts(s.view(), &gt, Matching::Multi, f64::INFINITY).unwrap();
        assert_eq!((c.tp, c.fp, c.precision(), c.recall()), (0, 0, 1.0, 0.0));
        assert_eq!((c.accepted(), c.measured_precision()), (0, None));
        let c = counts(s.view(), &gt, Matching::Single, 0.5).unwrap();
        assert_eq!((c.tp, c.fp, c.positives), (1, 2, 2));
        assert_eq!(c.precision(), 1.0 / 3.0);
        // 1 + 2 accepted, 1 of them right: 1/3 measured.
        assert_eq!((c.accepted(), c.measured_precision()), (3, Some(1.0 / 3.0)));
        assert_eq!(c.recall(), 0.5);
        // Single at t = 0.8 (inclusive): 0.9 T and 0.8 F accepted, 0.6 not.
        let c = counts(s.view(), &gt, Matching::Single, 0.8).unwrap();
        assert_eq!((c.tp, c.fp), (1, 1));
        // Multi at t = 0.35: accepted 0.9 T, 0.4 F, 0.8 F, 0.6 F; positives = 2 hard trues.
        let c = counts(s.view(), &gt, Matching::Multi, 0.35).unwrap();
        assert_eq!((c.tp, c.fp, c.positives), (1, 3, 2));
        // Multi at t = 0.1 accepts all 9: TP 2 (0.9, 0.1), FP 7.
        let c = counts(s.view(), &gt, Matching::Multi, 0.1).unwrap();
        assert_eq!((c.tp, c.fp), (2, 7));
    }

    #[test]
    fn multi_mode_skips_ignored_entries() {
        // Column [0.9 ignored, 0.8 T, 0.7 F]: candidates are 0.8 T and 0.7 F only.
        let s = array![[0.9], [0.8], [0.7]];
        let gt = GroundTruth::new(array![[false], [true], [false]].view())
            .unwrap()
            .with_soft(array![[true], [false], [false]].view())
            .unwrap();
        let c = counts(s.view(), &gt, Matching::Multi, 0.0).unwrap();
        assert_eq!((c.tp, c.fp, c.positives), (1, 1, 1));
    }

    #[test]
    fn clopper_pearson_lower_bound() {
        let lower = |tp, fp| Counts { tp, fp, positives: tp }.precision_lower95();
        // No false positive in n: P(Beta(n, 1) <= x) = x^n, so the 0.05 quantile is
        // 0.05^(1/n). n = 10: exp(ln(0.05) / 10) = exp(-2.995732 / 10) = exp(-0.2995732)
        // = 0.741134; n = 1: 0.05; n = 2: sqrt(0.05) = 0.223607.
        assert!((lower(10, 0).unwrap() - 0.741_134_449_9).abs() < 1e-9);
        for n in [1usize, 2, 28, 1000] {
            let want = 0.05f64.powf(1.0 / n as f64);
            assert!((lower(n, 0).unwrap() - want).abs() < 1e-12, "{n}");
        }
        // TP = 8, FP = 2: the 0.05 quantile x of Beta(8, 3). For integer shapes,
        // P(Beta(a, b) <= x) = P(Binomial(a + b - 1, x) >= a), so x solves
        // P(Binomial(10, x) >= 8) = sum_{i=8..10} C(10, i) x^i (1 - x)^(10 - i) = 0.05;
        // 80 steps of bisection on that sum in exact rational arithmetic give
        // x = 0.4930986989 (the sum is 0.0500000007 at 0.4930987).
        let x = lower(8, 2).unwrap();
        assert!((x - 0.493_098_698_9).abs() < 1e-9, "{x}");
        let tail: f64 = (8..=10)
            .map(|i| {
                let c = [1.0, 10.0, 45.0][10 - i]; // C(10, 10), C(10, 9), C(10, 8)
                c * x.powi(i as i32) * (1.0 - x).powi(10 - i as i32)
            })
            .sum();
        assert!((tail - 0.05).abs() < 1e-12, "{tail}");
        // Nothing correct: 0; nothing accepted: no bound.
        assert_eq!(lower(0, 3), Some(0.0));
        assert_eq!(lower(0, 0), None);
    }

    #[test]
    fn no_positives_means_zero_recall() {
        let s = array![[0.9], [0.1]];
        let gt = GroundTruth::new(array![[false], [false]].view()).unwrap();
        let c = counts(s.view(), &gt, Matching::Single, 0.0).unwrap();
        assert_eq!((c.tp, c.fp, c.positives, c.recall()), (0, 1, 0, 0.0));
    }
}
