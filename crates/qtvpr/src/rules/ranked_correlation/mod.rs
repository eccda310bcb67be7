//! semantics §4: calibration sampling by ranked correlation.
//!
//! Every query column is sorted into a *ranked profile*; the Pearson correlation of two
//! profiles is the dot product of their centred, unit-norm forms. Each deployment query
//! keeps its `k` most correlated calibration queries ([`top_k`]), compared on a grid of
//! 2^-40 ([`CORRELATION_GRID`]), and its weight is their mean correlation. That is the
//! rule, here; the files beside it make it fast without changing a bit of it:
//!
//! - `profiles.rs`: [`Ranked`], a block of columns gathered (tile by tile, so a C-order
//!   matrix is read row-wise), checked finite, sorted and standardised in the input's
//!   own type while in cache; their correlations with a deployment profile.
//! - `screen.rs`: [`Screen`], block summaries of the calibration profiles that bound
//!   every correlation, so that a deployment query reads about `k` profiles in full and
//!   still gets [`top_k`] of all its correlations, bit for bit (the proof is there).
//! - `kernels.rs`, at the bottom: the vector loops (standardisation, correlations, block
//!   summaries and bounds), each summing in fixed lanes so that every CPU gets the same
//!   bits.
//!
//! Profiles are kept in *ascending* order: reversing both profiles of a pair changes
//! neither their correlation nor any count of scores below a threshold, and ascending
//! is what the radix sort gives.

mod kernels;
mod profiles;
mod screen;

pub(crate) use profiles::Ranked;
pub(crate) use screen::Screen;

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::input::Score;
use crate::platform::threads;

/// Correlations are compared on a grid of `2^-40` (about 9.1e-13) when choosing
/// neighbours, so that correlations equal in exact arithmetic tie (and go to the lower
/// calibration index) whatever the floating-point summation order.
pub const CORRELATION_GRID: f64 = 1.0 / (1u64 << 40) as f64;

/// The `k` (clipped to the row length) calibration indices of highest correlation in
/// `row`, in order of decreasing correlation, ties to the lower index; and the weight:
/// the mean of their correlations, clipped below at 0.
///
/// Correlations are compared on the `CORRELATION_GRID`; the weight uses raw values.
fn top_k(row: &[f64], k: usize) -> (Vec<usize>, f64) {
    top_k_of(row.iter().copied().enumerate().collect(), k)
}

/// [`top_k`] of (calibration index, correlation) pairs.
fn top_k_of(mut pairs: Vec<(usize, f64)>, k: usize) -> (Vec<usize>, f64) {
    let k = k.min(pairs.len());
    let key = |r: f64| (r / CORRELATION_GRID).round_ties_even();
    let order = |a: &(usize, f64), b: &(usize, f64)| key(b.1).total_cmp(&key(a.1)).then(a.0.cmp(&b.0));
    if k < pairs.len() {
        pairs.select_nth_unstable_by(k - 1, order);
        pairs.truncate(k);
    }
    pairs.sort_unstable_by(order);
    let mean = pairs.iter().map(|p| p.1).sum::<f64>() / k as f64;
    (pairs.into_iter().map(|p| p.0).collect(), mean.max(0.0))
}

