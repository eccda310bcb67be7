//! semantics §14: confidence, a calibrated probability that a single-match decision is
//! right.
//!
//! A SLAM back end weighs a loop closure by how likely it is to be right and wants a
//! number in [0, 1], not a raw score. The confidence maps a query's *PA-score* to the
//! hit rate the calibration traverse shows at that PA-score. The PA-score is Lowe's
//! ratio on distances, `d1 / d2` with `d = sqrt(max(0, 2 - 2 s))`, the distance of a
//! cosine similarity `s`, for the best score `s1` and the second-best `s2` (0 / 0 is 1):
//! in [0, 1], lower is more distinctive. It was chosen over the margin of semantics §13
//! by measurement (`benches/confidence.py`: it ranks right above wrong best matches
//! better on the real matrices, and so does the map built on it).
//!
//! The *pairs* are the calibration's single-match decisions (each calibration query's
//! best match, soft-only ones left out, as for the gate's `m*`): PA-score `r_j`, and
//! `c_j = 1` when the best match is a hard positive. Sorted by descending PA-score
//! (ascending distinctiveness), equal ones one point, they are pooled twice by
//! pool-adjacent-violators: first by the least-squares rule (a block's value `x / n`,
//! the isotonic regression), then by the Laplace rule (a block's value `(x + 1) /
//! (n + 2)`, the posterior mean under a uniform prior, never 0 or 1 from a few
//! pairs). Both pool while a block's value is at least the next one's, so the *blocks*
//! are maximal and their Laplace values strictly increase. Each has its count `n`, its
//! successes `x`, and its *centre*, the mean PA-score of its pairs.
//!
//! The map is centred isotonic regression (Oron and Flournoy, 2017): linear in the
//! PA-score between adjacent centres, through each block's Laplace value at its centre.
//! Beyond the end centres it goes on linearly to the ends of the PA-score's range: to
//! the first block's one-sided 95% Clopper-Pearson lower bound at PA-score 1, and to
//! the last block's upper bound at PA-score 0 (no further than the calibration's own
//! evidence allows). So the map strictly decreases in the PA-score over its whole
//! range, and the confidence ranks decisions as the PA-score does: a flat step or tail
//! would tie them. `confidence_lower95` is the lower bound of the less confident of
//! the two blocks a PA-score lies between (the first block's beyond it), the bound of
//! semantics §8, computed by [`Counts::precision_lower95`](crate::Counts::precision_lower95).
//!
//! Values are compared as fractions in integers, so ties between blocks are exact,
//! whatever the counts. The map is found once per calibration, on the first request
//! ([`crate::Calibration::confidence_map`]), from the calibration's own scores: a
//! calibration file need not store it.
//!
//! Multi matching accepts every entry above a threshold, not a best match, so it has no
//! confidence ([`check`] says so); a decision record then carries NaN.

use crate::error::{Error, Result};
use crate::input::Score;
use crate::rules::decisions::{Candidates, Counts, Matching};

/// The PA-score of scores `s1 >= s2`, the best and the second-best of a column:
/// `d1 / d2` with `d = sqrt(max(0, 2 - 2 s))` (a cosine similarity's distance), 1 when
/// both distances are 0. In [0, 1]; lower is more distinctive.
///
/// Each `d` is computed halved, as `sqrt(max(0, (1 - s) / 2))`, which no finite `s`
/// overflows (`2 - 2 s` is infinite below about -9e307, and two such scores gave NaN).
/// Where `2 - 2 s` is finite the halved form is exactly its quarter (a scale by a power
/// of two commutes with rounding), the square root of a quarter is exactly half the
/// root, and the halves cancel: the ratio is the same bits.
pub fn pa_score(s1: f64, s2: f64) -> f64 {
    let distance = |s: f64| ((1.0 - s) / 2.0).max(0.0).sqrt();
    let (d1, d2) = (distance(s1), distance(s2));
    if d2 > 0.0 { d1 / d2 } else { 1.0 }
}

/// The PA-score of a column sorted ascending, of at least 2 scores.
pub(crate) fn pa_score_of_sorted<T: Score>(sorted: &[T]) -> f64 {
    let n = sorted.len();
    debug_assert!(n >= 2, "a PA-score needs 2 scores");
    pa_score(sorted[n - 1].to_f64(), sorted[n - 2].to_f64())
}

/// The PA-score of every column of `s` (|DB| >= 2 x |Q|, finite), without sorting: its
/// two largest scores (equal when the largest occurs twice).
pub(crate) fn pa_scores_of_columns<T: Score>(s: ndarray::ArrayView2<'_, T>) -> Vec<f64> {
    s.columns()
        .into_iter()
        .map(|column| {
            let (mut s1, mut s2) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
            for v in column.iter().map(|v| v.to_f64()) {
                if v > s1 {
                    (s1, s2) = (v, s1);
                } else if v > s2 {
                    s2 = v;
                }
            }
            pa_score(s1, s2)
        })
        .collect()
}

/// Semantics §14's pairs: `(PA-score, correct)` of each calibration query with a
/// single-match decision (its best match not soft-only), from the PA-score of every
/// calibration query.
pub(crate) fn pairs<'a>(pa_scores: &'a [f64], candidates: &'a Candidates) -> impl Iterator<Item = (f64, bool)> + 'a {
    pa_scores
        .iter()
        .enumerate()
        .filter_map(|(j, &r)| candidates.column(j).1.first().map(|&correct| (r, correct)))
}

