//! semantics §3: the threshold of maximum recall under a precision target.
//!
//! An exact sweep over the candidates in descending score order, evaluated only at the
//! end of each group of equal scores (equal scores are accepted together). Candidates
//! arrive as per-column sorted lists (`Candidates`), so a subset of columns is swept
//! by a lazy k-way merge rather than a sort, and the sweep stops as soon as no later
//! group can be valid: validity needs `FP <= (TP (1 - tau) + 1e-12) / tau` and TP never
//! exceeds the positives, so past that many false positives nothing can change. At
//! tau = 1 that is the first false candidate; in general a few times the positives, a
//! small fraction of a multi-mode subset's |DB| x k candidates.

use itertools::Itertools;
use ndarray::ArrayView2;

use crate::error::Result;
use crate::error::names::Input;
use crate::input::{GroundTruth, Score, check_gt_shape, check_precision, validate_scores};
use crate::rules::decisions::{Candidates, Matching};

/// The best threshold of a whole matrix (semantics §3), `f64::INFINITY` for reject-all.
///
/// `s` and `gt` are |DB| x |Q|; `tau` is the precision target in (0, 1].
///
/// # Errors
/// Empty or non-finite scores, a ground-truth shape that differs from `s`, or `tau`
/// outside (0, 1].
pub fn best_threshold<T: Score>(s: ArrayView2<'_, T>, gt: &GroundTruth, matching: Matching, tau: f64) -> Result<f64> {
    check_precision(tau)?;
    validate_scores(Input::Similarity, s)?;
    check_gt_shape(gt, Input::Similarity, s.dim())?;
    let cands = Candidates::new(s, gt.view(), matching);
    let all: Vec<usize> = (0..cands.ncols()).collect();
    Ok(subset_threshold(&cands, &all, tau))
}

/// The best threshold of the candidates of `columns` (in any order).
pub(crate) fn subset_threshold(cands: &Candidates, columns: &[usize], tau: f64) -> f64 {
    let merged = columns
        .iter()
        .map(|&j| {
            let (s, c) = cands.column(j);
            s.iter().copied().zip(c.iter().copied())
        })
        .kmerge_by(|a, b| a.0 > b.0);
    sweep(merged, tau, cands.positives(columns.iter().copied()))
}

