//! semantics §7: the baselines quantile transfer is measured against.
//!
//! - **schubert**: Schubert et al.'s (ICRA 2021) automatic threshold, a robust normal
//!   fit to the raw scores: `mu + sigma * z` with `mu` the median, `sigma` the median
//!   absolute deviation over 0.675 and `z` the standard normal quantile at 1 - 1e-6. It
//!   needs no ground truth, so the protocol fits it to each deployment segment. When
//!   half or more of the scores are equal the deviation is 0 and the fit degenerate:
//!   the threshold is reject-all, as in VPR_Tutorial (whose NaN threshold accepts
//!   nothing).
//! - **schubert-calibrated**: the same fit to the calibration scores, kept fixed.
//! - **calibration-threshold**: the section-3 threshold of the calibration set, kept
//!   fixed ([`Calibration::threshold`](crate::Calibration::threshold)).
//! - **oracle**: the section-3 threshold of each segment under its own ground truth
//!   ([`best_threshold`](crate::rules::best_threshold())).
//!
//! Only the first needs code of its own. A median is an order statistic, so it is found
//! by selection (`select_nth_unstable`, linear time on average) rather than by sorting;
//! the only allocation is one copy of the scores, which the absolute deviations reuse.

use ndarray::ArrayView2;

use crate::error::Result;
use crate::error::names::Input;
use crate::input::{Score, validate_scores};

/// The standard normal quantile at 1 - 1e-6 (semantics §7).
pub const SCHUBERT_Z: f64 = 4.753424308817087;

/// The normal-consistency constant of the median absolute deviation, as in
/// VPR_Tutorial's `thresholding(S, 'auto')`.
pub const MAD_SCALE: f64 = 0.675;

/// Schubert et al.'s threshold over every raw score of `s` (orientation does not
/// matter): `mu + sigma * SCHUBERT_Z`, or reject-all (`f64::INFINITY`) when
/// `sigma = 0`, that is when half or more of the scores are equal.
///
/// # Errors
/// Empty or non-finite scores.
pub fn schubert_threshold<T: Score>(s: ArrayView2<'_, T>) -> Result<f64> {
    validate_scores(Input::Similarity, s)?;
    Ok(schubert(s))
}

/// [`schubert_threshold`] without validation (the caller has checked `s`).
pub(crate) fn schubert<T: Score>(s: ArrayView2<'_, T>) -> f64 {
    let mut values: Vec<f64> = s.iter().map(|v| v.to_f64()).collect();
    schubert_of(&mut values)
}

/// Schubert's threshold of `values` (non-empty), which it reorders and overwrites.
pub(crate) fn schubert_of(values: &mut [f64]) -> f64 {
    let mu = median(values);
    values.iter_mut().for_each(|v| *v = (*v - mu).abs());
    let sigma = median(values) / MAD_SCALE;
    // A degenerate fit: VPR_Tutorial's threshold is then NaN, which accepts nothing.
    if sigma == 0.0 {
        f64::INFINITY
    } else {
        mu + sigma * SCHUBERT_Z
    }
}

/// The median of `values` (non-empty, finite): the middle value, or `(a + b) / 2` of the
/// two middle values when the count is even. Reorders `values`.
pub(crate) fn median(values: &mut [f64]) -> f64 {
    let n = values.len();
    assert!(n > 0, "median of no values");
    let (below, &mut upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        return upper;
    }
    // The lower middle value is the largest of the n / 2 values below the upper one.
    let lower = below.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (lower + upper) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn median_of_odd_and_even_counts() {
        // Odd: {5, 1, 3} sorted (1, 3, 5) -> 3.
        assert_eq!(median(&mut [5.0, 1.0, 3.0]), 3.0);
        // Even: {4, 1, 3, 2} sorted (1, 2, 3, 4) -> (2 + 3) / 2 = 2.5.
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        // Even with ties and negatives: (-2, -1, -1, 7) -> (-1 + -1) / 2 = -1.
        assert_eq!(median(&mut [-1.0, 7.0, -2.0, -1.0]), -1.0);
        assert_eq!(median(&mut [0.25]), 0.25);
    }

    #[test]
    fn schubert_even_count() {
        // {1, 2, 3, 10}: mu = (2 + 3) / 2 = 2.5; |S - mu| = (1.5, 0.5, 0.5, 7.5), sorted
        // (0.5, 0.5, 1.5, 7.5) -> median (0.5 + 1.5) / 2 = 1; sigma = 1 / 0.675;
        // t = 2.5 + 4.753424308817087 / 0.675 = 2.5 + 7.04211... = 9.54211...
        let t = schubert_threshold(array![[1.0, 2.0], [3.0, 10.0]].view()).unwrap();
        assert_eq!(t, 2.5 + (1.0 / 0.675) * SCHUBERT_Z);
        assert!((t - 9.542110087136425).abs() < 1e-12, "{t}");
    }

    #[test]
    fn schubert_odd_count() {
        // {1, 2, 7}: mu = 2; |S - mu| = (1, 0, 5) -> median 1; t = 2 + (1 / 0.675) * z.
        // float32 input widens exactly.
        let t = schubert_threshold(array![[1.0f32, 2.0, 7.0]].view()).unwrap();
        assert_eq!(t, 2.0 + (1.0 / 0.675) * SCHUBERT_Z);
        // The orientation does not matter: the transpose holds the same scores.
        let s = array![[1.0, 2.0, 7.0]];
        assert_eq!(schubert_threshold(s.t()).unwrap(), t);
    }

    #[test]
    fn schubert_zero_sigma_is_reject_all() {
        let inf = f64::INFINITY;
        // {1, 1, 1, 2}: mu = (1 + 1) / 2 = 1; |S - mu| = (0, 0, 0, 1) -> median (0 + 0) / 2
        // = 0 -> sigma 0 -> reject-all.
        assert_eq!(schubert_threshold(array![[1.0, 1.0], [1.0, 2.0]].view()).unwrap(), inf);
        // A single score: mu = 0.3, MAD 0 -> reject-all.
        assert_eq!(schubert_threshold(array![[0.3f32]].view()).unwrap(), inf);
        // {-1, -1, 2}: mu = -1, |S - mu| = (0, 0, 3) -> median 0 -> reject-all.
        assert_eq!(schubert_threshold(array![[-1.0, -1.0, 2.0]].view()).unwrap(), inf);
        // Two equal scores out of four are not enough: {1, 1, 2, 3}: mu = (1 + 2) / 2 = 1.5;
        // |S - mu| = (0.5, 0.5, 0.5, 1.5) -> median 0.5 -> t = 1.5 + (0.5 / 0.675) * z.
        let t = schubert_threshold(array![[1.0, 1.0], [2.0, 3.0]].view()).unwrap();
        assert_eq!(t, 1.5 + (0.5 / 0.675) * SCHUBERT_Z);
    }

    #[test]
    fn schubert_rejects_bad_scores() {
        let err = schubert_threshold(array![[0.1, f64::NAN]].view()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "similarity contains NaN at row 0, column 1; scores must be finite"
        );
        let empty = ndarray::Array2::<f32>::zeros((3, 0));
        assert!(schubert_threshold(empty.view()).is_err());
    }
}