/// One block of the fit: calibration pairs of adjacent PA-scores.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Block {
    /// Its centre: the mean PA-score of its pairs.
    pub pa_score: f64,
    /// Its number of pairs.
    pub n: usize,
    /// Its number of correct pairs (`c = 1`).
    pub x: usize,
}

impl Block {
    /// `(x + 1) / (n + 2)`: the map's value at the block's centre.
    pub fn confidence(&self) -> f64 {
        (self.x + 1) as f64 / (self.n + 2) as f64
    }

    /// The one-sided 95% Clopper-Pearson lower bound on the hit rate `x / n` (0 when
    /// `x` = 0).
    pub fn confidence_lower95(&self) -> f64 {
        Counts {
            tp: self.x,
            fp: self.n - self.x,
            positives: self.x,
        }
        .precision_lower95()
        .expect("a block holds at least one pair")
    }

    /// The one-sided 95% Clopper-Pearson upper bound on `x / n`: 1 less the lower bound
    /// on the share of wrong pairs (1 when `x` = `n`).
    pub fn confidence_upper95(&self) -> f64 {
        let wrong = Block {
            x: self.n - self.x,
            ..*self
        };
        1.0 - wrong.confidence_lower95()
    }
}

/// A block while pooling: its pairs' PA-scores summed, for the centre.
#[derive(Debug, Clone, Copy)]
struct Pool {
    sum: f64,
    n: usize,
    x: usize,
}

impl Pool {
    /// Pool-adjacent-violators over `points`, by ascending distinctiveness: pool while
    /// the block before is at least the last one, `(x + prior) / (n + 2 prior)` compared
    /// in integers (a violator, or an equal value: blocks are maximal).
    fn adjacent_violators(points: Vec<Pool>, prior: usize) -> Vec<Pool> {
        let at_least = |a: &Pool, b: &Pool| {
            (a.x + prior) as u128 * (b.n + 2 * prior) as u128 >= (b.x + prior) as u128 * (a.n + 2 * prior) as u128
        };
        let mut blocks: Vec<Pool> = Vec::with_capacity(points.len());
        for point in points {
            blocks.push(point);
            while let [.., before, last] = blocks[..] {
                if !at_least(&before, &last) {
                    break;
                }
                blocks.pop();
                let before = blocks.last_mut().expect("two blocks");
                (before.sum, before.n, before.x) = (before.sum + last.sum, before.n + last.n, before.x + last.x);
            }
        }
        blocks
    }
}

/// The confidence map of a calibration: the blocks of semantics §14, by ascending
/// confidence (descending PA-score), and the knots of its piecewise-linear map.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfidenceMap {
    blocks: Vec<Block>,
    /// `(PA-score, confidence, confidence_lower95)` at each knot, by descending PA-score:
    /// the end of the range (PA-score 1) unless the first centre is there, each centre,
    /// and PA-score 0 unless the last centre is there.
    knots: Vec<(f64, f64, f64)>,
}

impl ConfidenceMap {
    /// The map of calibration pairs `(PA-score, correct)`, in any order. PA-scores must
    /// lie in [0, 1] (those of finite scores do).
    pub fn fit(pairs: impl IntoIterator<Item = (f64, bool)>) -> Self {
        let mut pairs: Vec<(f64, bool)> = pairs.into_iter().collect();
        debug_assert!(
            pairs.iter().all(|p| (0.0..=1.0).contains(&p.0)),
            "a PA-score outside [0, 1]"
        );
        pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
        // Equal PA-scores are one point.
        let mut points: Vec<(f64, Pool)> = Vec::new();
        for (r, correct) in pairs {
            let c = usize::from(correct);
            match points.last_mut() {
                Some((last, p)) if *last == r => (p.sum, p.n, p.x) = (p.sum + r, p.n + 1, p.x + c),
                _ => points.push((r, Pool { sum: r, n: 1, x: c })),
            }
        }
        let least_squares = Pool::adjacent_violators(points.into_iter().map(|p| p.1).collect(), 0);
        let blocks: Vec<Block> = Pool::adjacent_violators(least_squares, 1)
            .into_iter()
            .map(|p| Block {
                pa_score: p.sum / p.n as f64,
                n: p.n,
                x: p.x,
            })
            .collect();
        let mut knots: Vec<(f64, f64, f64)> = blocks
            .iter()
            .map(|b| (b.pa_score, b.confidence(), b.confidence_lower95()))
            .collect();
        if let (Some(first), Some(last)) = (blocks.first(), blocks.last()) {
            if first.pa_score < 1.0 {
                let lower = first.confidence_lower95();
                knots.insert(0, (1.0, lower, lower));
            }
            if last.pa_score > 0.0 {
                knots.push((0.0, last.confidence_upper95(), last.confidence_lower95()));
            }
        }
        Self { blocks, knots }
    }

    /// The blocks, by ascending confidence (descending PA-score; empty: no pairs).
    pub fn blocks(&self) -> &[Block] {
        &self.blocks
    }

