//! semantics §14: confidence, a calibrated probability that a single-match decision is
//! right.
//!
//! A SLAM back end weighs a loop closure by how likely it is to be right and wants a
//! number in [0, 1], not a raw score. The margin of semantics §13 already separates
//! right from wrong best matches, and is scale-free; this module maps it to the hit
//! rate the calibration traverse shows at that margin.
//!
//! The *pairs* are the calibration's single-match decisions (each calibration query's
//! best match, soft-only ones left out, as for the gate's `m*`): margin `m_j`, and
//! `c_j = 1` when the best match is a hard positive. Sorted by margin, equal margins one
//! point, a weighted pool-adjacent-violators fit gives the non-decreasing step function
//! closest to the `c_j` in least squares (isotonic regression). Its *blocks* are
//! maximal (no two adjacent blocks have the same value), each with its lowest margin,
//! its count `n` and its successes `x`. A margin `m` falls in the block with the
//! largest lowest margin `<= m` (the first block below them all); its confidence is
//! that block's `x / n`, and its `confidence_lower95` the one-sided 95% Clopper-Pearson
//! lower bound on it: the bound of semantics §8, computed by
//! [`Counts::precision_lower95`](crate::Counts::precision_lower95) with `x` successes
//! among `n`.
//!
//! Values are compared as fractions in integers (`x1 n2` against `x2 n1`), so ties
//! between blocks are exact, whatever the counts. The map is found once per
//! calibration, on the first request ([`crate::Calibration::confidence_map`]), from the
//! same margins as the gate: a calibration file need not store it.
//!
//! Multi matching accepts every entry above a threshold, not a best match, so it has no
//! confidence ([`check`] says so); a decision record then carries NaN.

use crate::error::{Error, Result};
use crate::rules::decisions::{Counts, Matching};

/// One block of the fitted step function: the calibration pairs of margins from
/// `margin` up to (not including) the next block's.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Block {
    /// The lowest margin of the block's pairs.
    pub margin: f64,
    /// Its number of pairs.
    pub n: usize,
    /// Its number of correct pairs (`c = 1`).
    pub x: usize,
}

impl Block {
    /// `x / n`: the confidence of a margin in this block.
    pub fn confidence(&self) -> f64 {
        self.x as f64 / self.n as f64
    }

    /// The one-sided 95% Clopper-Pearson lower bound on `x / n` (0 when `x` = 0).
    pub fn confidence_lower95(&self) -> f64 {
        Counts {
            tp: self.x,
            fp: self.n - self.x,
            positives: self.x,
        }
        .precision_lower95()
        .expect("a block holds at least one pair")
    }

    /// Whether this block's value is at least `other`'s: `x / n >= x' / n'` in integers.
    fn at_least(&self, other: &Block) -> bool {
        self.x as u128 * other.n as u128 >= other.x as u128 * self.n as u128
    }
}

/// The confidence map of a calibration: the maximal blocks of the isotonic fit of its
/// pairs, by ascending margin, with their values and lower bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfidenceMap {
    blocks: Vec<Block>,
    /// Per block: `(confidence, confidence_lower95)`, found once.
    values: Vec<(f64, f64)>,
}

impl ConfidenceMap {
    /// The map of calibration pairs `(margin, correct)`, in any order. Margins must not
    /// be NaN (margins of finite scores never are).
    pub fn fit(pairs: impl IntoIterator<Item = (f64, bool)>) -> Self {
        let mut pairs: Vec<(f64, bool)> = pairs.into_iter().collect();
        debug_assert!(pairs.iter().all(|p| !p.0.is_nan()), "a NaN margin");
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Equal margins are one point.
        let mut points: Vec<Block> = Vec::new();
        for (margin, correct) in pairs {
            match points.last_mut() {
                Some(last) if last.margin == margin => {
                    last.n += 1;
                    last.x += usize::from(correct);
                }
                _ => points.push(Block {
                    margin,
                    n: 1,
                    x: usize::from(correct),
                }),
            }
        }
        let mut blocks: Vec<Block> = Vec::with_capacity(points.len());
        for point in points {
            blocks.push(point);
            // Pool while the block before is at least the last one: a violator
            // (greater) or an equal value (merged, so that blocks are maximal). The
            // pooled block keeps the lower margin, the one before's.
            while let [.., before, last] = blocks[..] {
                if !before.at_least(&last) {
                    break;
                }
                blocks.pop();
                let before = blocks.last_mut().expect("two blocks");
                before.n += last.n;
                before.x += last.x;
            }
        }
        let values = blocks
            .iter()
            .map(|b| (b.confidence(), b.confidence_lower95()))
            .collect();
        Self { blocks, values }
    }

