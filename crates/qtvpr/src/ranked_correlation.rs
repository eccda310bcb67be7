//! SPEC section 4: calibration sampling by ranked correlation.
//!
//! Every query column is sorted into a *ranked profile*; the Pearson correlation of two
//! profiles is the dot product of their centred, unit-norm forms, so the whole
//! |Qval| x |Qcal| correlation matrix is one matrix product, done by faer in parallel.
//! Each deployment query then keeps its `k` most correlated calibration queries
//! ([`top_k`]).
//!
//! Profiles are kept in *ascending* order: reversing both profiles of a pair changes
//! neither their correlation nor any count of scores below a threshold, and ascending
//! is what the radix sort gives. [`Ranked`] gathers a block of columns into a
//! column-major buffer of the input's own type (tile by tile, so a C-order matrix is
//! read row-wise rather than with one cache miss per score), checks every score is
//! finite, and sorts each column in place.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use ndarray::{Array2, ArrayView2, ShapeBuilder, s};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::input::{Score, check_nonempty};

/// Correlations are compared on a grid of `2^-40` (about 9.1e-13) when choosing
/// neighbours, so that correlations equal in exact arithmetic tie (and go to the lower
/// calibration index) whatever the floating-point summation order of the product.
pub const CORRELATION_GRID: f64 = 1.0 / (1u64 << 40) as f64;

/// A block of columns, each sorted ascending, column-major, in the input's type.
pub(crate) struct Ranked<T> {
    n_db: usize,
    sorted: Vec<T>,
}

impl<T: Score> Ranked<T> {
    /// Gather, check and sort the columns of `s`. `first_col` is the column index of
    /// `s`'s first column in the matrix `what` names, for error messages.
    ///
    /// # Errors
    /// [`Error::Empty`]; [`Error::NotFinite`] naming the first offending score in
    /// column-major order.
    pub(crate) fn new(what: &'static str, s: ArrayView2<'_, T>, first_col: usize) -> Result<Self> {
        check_nonempty(what, s.dim())?;
        let n_db = s.nrows();
        let mut sorted = vec![T::default(); s.len()];
        const TILE: usize = 64;
        sorted.par_chunks_mut(n_db * TILE).enumerate().for_each(|(tile, out)| {
            let cols = tile * TILE..(tile * TILE + out.len() / n_db);
            for rows in (0..n_db).step_by(4 * TILE).map(|r| r..(r + 4 * TILE).min(n_db)) {
                let block = s.slice(s![rows.clone(), cols.clone()]);
                for (i, row) in rows.zip(block.rows()) {
                    for (j, &v) in row.iter().enumerate() {
                        out[j * n_db + i] = v;
                    }
                }
            }
        });
        let bad = sorted.par_chunks(n_db).enumerate().find_map_first(|(col, column)| {
            let (row, v) = column.iter().enumerate().find(|(_, v)| !v.to_f64().is_finite())?;
            Some(Error::NotFinite {
                what,
                row,
                col: first_col + col,
                value: v.to_f64(),
            })
        });
        if let Some(err) = bad {
            return Err(err);
        }
        sorted.par_chunks_mut(n_db).for_each(T::sort_ascending);
        Ok(Self { n_db, sorted })
    }

    pub(crate) fn ncols(&self) -> usize {
        self.sorted.len() / self.n_db
    }

    /// Column `j`, ascending.
    pub(crate) fn column(&self, j: usize) -> &[T] {
        &self.sorted[j * self.n_db..(j + 1) * self.n_db]
    }

    /// All columns as a |DB| x n view (the same multiset of scores per column as the input).
    pub(crate) fn view(&self) -> ArrayView2<'_, T> {
        ArrayView2::from_shape((self.n_db, self.ncols()).f(), &self.sorted).expect("length is n_db * ncols")
    }

    /// The centred, unit-norm profiles.
    pub(crate) fn unit(&self) -> Unit {
        let mut unit = vec![0.0; self.sorted.len()];
        unit.par_chunks_mut(self.n_db)
            .zip(self.sorted.par_chunks(self.n_db))
            .for_each(|(z, p)| standardise(p, z));
        Unit { n_db: self.n_db, unit }
    }
}