    /// `(confidence, confidence_lower95)` of PA-score `r`: the map between the two knots
    /// `r` lies between, linear in `r`, and the lower bound of the first of them (by
    /// descending PA-score); both NaN without pairs. Outside [0, 1], the end knot's.
    pub fn of(&self, r: f64) -> (f64, f64) {
        // The knots at or above r, by descending PA-score: the first `above`.
        let above = self.knots.partition_point(|k| k.0 >= r);
        match (above.checked_sub(1).map(|i| self.knots[i]), self.knots.get(above)) {
            (Some(a), Some(b)) => {
                let t = (a.0 - r) / (a.0 - b.0);
                (a.1 + t * (b.1 - a.1), a.2)
            }
            (Some(a), None) => (a.1, a.2),
            (None, Some(b)) => (b.1, b.2),
            (None, None) => (f64::NAN, f64::NAN),
        }
    }

    /// The confidence of PA-score `r` (NaN without pairs).
    pub fn confidence(&self, r: f64) -> f64 {
        self.of(r).0
    }

    /// The one-sided 95% Clopper-Pearson lower bound on the confidence of PA-score `r`
    /// (NaN without pairs).
    pub fn confidence_lower95(&self, r: f64) -> f64 {
        self.of(r).1
    }
}

/// The number of equal-width bins of [0, 1] of the reliability summary and the ECE.
pub const RELIABILITY_BINS: usize = 10;

/// One bin of a reliability diagram: the decisions whose confidence lies in
/// `[lower, upper)` (the last bin, `[0.9, 1]`, holds 1.0), their mean confidence and
/// their observed hit rate. The expected calibration error ([`ece`]) is computed from
/// these bins, so a reliability diagram and the ECE cannot bin differently.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ReliabilityBin {
    /// The bin's lower edge, `i / 10`.
    pub lower: f64,
    /// Its upper edge, `(i + 1) / 10` (inclusive for the last bin only).
    pub upper: f64,
    /// Its number of decisions (at least 1: empty bins are left out).
    pub n: usize,
    /// The mean confidence of its decisions.
    pub mean_confidence: f64,
    /// The share of its decisions that are right (the mean of `c`).
    pub hit_rate: f64,
}

/// The reliability summary of confidences `p` (in [0, 1]) of decisions whose
/// correctness is `c`: over [`RELIABILITY_BINS`] equal-width bins of [0, 1] (decision
/// `i` in bin `min(floor(10 p_i), 9)`, so the last holds 1.0), the bins that hold a
/// decision, in ascending order.
///
/// # Panics
/// When `p` and `c` differ in length.
pub fn reliability(p: &[f64], c: &[bool]) -> Vec<ReliabilityBin> {
    assert_eq!(p.len(), c.len(), "one correctness per confidence");
    // Per bin: count, sum of p, right decisions.
    let mut sums = [(0usize, 0.0f64, 0usize); RELIABILITY_BINS];
    for (&p, &c) in p.iter().zip(c) {
        let bin = &mut sums[((p * RELIABILITY_BINS as f64).floor() as usize).min(RELIABILITY_BINS - 1)];
        bin.0 += 1;
        bin.1 += p;
        bin.2 += usize::from(c);
    }
    sums.iter()
        .enumerate()
        .filter(|(_, b)| b.0 > 0)
        .map(|(i, &(n, sum, right))| ReliabilityBin {
            lower: i as f64 / RELIABILITY_BINS as f64,
            upper: (i + 1) as f64 / RELIABILITY_BINS as f64,
            n,
            mean_confidence: sum / n as f64,
            hit_rate: right as f64 / n as f64,
        })
        .collect()
}

/// The expected calibration error of a reliability summary: each bin's `|mean
/// confidence - hit rate|` weighted by its share of the decisions (0 without a bin).
pub fn ece(bins: &[ReliabilityBin]) -> f64 {
    let total = bins.iter().map(|b| b.n).sum::<usize>() as f64;
    bins.iter()
        .map(|b| (b.mean_confidence - b.hit_rate).abs() * b.n as f64 / total)
        .sum()
}

/// The evaluation signals of semantics §14 over the protocol's deployment decisions:
/// how well each signal ranks right above wrong best matches, and how well the
/// confidence is calibrated. Serialised as
/// `{"signals": {"score": {"auroc"}, "margin": {"auroc"}, "pa_score": {"auroc"},
/// "consistency": {"auroc"}, "confidence": {"auroc", "brier", "ece", "bins"}}}`; a
/// figure without the decisions it needs is `null`.
#[derive(Debug, Clone, PartialEq)]
pub struct Signals {
    /// AUROC of the best score `s1`.
    pub score_auroc: Option<f64>,
    /// AUROC of the margin.
    pub margin_auroc: Option<f64>,
    /// AUROC of the PA-score, lower ranked higher (that of its negation).
    pub pa_score_auroc: Option<f64>,
    /// AUROC of the consistency of semantics §15 (`None` also where the database is too
    /// small for the sequence gate's parameters).
    pub consistency_auroc: Option<f64>,
    /// AUROC of the confidence.
    pub confidence_auroc: Option<f64>,
    /// The confidence's Brier score: the mean of `(confidence - c)^2`.
    pub brier: Option<f64>,
    /// The confidence's expected calibration error over 10 equal-width bins of [0, 1]:
    /// `ece` of [`Signals::bins`].
    pub ece: Option<f64>,
    /// The confidence's reliability summary (`reliability`): the non-empty bins of
    /// the ECE, for a reliability diagram.
    pub bins: Option<Vec<ReliabilityBin>>,
}