    /// The blocks, by ascending margin, values strictly increasing (empty: no pairs).
    pub fn blocks(&self) -> &[Block] {
        &self.blocks
    }

    /// `(confidence, confidence_lower95)` of margin `m`: those of the block with the
    /// largest lowest margin `<= m` (the first block when `m` is below them all); both
    /// NaN without pairs.
    pub fn of(&self, m: f64) -> (f64, f64) {
        let above = self.blocks.partition_point(|b| b.margin <= m);
        self.values
            .get(above.saturating_sub(1))
            .copied()
            .unwrap_or((f64::NAN, f64::NAN))
    }

    /// The confidence of margin `m` (NaN without pairs).
    pub fn confidence(&self, m: f64) -> f64 {
        self.of(m).0
    }

    /// The one-sided 95% Clopper-Pearson lower bound on the confidence of margin `m`
    /// (NaN without pairs).
    pub fn confidence_lower95(&self, m: f64) -> f64 {
        self.of(m).1
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
/// `{"signals": {"score": {"auroc"}, "margin": {"auroc"}, "confidence": {"auroc",
/// "brier", "ece", "bins"}}}`; a figure without the decisions it needs is `null`.
#[derive(Debug, Clone, PartialEq)]
pub struct Signals {
    /// AUROC of the best score `s1`.
    pub score_auroc: Option<f64>,
    /// AUROC of the margin.
    pub margin_auroc: Option<f64>,
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

impl Signals {
    /// The signals of decisions `(score, margin, correct)` under `map`. AUROCs are
    /// `None` without a right or without a wrong decision; Brier, ECE and the bins are
    /// `None` without a decision or without a confidence (a map without blocks).
    pub fn of(decisions: &[(f64, f64, bool)], map: &ConfidenceMap) -> Self {
        let c: Vec<bool> = decisions.iter().map(|d| d.2).collect();
        let p: Vec<f64> = decisions.iter().map(|d| map.confidence(d.1)).collect();
        let scores: Vec<f64> = decisions.iter().map(|d| d.0).collect();
        let margins: Vec<f64> = decisions.iter().map(|d| d.1).collect();
        let calibrated = !p.is_empty() && !map.blocks().is_empty();
        let bins = calibrated.then(|| reliability(&p, &c));
        Self {
            score_auroc: auroc(&scores, &c),
            margin_auroc: auroc(&margins, &c),
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
                let mut m = serializer.serialize_map(Some(3))?;
                m.serialize_entry("score", &Auroc(self.0.score_auroc))?;
                m.serialize_entry("margin", &Auroc(self.0.margin_auroc))?;
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

    fn blocks(pairs: &[(f64, bool)]) -> Vec<(f64, usize, usize)> {
        ConfidenceMap::fit(pairs.iter().copied())
            .blocks()
            .iter()
            .map(|b| (b.margin, b.n, b.x))
            .collect()
    }

    #[test]
    fn no_pairs_is_nan() {
        let map = ConfidenceMap::fit([]);
        assert!(map.blocks().is_empty());
        assert!(map.confidence(1.0).is_nan() && map.confidence_lower95(1.0).is_nan());
    }

    #[test]
    fn one_pair() {
        // One correct pair: one block, x/n = 1/1, and the bound is 0.05^(1/1) = 0.05.
        let map = ConfidenceMap::fit([(0.7, true)]);
        assert_eq!(blocks(&[(0.7, true)]), [(0.7, 1, 1)]);
        // Below, at and above the only block: the same block.
        for m in [-1.0, 0.7, 5.0] {
            assert_eq!(map.confidence(m), 1.0);
            assert!((map.confidence_lower95(m) - 0.05).abs() < 1e-12);
        }
        // One wrong pair: 0/1, bound 0.
        let map = ConfidenceMap::fit([(0.7, false)]);
        assert_eq!(map.of(0.0), (0.0, 0.0));
    }

    #[test]
    fn all_correct_and_all_wrong_are_one_block() {
        // Four correct pairs in any order: all values 1, merged into one block with the
        // lowest margin 0.5; n = 4, bound 0.05^(1/4) = 0.472871.
        let all = [(2.0, true), (0.5, true), (1.0, true), (3.0, true)];
        assert_eq!(blocks(&all), [(0.5, 4, 4)]);
        let map = ConfidenceMap::fit(all);
        assert!((map.confidence_lower95(1.5) - 0.472_870_804_6).abs() < 1e-9);
        let none = [(2.0, false), (0.5, false), (1.0, false)];
        assert_eq!(blocks(&none), [(0.5, 3, 0)]);
        assert_eq!(ConfidenceMap::fit(none).of(9.0), (0.0, 0.0));
    }

    #[test]
    fn ties_are_one_point() {
        // Margins 1, 1, 2, 2, 2 with c = 0, 1, 1, 0, 1: points (1: 1/2), (2: 2/3).
        // 1/2 < 2/3, so no pooling: two blocks.
        let pairs = [(1.0, false), (2.0, true), (1.0, true), (2.0, false), (2.0, true)];
        assert_eq!(blocks(&pairs), [(1.0, 2, 1), (2.0, 3, 2)]);
        // Equal values at distinct margins are merged: (1: 1/2), (2: 1/2), (3: 1/1) gives
        // blocks (1: 2/4), (3: 1/1).
        let pairs = [(1.0, true), (1.0, false), (2.0, false), (2.0, true), (3.0, true)];
        assert_eq!(blocks(&pairs), [(1.0, 4, 2), (3.0, 1, 1)]);
        // A tie is never split: points (1: 1/1) and (2: 0/2) violate and pool to 1/3.
        let pairs = [(1.0, true), (2.0, false), (2.0, false)];
        assert_eq!(blocks(&pairs), [(1.0, 3, 1)]);
        // Nor by pooling before it is whole: (1: 1/1) and (2: 1/2) pool to 2/3, though
        // the first pair at 2 alone (0/1) would pool with 1 and the second (1/1) not.
        let pairs = [(1.0, true), (2.0, false), (2.0, true)];
        assert_eq!(blocks(&pairs), [(1.0, 3, 2)]);
    }

    #[test]
    fn a_violator_chain() {
        // Margins 1..6 with c = 1, 0, 1, 0, 0, 1.
        // 1: [1/1]; 2: 0 < 1 pools: [1/2 @1]; 3: 1 > 1/2: [1/2 @1, 1/1 @3];
        // 4: 0 pools with 3: 1/2 @3, equal to the block before: pooled, [2/4 @1];
        // 5: 0 < 1/2 pools: [2/5 @1]; 6: 1 > 2/5: [2/5 @1, 1/1 @6].
        let c = [true, false, true, false, false, true];
        let pairs: Vec<(f64, bool)> = c.iter().enumerate().map(|(i, &c)| ((i + 1) as f64, c)).collect();
        assert_eq!(blocks(&pairs), [(1.0, 5, 2), (6.0, 1, 1)]);
        let map = ConfidenceMap::fit(pairs);
        assert_eq!(map.confidence(5.9), 0.4);
        assert_eq!(map.confidence(6.0), 1.0);
        assert_eq!(map.confidence(0.0), 0.4); // below every block: the first
        // 1 of 1: 0.05^(1/1).
        assert!((map.confidence_lower95(7.0) - 0.05).abs() < 1e-12);
        // A descending run pools into one block: c = 1, 1, 0, 0 gives 2/4.
        let down = [(1.0, true), (2.0, true), (3.0, false), (4.0, false)];
        assert_eq!(blocks(&down), [(1.0, 4, 2)]);
    }

    #[test]
    fn lower_bound_is_clopper_pearson() {
        // 1 of 2: the 0.05 quantile x of Beta(1, 2), whose cdf is 1 - (1 - x)^2; so
        // x = 1 - sqrt(0.95) = 1 - 0.9746794 = 0.0253206.
        let map = ConfidenceMap::fit([(1.0, true), (2.0, false), (3.0, true), (3.0, false)]);
        // Points (1: 1/1), (2: 0/1), (3: 1/2): 1 and 0 pool to 1/2 @1, equal to 1/2 @3.
        assert_eq!(
            map.blocks(),
            [Block {
                margin: 1.0,
                n: 4,
                x: 2
            }]
        );
        let one_of_two = ConfidenceMap::fit([(1.0, true), (1.0, false)]);
        assert!((one_of_two.confidence_lower95(1.0) - (1.0 - 0.95f64.sqrt())).abs() < 1e-12);
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
        // One block below margin 2 (0 of 2) and one from 2 (2 of 2): confidences 0 or 1.
        let map = ConfidenceMap::fit([(1.0, false), (1.5, false), (2.0, true), (3.0, true)]);
        // (score, margin, correct): scores 0.9 (right), 0.8 (wrong), 0.8 (right), 0.5
        // (wrong); margins 3, 1, 2.5, 0.5.
        let d = [(0.9, 3.0, true), (0.8, 1.0, false), (0.8, 2.5, true), (0.5, 0.5, false)];
        let s = Signals::of(&d, &map);
        // Score: right {0.9, 0.8} against wrong {0.8, 0.5}: pairs 0.9>0.8, 0.9>0.5,
        // 0.8=0.8 (a half), 0.8>0.5: 3.5 / 4.
        assert_eq!(s.score_auroc, Some(0.875));
        // Margin: right {3, 2.5} above wrong {1, 0.5}: 1. Confidence: 1, 1 against 0, 0.
        assert_eq!((s.margin_auroc, s.confidence_auroc), (Some(1.0), Some(1.0)));
        assert_eq!((s.brier, s.ece), (Some(0.0), Some(0.0)));
        // Its bins: the two wrong decisions at confidence 0 (bin 0), the two right ones
        // at 1 (the last bin).
        let bin = |lower, upper, n, mean_confidence, hit_rate| ReliabilityBin {
            lower,
            upper,
            n,
            mean_confidence,
            hit_rate,
        };
        assert_eq!(
            s.bins,
            Some(vec![bin(0.0, 0.1, 2, 0.0, 0.0), bin(0.9, 1.0, 2, 1.0, 1.0)])
        );
        // A map of one block 1 of 2 (right at 1, wrong at 2: a violator, pooled): every
        // confidence 0.5; AUROC 0.5 (all tied), Brier 0.25, ECE: one bin (5),
        // |0.5 - 2/4| = 0.
        let half = ConfidenceMap::fit([(1.0, true), (2.0, false)]);
        let s = Signals::of(&d, &half);
        assert_eq!((s.confidence_auroc, s.brier, s.ece), (Some(0.5), Some(0.25), Some(0.0)));
        // Bins: p = 0.25 (bin 2, wrong) and 1.0 (bin 9, the last, right), 0.95 (bin 9,
        // wrong): ECE = 1/3 |0.25 - 0| + 2/3 |0.975 - 1/2| = 0.083333 + 0.316667 = 0.4.
        let bins = reliability(&[0.25, 1.0, 0.95], &[false, true, false]);
        assert!((ece(&bins) - 0.4).abs() < 1e-12);
        // Without a wrong decision, no AUROC; without blocks, no calibration figure.
        let all_right = Signals::of(&[(0.9, 3.0, true)], &map);
        assert_eq!((all_right.score_auroc, all_right.brier), (None, Some(0.0)));
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
        fn monotone_bounded_and_lower_below(
            pairs in prop::collection::vec((0u8..12, any::<bool>()), 1..40),
            probes in prop::collection::vec(-1.0f64..13.0, 1..20),
        ) {
            // Margins on a coarse grid, so that ties are common.
            let pairs: Vec<(f64, bool)> = pairs.iter().map(|&(m, c)| (m as f64 / 2.0, c)).collect();
            let map = ConfidenceMap::fit(pairs.iter().copied());
            let b = map.blocks();
            // Maximal blocks, strictly increasing values, that account for every pair.
            prop_assert!(b.windows(2).all(|w| w[0].margin < w[1].margin && !w[0].at_least(&w[1])));
            prop_assert_eq!(b.iter().map(|b| b.n).sum::<usize>(), pairs.len());
            prop_assert_eq!(b.iter().map(|b| b.x).sum::<usize>(), pairs.iter().filter(|p| p.1).count());
            prop_assert_eq!(b[0].margin, pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min));
            let mut probes = probes;
            probes.sort_by(f64::total_cmp);
            let mut last = 0.0;
            for m in probes {
                let (c, lower) = map.of(m);
                prop_assert!((0.0..=1.0).contains(&c) && (0.0..=1.0).contains(&lower));
                prop_assert!(lower <= c, "{} > {}", lower, c);
                prop_assert!(c >= last, "not monotone at {}", m);
                last = c;
            }
        }
    }
}