/// Centred, unit-norm ranked profiles (zero for a constant column), column-major.
pub(crate) struct Unit {
    n_db: usize,
    unit: Vec<f64>,
}

impl Unit {
    fn mat(&self) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice(&self.unit, self.n_db, self.unit.len() / self.n_db)
    }

    /// Correlations with `cal`, as a column-major |Qcal| x |self| matrix: column `j`
    /// holds row `j` of the spec's `R`, contiguous.
    pub(crate) fn correlate(&self, cal: &Unit) -> Vec<f64> {
        let (lhs, rhs) = (cal.mat(), self.mat());
        let mut r = vec![0.0; lhs.ncols() * rhs.ncols()];
        let dst = MatMut::from_column_major_slice_mut(&mut r, lhs.ncols(), rhs.ncols());
        matmul(dst, Accum::Replace, lhs.transpose(), rhs, 1.0, Par::rayon(0));
        r
    }
}

/// Centre a sorted profile and scale it to unit norm, into `out`; all zeros when it is
/// constant (zero variance is tested exactly, as first == last, not as a small norm).
pub(crate) fn standardise<T: Score>(profile: &[T], out: &mut [f64]) {
    let n = profile.len();
    let (first, last) = (profile[0].to_f64(), profile[n - 1].to_f64());
    if first == last {
        out.fill(0.0);
        return;
    }
    // Scale by the largest magnitude first so that squares neither overflow nor underflow
    // (a division: the reciprocal of a subnormal scale would overflow).
    let scale = first.abs().max(last.abs());
    for (o, x) in out.iter_mut().zip(profile) {
        *o = x.to_f64() / scale;
    }
    let mean = out.iter().sum::<f64>() / n as f64;
    out.iter_mut().for_each(|o| *o -= mean);
    let inv_norm = 1.0 / out.iter().map(|o| o * o).sum::<f64>().sqrt();
    out.iter_mut().for_each(|o| *o *= inv_norm);
}

/// The `k` (clipped to the row length) calibration indices of highest correlation in
/// `row`, in order of decreasing correlation, ties to the lower index; and the weight:
/// the mean of their correlations, clipped below at 0.
///
/// Correlations are compared on the [`CORRELATION_GRID`]; the weight uses raw values.
pub fn top_k(row: &[f64], k: usize) -> (Vec<usize>, f64) {
    let k = k.min(row.len());
    let key = |i: usize| (row[i] / CORRELATION_GRID).round_ties_even();
    let order = |a: &usize, b: &usize| key(*b).total_cmp(&key(*a)).then(a.cmp(b));
    let mut idx: Vec<usize> = (0..row.len()).collect();
    if k < idx.len() {
        idx.select_nth_unstable_by(k - 1, order);
        idx.truncate(k);
    }
    idx.sort_unstable_by(order);
    let mean = idx.iter().map(|&i| row[i]).sum::<f64>() / k as f64;
    (idx, mean.max(0.0))
}

/// The full |Qval| x |Qcal| ranked-correlation matrix `R` of SPEC section 4.
///
/// # Errors
/// Empty or non-finite scores, or a different number of database rows.
pub fn ranked_correlation<T: Score, U: Score>(val: ArrayView2<'_, T>, cal: ArrayView2<'_, U>) -> Result<Array2<f64>> {
    let cal = Ranked::new("calibration similarity", cal, 0)?;
    let val = Ranked::new("deployment similarity", val, 0)?;
    if val.n_db != cal.n_db {
        return Err(Error::DatabaseMismatch {
            calibration: cal.n_db,
            deployment: val.n_db,
        });
    }
    let r = val.unit().correlate(&cal.unit());
    // Column-major |Qcal| x |Qval| is row-major |Qval| x |Qcal|.
    Ok(Array2::from_shape_vec((val.ncols(), cal.ncols()), r).expect("shape matches length"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    fn close(a: f64, b: f64) -> bool {
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