/// One deployment decision, as [`Signals::of`] reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Signal {
    /// The best score `s1`.
    pub score: f64,
    /// The margin (semantics §13).
    pub margin: f64,
    /// The PA-score.
    pub pa_score: f64,
    /// The consistency (semantics §15), where it can be had.
    pub consistency: Option<f64>,
    /// Whether the best match is right.
    pub correct: bool,
}

impl Signals {
    /// The figures' names, in the order of [`Signals::figures`]: the CSV columns and the
    /// keys of the table.
    pub const FIGURES: [&'static str; 7] = [
        "auroc_score",
        "auroc_margin",
        "auroc_pa_score",
        "auroc_consistency",
        "auroc_confidence",
        "brier",
        "ece",
    ];

    /// The figures named by [`Signals::FIGURES`].
    pub fn figures(&self) -> [Option<f64>; 7] {
        [
            self.score_auroc,
            self.margin_auroc,
            self.pa_score_auroc,
            self.consistency_auroc,
            self.confidence_auroc,
            self.brier,
            self.ece,
        ]
    }

    /// The signals of `decisions` under `map`. AUROCs are `None` without a right or
    /// without a wrong decision; Brier, ECE and the bins are `None` without a decision
    /// or without a confidence (a map without blocks).
    pub fn of(decisions: &[Signal], map: &ConfidenceMap) -> Self {
        let c: Vec<bool> = decisions.iter().map(|d| d.correct).collect();
        let p: Vec<f64> = decisions.iter().map(|d| map.confidence(d.pa_score)).collect();
        let of = |f: fn(&Signal) -> f64| auroc(&decisions.iter().map(f).collect::<Vec<f64>>(), &c);
        let calibrated = !p.is_empty() && !map.blocks().is_empty();
        let bins = calibrated.then(|| reliability(&p, &c));
        Self {
            score_auroc: of(|d| d.score),
            margin_auroc: of(|d| d.margin),
            pa_score_auroc: of(|d| -d.pa_score),
            consistency_auroc: decisions
                .iter()
                .map(|d| d.consistency)
                .collect::<Option<Vec<f64>>>()
                .and_then(|x| auroc(&x, &c)),
            confidence_auroc: auroc(&p, &c).filter(|_| calibrated),
            brier: calibrated.then(|| {
                p.iter()
                    .zip(&c)
                    .map(|(p, &c)| (p - f64::from(u8::from(c))).powi(2))
                    .sum::<f64>()
                    / p.len() as f64
            }),
            ece: bins.as_deref().map(ece),
            bins,
        }
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Signals {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        struct Auroc(Option<f64>);
        impl serde::Serialize for Auroc {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
                let mut m = serializer.serialize_map(Some(1))?;
                m.serialize_entry("auroc", &self.0)?;
                m.end()
            }
        }
        struct Calibrated<'a>(&'a Signals);
        impl serde::Serialize for Calibrated<'_> {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
                let mut m = serializer.serialize_map(Some(4))?;
                m.serialize_entry("auroc", &self.0.confidence_auroc)?;
                m.serialize_entry("brier", &self.0.brier)?;
                m.serialize_entry("ece", &self.0.ece)?;
                m.serialize_entry("bins", &self.0.bins)?;
                m.end()
            }
        }
        struct All<'a>(&'a Signals);
        impl serde::Serialize for All<'_> {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
                let mut m = serializer.serialize_map(Some(5))?;
                m.serialize_entry("score", &Auroc(self.0.score_auroc))?;
                m.serialize_entry("margin", &Auroc(self.0.margin_auroc))?;
                m.serialize_entry("pa_score", &Auroc(self.0.pa_score_auroc))?;
                m.serialize_entry("consistency", &Auroc(self.0.consistency_auroc))?;
                m.serialize_entry("confidence", &Calibrated(self.0))?;
                m.end()
            }
        }
        let mut m = serializer.serialize_map(Some(1))?;
        m.serialize_entry("signals", &All(self))?;
        m.end()
    }
}

/// The probability that a right decision's `x` is above a wrong one's, ties one half
/// (the Mann-Whitney statistic, from mid-ranks); `None` without both kinds.
fn auroc(x: &[f64], c: &[bool]) -> Option<f64> {
    let right = c.iter().filter(|&&c| c).count();
    let wrong = c.len() - right;
    if right == 0 || wrong == 0 {
        return None;
    }
    let mut order: Vec<usize> = (0..x.len()).collect();
    order.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    // Twice the rank sum of the right decisions, with a group of ties at ranks
    // a + 1 ..= b sharing (a + 1 + b) / 2: integers throughout.
    let mut twice_ranks = 0u128;
    let mut a = 0;
    while a < order.len() {
        let mut b = a + 1;
        while b < order.len() && x[order[b]] == x[order[a]] {
            b += 1;
        }
        let right_here = order[a..b].iter().filter(|&&i| c[i]).count() as u128;
        twice_ranks += right_here * (a as u128 + 1 + b as u128);
        a = b;
    }
    let (right, wrong) = (right as u128, wrong as u128);
    // U = rank sum - right (right + 1) / 2, doubled.
    let twice_u = twice_ranks - right * (right + 1);
    Some(twice_u as f64 / (2 * right * wrong) as f64)
}

