//! semantics §13: the margin gate, a scale-free check on each single-match decision.
//!
//! The *margin* of a query column is how far its best match stands out of the column:
//! `(s1 - s2) / sigma`, its largest score less its second-largest (equal when the
//! largest occurs twice), over the population standard deviation of its |DB| scores
//! (0 for a constant column). It does not change when every score of a column is
//! shifted or scaled by a positive factor, which is what moves raw scores between
//! conditions; so a gate on it, calibrated once, holds where a fixed score threshold
//! drifts.
//!
//! The gate `m*` is the semantics §3 threshold of the calibration's single-match
//! decisions with their margins in place of their scores (each calibration query's best
//! match; soft-only ones left out; positives are the queries with a positive), and
//! `+inf` (reject-all) when no group meets the target. The gate ([`MarginGate`]) passes
//! a query whose margin is at or above `m*`; a gated decision accepts the best match
//! when its score is at or above the threshold **and** the gate passes (the rule of
//! [`super::Gates`]). Multi matching accepts every entry above a threshold, not a best
//! match, so it has no gate ([`check`] says so).
//!
//! Every margin of the library is computed by one function from the column sorted
//! ascending, in `f64` and in a fixed order, so the batch transfer, [`crate::Online`],
//! [`crate::operations::evaluate()`] and [`margins`] give the same bits for the same column.

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::{GateSignals, QueryGate};
use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::input::{Score, validate_scores};
use crate::platform::threads;
use crate::rules::best_threshold::sweep;
use crate::rules::decisions::{Candidates, Matching};

/// Check that decisions in `matching` mode over a database of `n_db` images can be
/// gated on their margin.
///
/// # Errors
/// [`Error::InvalidParameter`] naming the gate: multi matching, or fewer than 2
/// database images (a column then has no second-largest score).
pub fn check(matching: Matching, n_db: usize) -> Result<()> {
    if matching == Matching::Multi {
        return Err(Error::param(
            "gate",
            "margin needs single matching: it gates each query's best match, and multi matching \
             accepts every database entry at or above the threshold",
        ));
    }
    if n_db < 2 {
        return Err(Error::param(
            "gate",
            format!("margin needs at least 2 database images (a best and a second-best score), got {n_db}"),
        ));
    }
    Ok(())
}

/// The margin of a column sorted ascending, of at least 2 finite scores.
///
/// The scores are scaled by a power of two (exactly) so that no square overflows or
/// underflows; the mean and the mean squared deviation are summed in eight lanes, the
/// same order every time.
pub(crate) fn of_sorted<T: Score>(sorted: &[T]) -> f64 {
    let n = sorted.len();
    debug_assert!(n >= 2, "a margin needs 2 scores");
    let (lowest, second, highest) = (sorted[0].to_f64(), sorted[n - 2].to_f64(), sorted[n - 1].to_f64());
    if lowest == highest {
        return 0.0; // sigma = 0
    }
    let exponent = lowest.abs().max(highest.abs()).log2().floor().clamp(-1000.0, 1000.0);
    let scale = (-exponent).exp2();
    let mean = lanes(sorted, |x| x * scale) / n as f64;
    let variance = lanes(sorted, |x| (x * scale - mean).powi(2)) / n as f64;
    (highest * scale - second * scale) / variance.sqrt()
}