/// The full |Qval| x |Qcal| ranked-correlation matrix `R` of semantics §4, in `f64`,
/// the same values the transfer ranks neighbours by.
///
/// # Errors
/// Empty or non-finite scores, or a different number of database rows.
pub fn ranked_correlation<T: Score, U: Score>(val: ArrayView2<'_, T>, cal: ArrayView2<'_, U>) -> Result<Array2<f64>> {
    threads::install(|| {
        let cal = Ranked::new(Input::CalSimilarity, cal, 0)?;
        let val = Ranked::new(Input::DeploymentSimilarity, val, 0)?;
        if val.n_db() != cal.n_db() {
            return Err(Error::DatabaseMismatch {
                calibration: cal.n_db(),
                deployment: val.n_db(),
            });
        }
        let mut r = vec![0.0; val.ncols() * cal.ncols()];
        let all: Vec<usize> = (0..cal.ncols()).collect();
        r.par_chunks_mut(cal.ncols()).enumerate().for_each_init(
            || vec![0.0; val.n_db()],
            |u, (j, row)| {
                val.profile(j, u);
                cal.correlations(&all, u, row);
            },
        );
        Ok(Array2::from_shape_vec((val.ncols(), cal.ncols()), r).expect("shape matches length"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    pub(super) fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn pearson_of_ranked_profiles() {
        // cal profiles (sorted): [3,2,1] -> centred [1,0,-1]; [4,1,1] -> mean 2 -> [2,-1,-1].
        // val profile [2,6,4] sorts to [6,4,2] -> [2,0,-2]: r = 1 with the first; with the
        // second (4 + 0 + 2) / (sqrt 8 * sqrt 6) = 6 / sqrt 48 = 0.8660254037844386.
        let cal = array![[1.0, 1.0], [3.0, 4.0], [2.0, 1.0]];
        let val = array![[2.0f32], [6.0], [4.0]];
        let r = ranked_correlation(val.view(), cal.view()).unwrap();
        assert_eq!(r.dim(), (1, 2));
        assert!(close(r[[0, 0]], 1.0), "{r}");
        assert!(close(r[[0, 1]], 6.0 / 48f64.sqrt()), "{r}");
        // [1,2,3] vs [0,1,3] (sorted [3,2,1], [3,1,0]): centred [1,0,-1] and [5/3,-1/3,-4/3];
        // dot 3, norms sqrt 2 and sqrt(42)/3 -> r = 9 / sqrt 84.
        let r = ranked_correlation(array![[1.0], [2.0], [3.0]].view(), array![[0.0], [1.0], [3.0]].view()).unwrap();
        assert!(close(r[[0, 0]], 9.0 / 84f64.sqrt()), "{r}");
    }

    #[test]
    fn constant_columns_correlate_zero() {
        // A constant profile has zero variance: correlation 0 with everything, itself included.
        let cal = array![[0.1, 5.0], [0.1, 3.0], [0.1, 4.0]];
        let r = ranked_correlation(cal.view(), cal.view()).unwrap();
        assert_eq!(r[[0, 0]], 0.0);
        assert_eq!(r[[0, 1]], 0.0);
        assert_eq!(r[[1, 0]], 0.0);
        assert!(close(r[[1, 1]], 1.0));
    }

    #[test]
    fn huge_and_tiny_scores_do_not_overflow() {
        // Profiles [1e300, 0, -1e300] and [3e-310, 2e-310, 1e-310] are both linear: r = 1.
        let r = ranked_correlation(
            array![[1e300], [0.0], [-1e300]].view(),
            array![[3e-310], [1e-310], [2e-310]].view(),
        )
        .unwrap();
        assert!(close(r[[0, 0]], 1.0), "{r}");
    }

    #[test]
    fn top_k_orders_by_correlation_then_index() {
        // Ties 0.9 (indices 1, 3) and 0.5 (0, 2): order 1, 3, 0; weight (0.9+0.9+0.5)/3.
        let (nb, w) = top_k(&[0.5, 0.9, 0.5, 0.9], 3);
        assert_eq!(nb, vec![1, 3, 0]);
        assert!(close(w, 2.3 / 3.0));
    }

    #[test]
    fn top_k_clips_k_and_weight() {
        let (nb, w) = top_k(&[0.2, 0.1], 5);
        assert_eq!(nb, vec![0, 1]);
        assert!(close(w, 0.15));
        // A negative mean correlation is clipped to weight 0.
        let (nb, w) = top_k(&[-0.5, -0.7], 1);
        assert_eq!((nb, w), (vec![0], 0.0));
    }

    #[test]
    fn correlations_within_the_grid_tie() {
        // 0.3 and 0.3 + 1e-15 differ by far less than 2^-40: a tie, so the lower index wins.
        assert_eq!(top_k(&[0.3, 0.3 + 1e-15], 1).0, vec![0]);
        // 1e-9 is far more than the grid: the larger one wins.
        assert_eq!(top_k(&[0.3, 0.3 + 1e-9], 1).0, vec![1]);
    }

    /// A fixed LCG in [0, 1).
    pub(super) fn lcg(seed: u64) -> impl FnMut() -> f64 {
        let mut x = seed;
        move || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn database_sizes_must_agree() {
        let err = ranked_correlation(array![[1.0], [2.0]].view(), array![[1.0], [2.0], [3.0]].view()).unwrap_err();
        assert_eq!(
            err,
            Error::DatabaseMismatch {
                calibration: 3,
                deployment: 2
            }
        );
    }
}