/// Check that decisions in `matching` mode over a database of `n_db` images have a
/// confidence.
///
/// # Errors
/// [`Error::InvalidParameter`] naming `confidence`: multi matching, or fewer than 2
/// database images (a column then has no margin).
pub fn check(matching: Matching, n_db: usize) -> Result<()> {
    if matching == Matching::Multi {
        return Err(Error::param(
            "confidence",
            "needs single matching: it is the probability that a query's best match is right, and multi \
             matching accepts every database entry at or above the threshold",
        ));
    }
    if n_db < 2 {
        return Err(Error::param(
            "confidence",
            format!("needs at least 2 database images (a best and a second-best score), got {n_db}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The blocks of `pairs`, centres rounded to 1e-12 (a sum of PA-scores over a count).
    fn blocks(pairs: &[(f64, bool)]) -> Vec<(f64, usize, usize)> {
        ConfidenceMap::fit(pairs.iter().copied())
            .blocks()
            .iter()
            .map(|b| (round(b.pa_score), b.n, b.x))
            .collect()
    }

    fn round(x: f64) -> f64 {
        (x * 1e12).round() / 1e12
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn pa_score_by_hand() {
        // s = 0.875: d = sqrt(2 - 1.75) = 0.5; s = 0.5: d = 1. So 0.5 / 1.
        assert_eq!(pa_score(0.875, 0.5), 0.5);
        // The largest twice: d1 = d2, 1. Both at or above 1 (d = 0): 0 / 0 is 1.
        assert_eq!(pa_score(0.3, 0.3), 1.0);
        assert_eq!(pa_score(1.5, 1.2), 1.0);
        // Only the best at or above 1: d1 = 0, the most distinctive.
        assert_eq!(pa_score(1.0, 0.5), 0.0);
        // Below -1 the distance exceeds 2, and the ratio stays in [0, 1]:
        // sqrt(2 + 2) / sqrt(2 + 6) = 2 / sqrt(8).
        assert!(close(pa_score(-1.0, -3.0), 2.0 / 8f64.sqrt()));
        // Without sorting, the same two scores as a sorted column's last two.
        let s = ndarray::array![[0.2f32, 0.9, 0.4], [0.875, 0.9, -3.0], [0.5, 0.1, -1.0]];
        let want: Vec<f64> = s
            .columns()
            .into_iter()
            .map(|c| {
                let mut v = c.to_vec();
                v.sort_by(f32::total_cmp);
                pa_score_of_sorted(&v)
            })
            .collect();
        assert_eq!(pa_scores_of_columns(s.view()), want);
        assert_eq!(want[0], 0.5);
        assert_eq!(want[1], 1.0);
    }

    #[test]
    fn pa_score_is_finite_at_the_extremes_of_f32_and_f64() {
        // d = sqrt(max(0, (1 - s) / 2)). s = -2^1021: 1 + 2^1021 rounds to 2^1021, so
        // d = sqrt(2^1020) = 2^510; s = -2^1023: d = 2^511. 2^510 / 2^511 = 0.5, where
        // 2 - 2 s overflowed to inf for the second score (the old form gave 0).
        let p = |e: i32| -(2f64.powi(e));
        assert_eq!(pa_score(p(1021), p(1023)), 0.5);
        // Two scores whose 2 - 2 s overflowed (inf / inf was NaN): equal distances, 1.
        assert_eq!(pa_score(p(1023), p(1023)), 1.0);
        assert_eq!(pa_score(-f64::MAX, -f64::MAX), 1.0);
        // -2^1023 against -f64::MAX = -(2 - 2^-52) 2^1023: d2 = 2^511 sqrt(2 - 2^-52),
        // so the ratio is 1 / sqrt(2 - 2^-52), 1 / sqrt(2) to 1e-16.
        assert!(close(pa_score(p(1023), -f64::MAX), 0.5f64.sqrt()));
        // The best at f64::MAX (1 - s < 0, d1 = 0): 0; both there (0 / 0): 1.
        assert_eq!(pa_score(f64::MAX, -f64::MAX), 0.0);
        assert_eq!(pa_score(f64::MAX, f64::MAX), 1.0);
        // f32: -2^125 and -2^127 (f32::MAX is about 2^128): 1 + 2^125 rounds to 2^125,
        // d = sqrt(2^124) = 2^62, and 2^63: 0.5. In a float32 column too.
        assert_eq!(
            pa_score(f64::from(-(2f32.powi(125))), f64::from(-(2f32.powi(127)))),
            0.5
        );
        let s = ndarray::array![
            [f32::MIN, f32::MAX, -(2f32.powi(125))],
            [f32::MIN, f32::MIN, -(2f32.powi(127))]
        ];
        assert_eq!(pa_scores_of_columns(s.view()), [1.0, 0.0, 0.5]);
        let s = ndarray::array![[f64::MIN, p(1021)], [f64::MIN, p(1023)], [f64::MIN, p(1023)]];
        assert_eq!(pa_scores_of_columns(s.view()), [1.0, 0.5]);
    }

    #[test]
    fn pa_score_is_the_bits_of_the_unhalved_form_where_that_is_finite() {
        // sqrt(max(0, 2 - 2 s1)) / sqrt(max(0, 2 - 2 s2)) where 2 - 2 s is finite: the
        // form before the halved one, held to the same bits on scores near 1 (the ulps
        // below 1), subnormal, ordinary and large.
        let unhalved = |s1: f64, s2: f64| {
            let d = |s: f64| (2.0 - 2.0 * s).max(0.0).sqrt();
            if d(s2) > 0.0 { d(s1) / d(s2) } else { 1.0 }
        };
        let mut scores = vec![
            0.0,
            1.0,
            -1.0,
            5e-324,
            -5e-324,
            f64::MIN_POSITIVE,
            1e300,
            -1e300,
            -8e307,
        ];
        let mut below_one = 1.0f64;
        for _ in 0..64 {
            below_one = below_one.next_down();
            scores.push(below_one);
        }
        // xorshift64: scores over many magnitudes, either sign.
        let mut state = 0x2545_F491_4F6C_DD1D_u64;
        for _ in 0..2000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let unit = (state >> 11) as f64 / (1u64 << 53) as f64;
            let exponent = (state % 61) as i32 - 40;
            scores.push((2.0 * unit - 1.0) * 2f64.powi(exponent));
        }
        for &a in &scores {
            for &b in scores.iter().step_by(7) {
                let (s1, s2) = if a >= b { (a, b) } else { (b, a) };
                assert_eq!(pa_score(s1, s2).to_bits(), unhalved(s1, s2).to_bits(), "{s1:e} {s2:e}");
            }
        }
    }

    #[test]
    fn no_pairs_is_nan() {
        let map = ConfidenceMap::fit([]);
        assert!(map.blocks().is_empty());
        assert!(map.confidence(0.5).is_nan() && map.confidence_lower95(0.5).is_nan());
    }

    #[test]
    fn one_pair_goes_on_to_its_bounds() {
        // One correct pair at PA-score 0.5: one block, value (1 + 1) / (1 + 2) = 2/3 at
        // its centre; its 95% bounds on 1 of 1 are 0.05^(1/1) = 0.05 and 1.
        let map = ConfidenceMap::fit([(0.5, true)]);
        assert_eq!(blocks(&[(0.5, true)]), [(0.5, 1, 1)]);
        assert_eq!(map.confidence(0.5), 2.0 / 3.0);
        // Linear to 0.05 at PA-score 1 and to 1 at 0: halfway on either side.
        assert!(close(map.confidence(0.75), (0.05 + 2.0 / 3.0) / 2.0));
        assert!(close(map.confidence(0.25), (2.0 / 3.0 + 1.0) / 2.0));
        assert!(close(map.confidence(1.0), 0.05) && map.confidence(0.0) == 1.0);
        // The lower bound is the block's, everywhere.
        for r in [0.0, 0.3, 0.5, 0.9, 1.0] {
            assert!(close(map.confidence_lower95(r), 0.05));
        }
        // One wrong pair: 1/3 at its centre, from 0 (its lower bound) to 0.95, 1 less
        // the lower bound 0.05 on 1 wrong of 1.
        let map = ConfidenceMap::fit([(0.5, false)]);
        assert_eq!(map.of(0.5), (1.0 / 3.0, 0.0));
        assert_eq!(map.of(1.0), (0.0, 0.0));
        assert!(close(map.confidence(0.0), 0.95));
        // A centre at an end of the range has no knot beyond it.
        let map = ConfidenceMap::fit([(1.0, true), (0.0, true), (0.0, false)]);
        // Points (1: 1/1) and (0: 1/2) violate: one block of 2 of 3, centre 1/3.
        assert_eq!(
            map.blocks(),
            [Block {
                pa_score: 1.0 / 3.0,
                n: 3,
                x: 2
            }]
        );
    }

    /// Pairs of three blocks, 0 of 2 at PA-score 0.8, 1 of 2 at 0.6 and 3 of 3 at 0.1.
    const THREE_BLOCKS: [(f64, bool); 7] = [
        (0.8, false),
        (0.8, false),
        (0.6, true),
        (0.6, false),
        (0.1, true),
        (0.1, true),
        (0.1, true),
    ];

    #[test]
    fn two_passes_of_pooling() {
        // Descending PA-score: 0.9 (0 of 1), then 0.5 (1 of 10). By x / n, 0 < 0.1: two
        // blocks. By (x + 1) / (n + 2), 1/3 >= 2/12: pooled into one block of 1 of 11,
        // centre (0.9 + 10 x 0.5) / 11.
        let mut pairs = vec![(0.9, false), (0.5, true)];
        pairs.extend([(0.5, false); 9]);
        assert_eq!(blocks(&pairs), [(round(5.9 / 11.0), 11, 1)]);
        // Equal Laplace values are merged too (blocks are maximal): 0 of 1 and 1 of 4
        // are 1/3 and 2/6.
        let mut pairs = vec![(0.9, false), (0.4, true)];
        pairs.extend([(0.4, false); 3]);
        assert_eq!(blocks(&pairs), [(2.5 / 5.0, 5, 1)]);
        // Equal PA-scores are one point, never split: (0.8: 1/1) and (0.2: 0/2) violate
        // and pool to 1 of 3.
        assert_eq!(blocks(&[(0.8, true), (0.2, false), (0.2, false)]), [(0.4, 3, 1)]);
        // Increasing values stay apart: (0.8: 0 of 2), (0.6: 1 of 2), (0.1: 3 of 3) are
        // 1/4, 2/4 and 4/5 by Laplace.
        assert_eq!(blocks(&THREE_BLOCKS), [(0.8, 2, 0), (0.6, 2, 1), (0.1, 3, 3)]);
    }

    #[test]
    fn linear_between_centres_and_the_lower_bound_of_the_less_confident() {
        // Knots (1: lower 0), (0.8: 1/4), (0.6: 1/2), (0.1: 4/5), (0: upper of 3 of 3 = 1).
        let map = ConfidenceMap::fit(THREE_BLOCKS);
        // 1 of 2: the 0.05 quantile of Beta(1, 2), 1 - sqrt(0.95); 3 of 3: 0.05^(1/3).
        let (one_of_two, three_of_three) = (1.0 - 0.95f64.sqrt(), 0.05f64.powf(1.0 / 3.0));
        assert_eq!(map.of(1.0), (0.0, 0.0));
        assert!(close(map.confidence(0.9), 0.125));
        assert_eq!(map.of(0.8), (0.25, 0.0));
        // 0.7: halfway from 1/4 to 1/2, with the lower bound of the 0.8 block.
        assert!(close(map.confidence(0.7), 0.375) && map.confidence_lower95(0.7) == 0.0);
        // 0.35: halfway from 1/2 to 4/5, the bound of the 0.6 block.
        assert!(close(map.confidence(0.35), 0.65));
        assert!(close(map.confidence_lower95(0.35), one_of_two));
        // 0.05: halfway from 4/5 to 1, the bound of the last block.
        assert!(close(map.confidence(0.05), 0.9));
        assert!(close(map.confidence_lower95(0.05), three_of_three));
        assert_eq!(map.confidence(0.0), 1.0);
        // Outside [0, 1]: the end knot's.
        assert_eq!(map.of(1.5), map.of(1.0));
        assert_eq!(map.of(-0.5), map.of(0.0));
    }

    #[test]
    fn multi_and_one_row_are_errors() {
        assert!(
            check(Matching::Multi, 10)
                .unwrap_err()
                .to_string()
                .starts_with("confidence needs single matching")
        );
        assert_eq!(
            check(Matching::Single, 1).unwrap_err().to_string(),
            "confidence needs at least 2 database images (a best and a second-best score), got 1"
        );
        assert!(check(Matching::Single, 2).is_ok());
    }

    #[test]
    fn signals_by_hand() {
        // Blocks 0 of 2 (PA-score 0.8) and 2 of 2 (0.2): knots (1: 0), (0.8: 1/4),
        // (0.2: 3/4), (0: 1).
        let map = ConfidenceMap::fit([(0.8, false), (0.8, false), (0.2, true), (0.2, true)]);
        // (score, margin, PA-score, correct): scores 0.9 (right), 0.8 (wrong), 0.8
        // (right), 0.5 (wrong); margins 3, 1, 2.5, 0.5; PA-scores 0.2, 0.5, 0.8, 1.
        // Consistencies 1, 0.2, 0.6, 0.6.
        let d: Vec<Signal> = [
            (0.9, 3.0, 0.2, 1.0, true),
            (0.8, 1.0, 0.5, 0.2, false),
            (0.8, 2.5, 0.8, 0.6, true),
            (0.5, 0.5, 1.0, 0.6, false),
        ]
        .map(|(score, margin, pa_score, consistency, correct)| Signal {
            score,
            margin,
            pa_score,
            consistency: Some(consistency),
            correct,
        })
        .to_vec();
        let s = Signals::of(&d, &map);
        // Score: right {0.9, 0.8} against wrong {0.8, 0.5}: pairs 0.9>0.8, 0.9>0.5,
        // 0.8=0.8 (a half), 0.8>0.5: 3.5 / 4. Margin: right above wrong, 1.
        assert_eq!((s.score_auroc, s.margin_auroc), (Some(0.875), Some(1.0)));
        // PA-score, lower ranked higher: right {0.2, 0.8} against wrong {0.5, 1}: 0.2
        // beats both, 0.8 beats 1 only: 3 / 4. The confidence ranks as it does.
        assert_eq!((s.pa_score_auroc, s.confidence_auroc), (Some(0.75), Some(0.75)));
        // Consistency: right {1, 0.6} against wrong {0.2, 0.6}: 1 beats both, 0.6 beats
        // 0.2 and ties 0.6 (a half): 3.5 / 4. Without it for every decision, none.
        assert_eq!(s.consistency_auroc, Some(0.875));
        let partial: Vec<Signal> = d
            .iter()
            .enumerate()
            .map(|(i, x)| Signal {
                consistency: (i > 0).then_some(0.5),
                ..*x
            })
            .collect();
        assert_eq!(Signals::of(&partial, &map).consistency_auroc, None);
        // Confidences 3/4, 1/2, 1/4, 0: Brier (1/16 + 1/4 + 9/16 + 0) / 4 = 7/32.
        assert_eq!(s.brier, Some(7.0 / 32.0));
        // Bins 7 (right), 5 (wrong), 2 (right), 0 (wrong): ECE (1/4 + 1/2 + 3/4 + 0) / 4.
        assert!(close(s.ece.unwrap(), 0.375));
        assert_eq!(s.bins.as_ref().map(Vec::len), Some(4));
        assert_eq!(Signals::FIGURES.len(), s.figures().len());
        assert_eq!(s.figures()[2], Some(0.75));
        // Bins: p = 0.25 (bin 2, wrong) and 1.0 (bin 9, the last, right), 0.95 (bin 9,
        // wrong): ECE = 1/3 |0.25 - 0| + 2/3 |0.975 - 1/2| = 0.083333 + 0.316667 = 0.4.
        let bins = reliability(&[0.25, 1.0, 0.95], &[false, true, false]);
        assert!((ece(&bins) - 0.4).abs() < 1e-12);
        // Without a wrong decision, no AUROC; without blocks, no calibration figure.
        let all_right = Signals::of(&d[..1], &map);
        assert_eq!((all_right.score_auroc, all_right.brier), (None, Some(1.0 / 16.0)));
        let none = Signals::of(&d, &ConfidenceMap::fit([]));
        assert_eq!(
            (none.score_auroc, none.confidence_auroc, none.brier, none.ece, none.bins),
            (Some(0.875), None, None, None, None)
        );
    }

    #[test]
    fn reliability_bins_by_hand() {
        // (p, c) in four of the ten bins; a p on an edge goes up (0.1: bin 1), except
        // 1.0, which the last bin holds with 0.9.
        let pc = [
            (0.0, false),
            (0.08, false),
            (0.1, true),
            (0.55, true),
            (0.58, false),
            (0.59, true),
            (0.9, false),
            (1.0, true),
        ];
        let (p, c): (Vec<f64>, Vec<bool>) = pc.iter().copied().unzip();
        let bins = reliability(&p, &c);
        // Bin 0: 0 and 0.08, mean 0.04, none right. Bin 1: 0.1, right.
        // Bin 5: (0.55 + 0.58 + 0.59) / 3 = 1.72 / 3 = 0.573333, 2 of 3 right.
        // Bin 9: (0.9 + 1.0) / 2 = 0.95, 1 of 2 right. Bins 2-4 and 6-8 are empty: left out.
        let got: Vec<(f64, f64, usize)> = bins.iter().map(|b| (b.lower, b.upper, b.n)).collect();
        assert_eq!(got, [(0.0, 0.1, 2), (0.1, 0.2, 1), (0.5, 0.6, 3), (0.9, 1.0, 2)]);
        let want = [(0.04, 0.0), (0.1, 1.0), (1.72 / 3.0, 2.0 / 3.0), (0.95, 0.5)];
        for (b, (mean, hit)) in bins.iter().zip(want) {
            assert!((b.mean_confidence - mean).abs() < 1e-12, "{b:?}");
            assert_eq!(b.hit_rate, hit, "{b:?}");
        }
        // ECE = 2/8 x 0.04 + 1/8 x 0.9 + 3/8 x |0.573333 - 0.666667| + 2/8 x 0.45
        //     = 0.01 + 0.1125 + 0.035 + 0.1125 = 0.27.
        assert!((ece(&bins) - 0.27).abs() < 1e-12, "{}", ece(&bins));
        // No decision: no bin, and an ECE of 0.
        assert!(reliability(&[], &[]).is_empty());
        assert_eq!(ece(&[]), 0.0);
    }

    proptest! {
        #[test]
        fn strictly_decreasing_bounded_and_lower_below(
            pairs in prop::collection::vec((0u8..=10, any::<bool>()), 1..40),
            probes in prop::collection::vec(0u16..=1000, 2..20),
        ) {
            // PA-scores on a coarse grid, so that ties are common.
            let pairs: Vec<(f64, bool)> = pairs.iter().map(|&(r, c)| (r as f64 / 10.0, c)).collect();
            let map = ConfidenceMap::fit(pairs.iter().copied());
            let b = map.blocks();
            // Maximal blocks: centres descending, Laplace values strictly increasing,
            // every pair accounted for.
            prop_assert!(b.windows(2).all(|w| w[0].pa_score > w[1].pa_score && w[0].confidence() < w[1].confidence()));
            prop_assert_eq!(b.iter().map(|b| b.n).sum::<usize>(), pairs.len());
            prop_assert_eq!(b.iter().map(|b| b.x).sum::<usize>(), pairs.iter().filter(|p| p.1).count());
            // Each block's value lies strictly inside its own 95% bounds.
            prop_assert!(b.iter().all(|b| b.confidence_lower95() < b.confidence() && b.confidence() < b.confidence_upper95()));
            // Probes apart by 1e-3, far above rounding.
            let mut probes = probes;
            probes.sort_unstable();
            probes.dedup();
            let mut last: Option<f64> = None;
            for r in probes.into_iter().map(|p| f64::from(p) / 1000.0) {
                let (c, lower) = map.of(r);
                prop_assert!((0.0..=1.0).contains(&c) && (0.0..=1.0).contains(&lower));
                prop_assert!(lower <= c, "{} > {}", lower, c);
                // A higher PA-score has a strictly lower confidence.
                prop_assert!(last.is_none_or(|last| c < last), "not strictly decreasing at {}", r);
                last = Some(c);
            }
        }
    }
}