/// The exact sweep (semantics §3) over candidates sorted by descending score, of which
/// at most `positives` can be correct.
pub(crate) fn sweep(sorted: impl Iterator<Item = (f64, bool)>, tau: f64, positives: usize) -> f64 {
    // No group with more false positives than this can be valid (with a margin of one
    // for rounding); FP only grows, so the sweep stops there.
    let max_fp = (((positives as f64 * (1.0 - tau) + 1e-12) / tau).floor() as usize).saturating_add(1);
    let (mut tp, mut fp) = (0usize, 0usize);
    let (mut best_tp, mut best_t) = (0usize, f64::INFINITY);
    let mut it = sorted.peekable();
    while let Some((score, correct)) = it.next() {
        if correct {
            tp += 1;
        } else {
            fp += 1;
            if fp > max_fp {
                break;
            }
        }
        if it.peek().is_some_and(|next| next.0 == score) {
            continue; // not the last candidate of its group of equal scores
        }
        let valid = tp > 0 && tp as f64 >= tau * (tp + fp) as f64 - 1e-12;
        // TP never decreases along the sweep, so the first valid group that raises the
        // best TP is the first (highest) group at which TP reaches its valid maximum.
        if valid && tp > best_tp {
            best_tp = tp;
            best_t = score;
        }
    }
    best_t
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    /// Multi mode, two columns: q0 = [0.9 T, 0.8 F, 0.6 F], q1 = [0.8 T, 0.7 T, 0.05 F].
    /// Merged, descending: 0.9 T | 0.8 F, 0.8 T | 0.7 T | 0.6 F | 0.05 F.
    /// At the end of each group (TP, FP): 0.9 (1, 0); 0.8 (2, 1); 0.7 (3, 1); 0.6 (3, 2); 0.05 (3, 3).
    fn example() -> (ndarray::Array2<f64>, GroundTruth) {
        let s = array![[0.9, 0.8], [0.8, 0.7], [0.6, 0.05]];
        let gt = GroundTruth::new(array![[true, true], [false, true], [false, false]].view()).unwrap();
        (s, gt)
    }

    fn best(tau: f64) -> f64 {
        let (s, gt) = example();
        best_threshold(s.view(), &gt, Matching::Multi, tau).unwrap()
    }

    #[test]
    fn perfect_precision_stops_before_the_first_false_group() {
        // tau = 1: only 0.9 (1, 0) is valid; the tied 0.8 group carries a FP -> 0.9.
        assert_eq!(best(1.0), 0.9);
    }

    #[test]
    fn lower_targets_reach_further() {
        // tau = 0.6: 0.8 (2 >= 1.8), 0.7 (3 >= 2.4), 0.6 (3 >= 3.0 - 1e-12) valid; TP* = 3,
        // first reached at 0.7.
        assert_eq!(best(0.6), 0.7);
        // tau = 0.75: 0.8 needs 2 >= 2.25 (no); 0.7 needs 3 >= 3.0 - 1e-12 (yes) -> 0.7.
        assert_eq!(best(0.75), 0.7);
        // tau = 0.76: 0.7 needs 3 >= 3.04 (no), 0.8 needs 2 >= 2.28 (no) -> 0.9.
        assert_eq!(best(0.76), 0.9);
    }

    #[test]
    fn early_stop_changes_nothing() {
        // Against the same sweep told there could be as many positives as candidates
        // (so it never stops early), on every subset of the example's columns.
        let (s, gt) = example();
        let cands = Candidates::new(s.view(), gt.view(), Matching::Multi);
        for cols in [vec![0], vec![1], vec![0, 1], vec![1, 0]] {
            for tau in [1.0, 0.9, 0.76, 0.75, 0.6, 0.5, 0.1] {
                let merged = || {
                    cols.iter()
                        .map(|&j| {
                            let (s, c) = cands.column(j);
                            s.iter().copied().zip(c.iter().copied())
                        })
                        .kmerge_by(|a, b| a.0 > b.0)
                };
                assert_eq!(
                    sweep(merged(), tau, usize::MAX / 2),
                    subset_threshold(&cands, &cols, tau),
                    "{cols:?} {tau}"
                );
            }
        }
        // q1 alone: 0.8 T, 0.7 T, 0.05 F -> tau = 1 stops at 0.05 F, having reached 0.7.
        assert_eq!(subset_threshold(&cands, &[1], 1.0), 0.7);
    }

    #[test]
    fn reject_all_without_a_valid_group() {
        // Only false candidates: TP never > 0 -> +inf. Same with no positives at all.
        let s = array![[0.9, 0.8], [0.1, 0.2]];
        let gt = GroundTruth::new(array![[false, false], [false, false]].view()).unwrap();
        for matching in [Matching::Single, Matching::Multi] {
            assert_eq!(best_threshold(s.view(), &gt, matching, 1.0).unwrap(), f64::INFINITY);
            assert_eq!(best_threshold(s.view(), &gt, matching, 0.5).unwrap(), f64::INFINITY);
        }
    }

    #[test]
    fn single_mode_uses_best_matches_only() {
        // Best matches: q0 -> 0.9 (T), q1 -> 0.7 (F), q2 -> 0.5 (T). tau = 1: the lowest
        // correct above the false 0.7 is 0.9. tau = 0.6: 0.5 group gives (2, 1), 2 >= 1.8 -> 0.5.
        let s = array![[0.9, 0.7, 0.1], [0.3, 0.2, 0.5]];
        let gt = GroundTruth::new(array![[1u8, 0, 0], [0, 1, 1]].view()).unwrap();
        assert_eq!(best_threshold(s.view(), &gt, Matching::Single, 1.0).unwrap(), 0.9);
        assert_eq!(best_threshold(s.view(), &gt, Matching::Single, 0.6).unwrap(), 0.5);
    }

    #[test]
    fn rejects_bad_precision() {
        let (s, gt) = example();
        for tau in [0.0, -0.1, 1.5, f64::NAN] {
            let err = best_threshold(s.view(), &gt, Matching::Single, tau).unwrap_err();
            assert!(err.to_string().starts_with("precision must be in (0, 1]"), "{err}");
        }
    }
}