/// The sum of `f(x)` over `xs` in eight interleaved lanes (vectorisable, fixed order).
#[inline(always)]
fn lanes<T: Score>(xs: &[T], f: impl Fn(f64) -> f64) -> f64 {
    const LANES: usize = 8;
    let chunks = xs.chunks_exact(LANES);
    let tail: f64 = chunks.remainder().iter().map(|x| f(x.to_f64())).sum();
    let mut acc = [0.0; LANES];
    for c in chunks {
        for l in 0..LANES {
            acc[l] += f(c[l].to_f64());
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// The margin of every column of `s` (|DB| x |Q|): what a gate compares with `m*`.
///
/// # Errors
/// Empty or non-finite scores; fewer than 2 database images.
pub fn margins<T: Score>(s: ArrayView2<'_, T>) -> Result<Vec<f64>> {
    validate_scores(Input::Similarity, s)?;
    check(Matching::Single, s.nrows())?;
    Ok(of_columns(s))
}

/// [`margins`] of a matrix already checked (finite, at least 2 rows).
pub(crate) fn of_columns<T: Score>(s: ArrayView2<'_, T>) -> Vec<f64> {
    threads::install(|| {
        (0..s.ncols())
            .into_par_iter()
            .map_init(Vec::new, |column, j| {
                column.clear();
                column.extend(s.column(j).iter().copied());
                T::sort_ascending(column);
                of_sorted(column)
            })
            .collect()
    })
}

/// The margin gate at its level `m*`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MarginGate {
    /// `m*`, the margin a best match needs (`+inf`: reject-all).
    pub(crate) level: f64,
}

impl QueryGate for MarginGate {
    fn level(&self) -> f64 {
        self.level
    }

    fn passes(&self, query: &GateSignals) -> bool {
        query.margin.is_none_or(|margin| margin >= self.level)
    }
}

/// The calibration's single-match decisions with their margins: what `m*` is found on.
#[derive(Debug, Clone)]
pub(crate) struct CalibrationMargins {
    /// (margin, correct) of every calibration decision, by descending margin.
    decisions: Vec<(f64, bool)>,
    /// The calibration queries with a positive.
    positives: usize,
}

impl CalibrationMargins {
    /// From the margin of each calibration query and its single-match candidates.
    pub(crate) fn new(margins: &[f64], candidates: &Candidates) -> Self {
        let mut decisions: Vec<(f64, bool)> = margins
            .iter()
            .enumerate()
            .filter_map(|(j, &m)| candidates.column(j).1.first().map(|&correct| (m, correct)))
            .collect();
        decisions.sort_by(|a, b| b.0.total_cmp(&a.0));
        Self {
            decisions,
            positives: candidates.positives(0..margins.len()),
        }
    }

    /// `m*` at precision target `tau` (`+inf`: reject-all).
    pub(crate) fn gate(&self, tau: f64) -> f64 {
        sweep(self.decisions.iter().copied(), tau, self.positives)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::Truth;
    use crate::input::params::Gate;
    use ndarray::array;

    fn margin_of(column: &[f64]) -> f64 {
        let mut v = column.to_vec();
        v.sort_by(f64::total_cmp);
        of_sorted(&v)
    }

    #[test]
    fn margin_by_hand() {
        // mean 2, population variance (4 + 0 + 1 + 1) / 4 = 1.5.
        let m = margin_of(&[4.0, 2.0, 1.0, 1.0]);
        assert!((m - 2.0 / 1.5f64.sqrt()).abs() < 1e-15, "{m}");
        // The largest twice: s2 = s1.
        assert_eq!(margin_of(&[3.0, 1.0, 3.0]), 0.0);
        // Constant: sigma = 0.
        assert_eq!(margin_of(&[0.5, 0.5]), 0.0);
        // Two values: (s1 - s2) / (|s1 - s2| / 2) = 2.
        assert_eq!(margin_of(&[0.25, 0.75]), 2.0);
    }

    #[test]
    fn scale_free_and_safe_at_the_ends_of_the_range() {
        let base = [0.9, 0.2, 0.4, 0.35, 0.1];
        let m = margin_of(&base);
        for (a, b) in [(2.0, -7.0), (1e-300, 0.0), (1e300, 1e300), (0.001, 5.0)] {
            let shifted: Vec<f64> = base.iter().map(|x| a * x + b).collect();
            let ms = margin_of(&shifted);
            assert!((ms - m).abs() < 1e-9 * m, "{a} x + {b}: {ms} vs {m}");
        }
        // Huge magnitudes that would overflow a square unscaled.
        assert!((margin_of(&[1e300, -1e300]) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn margins_of_a_matrix_check_their_input() {
        let s = array![[0.9f32, 0.5], [0.1, 0.5], [0.2, 0.5]];
        let m = margins(s.view()).unwrap();
        assert_eq!(m[1], 0.0);
        assert!((m[0] - margin_of(&[0.9f32 as f64, 0.1f32 as f64, 0.2f32 as f64])).abs() == 0.0);
        let one = array![[0.9, 0.5]];
        assert_eq!(
            margins(one.view()).unwrap_err().to_string(),
            "gate margin needs at least 2 database images (a best and a second-best score), got 1"
        );
        let bad = array![[0.9, f64::NAN], [0.1, 0.2]];
        assert!(
            margins(bad.view())
                .unwrap_err()
                .to_string()
                .contains("NaN at row 0, column 1")
        );
    }

    #[test]
    fn gate_is_section_3_on_margins() {
        // Four calibration queries: margins 3 (correct), 2 (wrong), 1 (correct), and a
        // soft-only best match (left out); three positives.
        let s = array![[0.9, 0.5, 0.6, 0.8], [0.1, 0.1, 0.5, 0.1]];
        let gt = array![
            [Truth::True, Truth::False, Truth::True, Truth::Ignored],
            [Truth::False, Truth::True, Truth::False, Truth::True]
        ];
        let candidates = Candidates::new(s.view(), gt.view(), Matching::Single);
        let cal = CalibrationMargins::new(&[3.0, 2.0, 1.0, 9.0], &candidates);
        assert_eq!(cal.positives, 4);
        assert_eq!(cal.gate(1.0), 3.0);
        assert_eq!(cal.gate(0.6), 1.0);
        let none = CalibrationMargins::new(
            &[3.0, 2.0, 1.0, 9.0],
            &Candidates::new(s.view(), gt.map(|_| Truth::False).view(), Matching::Single),
        );
        assert_eq!(none.gate(1.0), f64::INFINITY);
    }

    #[test]
    fn gate_names_and_checks() {
        assert_eq!("margin".parse::<Gate>().unwrap(), Gate::Margin);
        assert_eq!(
            "ratio".parse::<Gate>().unwrap_err().to_string(),
            "gate must be none, or one or more of margin, sequence joined by commas, got \"ratio\": unknown gate \
             \"ratio\""
        );
        assert!(
            check(Matching::Multi, 10)
                .unwrap_err()
                .to_string()
                .starts_with("gate margin needs single matching")
        );
        assert!(check(Matching::Single, 2).is_ok());
    }
}
