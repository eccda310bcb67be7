//! semantics §4: calibration sampling by ranked correlation.
//!
//! Every query column is sorted into a *ranked profile*; the Pearson correlation of two
//! profiles is the dot product of their centred, unit-norm forms. Each deployment query
//! keeps its `k` most correlated calibration queries ([`top_k`]).
//!
//! The |Qval| x |Qcal| correlations are found in two steps, with the same result as
//! computing them all in `f64`:
//! 1. a *screen*: each profile's offset from the mean calibration profile is rounded to
//!    `f32`, and one faer product of those offsets (twice the speed and half the memory
//!    of `f64`) gives every correlation to within a proven bound, which shrinks with
//!    the offsets' norms (`Screen::error`);
//! 2. each deployment query computes in `f64` only the correlations that the bound says
//!    could reach its top `k` (`screened_top_k`): about `k` of them on real data.
//!
//! Profiles are kept in *ascending* order: reversing both profiles of a pair changes
//! neither their correlation nor any count of scores below a threshold, and ascending
//! is what the radix sort gives. `Ranked` gathers a block of columns into a
//! column-major buffer of the input's own type (tile by tile, so a C-order matrix is
//! read row-wise rather than with one cache miss per score), checks every score is
//! finite, and sorts, standardises and screens each column while it is in cache.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use ndarray::{Array2, ArrayView2, ShapeBuilder, s};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::input::{Score, check_nonempty};
use crate::names::Input;
use crate::threads;

/// Correlations are compared on a grid of `2^-40` (about 9.1e-13) when choosing
/// neighbours, so that correlations equal in exact arithmetic tie (and go to the lower
/// calibration index) whatever the floating-point summation order.
pub const CORRELATION_GRID: f64 = 1.0 / (1u64 << 40) as f64;

/// A block of columns, each sorted ascending, column-major, in the input's type; with
/// each column's standardisation and its [`Screen`].
#[derive(Default)]
pub(crate) struct Ranked<T> {
    n_db: usize,
    sorted: Vec<T>,
    standard: Vec<Standard>,
    screen: Screen,
}

/// Standardised profiles `p` as offsets from a [`Reference`] profile `m`, for the
/// screening product: per column, `p - m` rounded to `f32` (column-major), `p . m` and
/// `|p - m|`. Then `p . q = p . m + (q . m - m . m) + (p - m) . (q - m)`, and only the
/// last, small term is taken in `f32`, so its error shrinks with the offsets' norms.
#[derive(Default)]
pub(crate) struct Screen {
    n_db: usize,
    offsets: Vec<f32>,
    along: Vec<f64>,
    spread: Vec<f64>,
}

/// The profile screens are taken against: the mean standardised calibration profile
/// (or zero), with its squared norm.
pub(crate) struct Reference {
    profile: Vec<f64>,
    norm2: f64,
}

impl Reference {
    /// The zero profile: screens of the profiles themselves.
    pub(crate) fn zero(n_db: usize) -> Self {
        Self {
            profile: vec![0.0; n_db],
            norm2: 0.0,
        }
    }

    /// The mean standardised profile of `ranked`'s columns, summed row by row in column
    /// order (the same bits on every run).
    pub(crate) fn mean_of<T: Score>(ranked: &Ranked<T>) -> Self {
        threads::install(|| {
            let mut profile = vec![0.0; ranked.n_db];
            const ROWS: usize = 256;
            profile.par_chunks_mut(ROWS).enumerate().for_each(|(block, out)| {
                let rows = block * ROWS..block * ROWS + out.len();
                for j in 0..ranked.ncols() {
                    let standard = ranked.standard[j];
                    for (o, &x) in out.iter_mut().zip(&ranked.column(j)[rows.clone()]) {
                        *o += standard.apply(x);
                    }
                }
                let n = ranked.ncols() as f64;
                out.iter_mut().for_each(|o| *o /= n);
            });
            let norm2 = sum_lanes(&profile, &profile, |a, b| a * b);
            Self { profile, norm2 }
        })
    }
}

impl<T: Score> Ranked<T> {
    /// Gather, check, sort and standardise the columns of `s`, and screen them against
    /// `reference`. `first_col` is the column index of `s`'s first column in the matrix
    /// `what` names, for error messages.
    ///
    /// # Errors
    /// [`Error::Empty`]; [`Error::NotFinite`] naming the first offending score in
    /// column-major order.
    pub(crate) fn new(what: Input, s: ArrayView2<'_, T>, first_col: usize, reference: &Reference) -> Result<Self> {
        let mut ranked = Self::default();
        ranked.refill(what, s, first_col, reference)?;
        Ok(ranked)
    }

    /// [`Ranked::new`] in the buffers of `self`, for a stream of chunks (fresh buffers
    /// for each would cost the kernel zeroing their pages again and again).
    ///
    /// # Errors
    /// As [`Ranked::new`]; `self` is then left in an unspecified but valid state.
    pub(crate) fn refill(
        &mut self,
        what: Input,
        s: ArrayView2<'_, T>,
        first_col: usize,
        reference: &Reference,
    ) -> Result<()> {
        threads::install(|| {
            check_nonempty(what, s.dim())?;
            let (n_db, n) = s.dim();
            let Self {
                sorted,
                standard,
                screen,
                ..
            } = self;
            self.n_db = n_db;
            sorted.resize(s.len(), T::default());
            standard.resize(n, Standard::CONSTANT);
            screen.resize(n_db, n);
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
            let bad = sorted
                .par_chunks_mut(n_db)
                .zip(standard)
                .zip(screen.columns_mut())
                .enumerate()
                .find_map_first(|(col, ((column, standard), screen))| {
                    if !column.iter().fold(true, |finite, v| finite & v.to_f64().is_finite()) {
                        let (row, v) = column.iter().enumerate().find(|(_, v)| !v.to_f64().is_finite())?;
                        return Some(Error::NotFinite {
                            what,
                            row,
                            col: first_col + col,
                            value: v.to_f64(),
                        });
                    }
                    T::sort_ascending(column);
                    *standard = screen_column(column, reference, screen);
                    None
                });
            bad.map_or(Ok(()), Err)
        })
    }

    pub(crate) fn ncols(&self) -> usize {
        self.standard.len()
    }

    /// Column `j`, ascending.
    pub(crate) fn column(&self, j: usize) -> &[T] {
        &self.sorted[j * self.n_db..(j + 1) * self.n_db]
    }

    /// All columns as a |DB| x n view (the same multiset of scores per column as the input).
    pub(crate) fn view(&self) -> ArrayView2<'_, T> {
        ArrayView2::from_shape((self.n_db, self.ncols()).f(), &self.sorted).expect("length is n_db * ncols")
    }

    /// The standardised profile of column `j`, in `f64`, into `out`.
    pub(crate) fn profile(&self, j: usize, out: &mut [f64]) {
        let standard = self.standard[j];
        out.iter_mut()
            .zip(self.column(j))
            .for_each(|(o, &x)| *o = standard.apply(x));
    }

    /// The correlation of column `j` with a standardised profile `u`, in `f64`.
    pub(crate) fn correlation(&self, j: usize, u: &[f64]) -> f64 {
        pulp::Arch::new().dispatch(Correlation {
            u,
            column: self.column(j),
            standard: self.standard[j],
        })
    }

    /// Screen every column against `reference` afresh.
    pub(crate) fn rescreen(&mut self, reference: &Reference) {
        threads::install(|| {
            let Self {
                n_db,
                sorted,
                standard,
                screen,
            } = self;
            sorted
                .par_chunks(*n_db)
                .zip(standard)
                .zip(screen.columns_mut())
                .for_each(|((column, standard), screen)| *standard = screen_column(column, reference, screen));
        })
    }

    pub(crate) fn screen(&self) -> &Screen {
        &self.screen
    }
}

/// Standardise a sorted column and screen it against `reference`, compiled for the
/// widest vectors the CPU has.
fn screen_column<T: Score>(
    column: &[T],
    reference: &Reference,
    (offsets, along, spread): (&mut [f32], &mut f64, &mut f64),
) -> Standard {
    let standard;
    (standard, *along, *spread) = pulp::Arch::new().dispatch(ScreenColumn {
        column,
        reference: &reference.profile,
        offsets,
    });
    standard
}

impl Screen {
    /// Room for `n` columns of `n_db` scores.
    fn resize(&mut self, n_db: usize, n: usize) {
        self.n_db = n_db;
        self.offsets.resize(n_db * n, 0.0);
        self.along.resize(n, 0.0);
        self.spread.resize(n, 0.0);
    }

    /// Per column: its offsets, `p . m` and `|p - m|`, to fill.
    fn columns_mut(&mut self) -> impl IndexedParallelIterator<Item = (&mut [f32], &mut f64, &mut f64)> {
        (self.offsets.par_chunks_mut(self.n_db))
            .zip(&mut self.along)
            .zip(&mut self.spread)
            .map(|((o, a), s)| (o, a, s))
    }

    fn offsets(&self) -> MatRef<'_, f32> {
        MatRef::from_column_major_slice(&self.offsets, self.n_db, self.along.len())
    }

    /// The largest `|p - m|`.
    pub(crate) fn max_spread(&self) -> f64 {
        self.spread.iter().copied().fold(0.0, f64::max)
    }

    /// Screened correlations of `self`'s columns with `cal`'s (both against `reference`),
    /// as a column-major |Qcal| x |self| matrix: column `j` holds row `j` of the spec's
    /// `R`, each value within [`Screen::error`] of the `f64` one.
    ///
    /// The `f32` product runs over blocks of [`DEPTH`] database rows, summed into the
    /// result, so that its error bound does not grow with |DB|.
    pub(crate) fn correlations(&self, cal: &Screen, reference: &Reference) -> Vec<f64> {
        threads::install(|| {
            let (val_offsets, cal_offsets) = (self.offsets(), cal.offsets());
            let mut products = vec![0.0f32; cal.along.len() * self.along.len()];
            let mut dst = MatMut::from_column_major_slice_mut(&mut products, cal.along.len(), self.along.len());
            for start in (0..self.n_db).step_by(DEPTH) {
                let rows = DEPTH.min(self.n_db - start);
                let accum = if start == 0 { Accum::Replace } else { Accum::Add };
                let (lhs, rhs) = (
                    cal_offsets.subrows(start, rows).transpose(),
                    val_offsets.subrows(start, rows),
                );
                matmul(dst.as_mut(), accum, lhs, rhs, 1.0, Par::rayon(0));
            }
            let n_cal = cal.along.len();
            let mut r = vec![0.0; products.len()];
            (r.par_chunks_mut(n_cal).zip(products.par_chunks(n_cal)).zip(&self.along)).for_each(|((r, d), along)| {
                let shift = along - reference.norm2;
                r.iter_mut()
                    .zip(d)
                    .zip(&cal.along)
                    .for_each(|((r, &d), a)| *r = a + shift + f64::from(d));
            });
            r
        })
    }

    /// A bound on the difference between the screened correlation of column `j` with any
    /// calibration column (whose largest spread is `cal_spread`) and the `f64` one.
    ///
    /// With `u = 2^-24`, offsets `a` and `b` of norms `|a|` and `|b|`:
    /// - rounding both to `f32` moves their dot product by at most `(2u + u^2) |a| |b|`;
    /// - each block's `f32` dot product of `d <= DEPTH` terms, in any summation order,
    ///   is off by at most `gamma(d) = d u / (1 - d u)` times its sum of absolute
    ///   products, and those sums add up to at most `|a| |b|` (Cauchy-Schwarz);
    /// - adding each block's result into the total, and rounding the last, costs at
    ///   most `u` times a sum below `2 |a| |b|` each;
    /// - the `f64` terms (`p . m`, `m . m`, the sums, the rounding of the offsets, and
    ///   the `f64` correlation itself) are each within `gamma_64(n_db)` of exact, with
    ///   norms at most 1 (`m` is a mean of unit vectors).
    ///
    /// The `f32` part is inflated by 1% for the norms' own rounding.
    pub(crate) fn error(&self, j: usize, cal_spread: f64) -> f64 {
        let gamma = |m: usize, u: f64| m as f64 * u / (1.0 - m as f64 * u);
        let u = f64::from(f32::EPSILON) / 2.0;
        let blocks = self.n_db.div_ceil(DEPTH) as f64;
        let f32_part = 1.01 * (3.0 * u + gamma(self.n_db.min(DEPTH), u) + 2.0 * u * (blocks + 1.0));
        f32_part * self.spread[j] * cal_spread + 8.0 * gamma(self.n_db + 2, f64::EPSILON / 2.0)
    }
}

/// Database rows per block of the screening product.
const DEPTH: usize = 1024;

/// How a sorted profile is centred and scaled to unit norm: `(x * inv_scale - mean) *
/// inv_norm`, where `inv_scale` is a power of two that keeps squares from overflowing
/// or underflowing (so scaling is exact), and `inv_norm` is 0 for a constant profile.
#[derive(Debug, Clone, Copy)]
struct Standard {
    inv_scale: f64,
    mean: f64,
    inv_norm: f64,
}

impl Standard {
    const CONSTANT: Self = Self {
        inv_scale: 1.0,
        mean: 0.0,
        inv_norm: 0.0,
    };

    /// The standardisation of a sorted, finite profile. Zero variance is tested exactly
    /// (first == last), not as a small norm.
    #[inline(always)]
    fn of<T: Score>(profile: &[T]) -> Self {
        let (first, last) = (profile[0].to_f64(), profile[profile.len() - 1].to_f64());
        if first == last {
            return Self::CONSTANT;
        }
        // 2^-e for the exponent e of the largest magnitude, within range both ways.
        let exponent = first.abs().max(last.abs()).log2().floor().clamp(-1000.0, 1000.0);
        let inv_scale = (-exponent).exp2();
        let mean = sum_lanes(profile, profile, |x, _| x.to_f64() * inv_scale) / profile.len() as f64;
        let centred = Self {
            inv_scale,
            mean,
            inv_norm: 1.0,
        };
        let norm = sum_lanes(profile, profile, |x, _| centred.apply(x).powi(2)).sqrt();
        Self {
            inv_norm: 1.0 / norm,
            ..centred
        }
    }

    #[inline(always)]
    fn apply<T: Score>(self, x: T) -> f64 {
        (x.to_f64() * self.inv_scale - self.mean) * self.inv_norm
    }
}

/// The correlation of a standardised profile `u` with a sorted `column`, compiled for
/// the widest vectors the CPU has (the lanes of [`sum_lanes`] fix the summation order,
/// so every CPU gets the same bits).
struct Correlation<'a, T> {
    u: &'a [f64],
    column: &'a [T],
    standard: Standard,
}

impl<T: Score> pulp::WithSimd for Correlation<'_, T> {
    type Output = f64;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> f64 {
        let standard = self.standard;
        sum_lanes(self.u, self.column, |a, x| a * standard.apply(x))
    }
}

/// The kernel of [`screen_column`]: the standardisation of `column`, and its offsets
/// from `reference` with `p . m` and `|p - m|`, in the lanes of [`sum_lanes`].
struct ScreenColumn<'a, T> {
    column: &'a [T],
    reference: &'a [f64],
    offsets: &'a mut [f32],
}

impl<T: Score> pulp::WithSimd for ScreenColumn<'_, T> {
    type Output = (Standard, f64, f64);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> (Standard, f64, f64) {
        const LANES: usize = 8;
        let standard = Standard::of(self.column);
        let (mut along, mut spread) = ([0.0; LANES], [0.0; LANES]);
        let mut lane = |l: usize, x: T, m: f64, o: &mut f32| {
            let p = standard.apply(x);
            let d = p - m;
            *o = d as f32;
            along[l] += p * m;
            spread[l] += d * d;
        };
        let (x8, m8) = (self.column.chunks_exact(LANES), self.reference.chunks_exact(LANES));
        let (x_tail, m_tail) = (x8.remainder(), m8.remainder());
        let mut o8 = self.offsets.chunks_exact_mut(LANES);
        for ((x, m), o) in x8.zip(m8).zip(&mut o8) {
            for l in 0..LANES {
                lane(l, x[l], m[l], &mut o[l]);
            }
        }
        for ((&x, &m), o) in x_tail.iter().zip(m_tail).zip(o8.into_remainder()) {
            lane(0, x, m, o);
        }
        let sum = |lanes: [f64; LANES]| lanes.iter().sum::<f64>();
        (standard, sum(along), sum(spread).sqrt())
    }
}

/// The sum of `f(a_i, b_i)` over two equally long slices, in eight interleaved lanes:
/// vectorisable, and the same order every time.
#[inline(always)]
fn sum_lanes<A: Copy, B: Copy>(a: &[A], b: &[B], f: impl Fn(A, B) -> f64) -> f64 {
    const LANES: usize = 8;
    let (a8, b8) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f64 = a8.remainder().iter().zip(b8.remainder()).map(|(&x, &y)| f(x, y)).sum();
    let mut lanes = [0.0; LANES];
    for (x, y) in a8.zip(b8) {
        for l in 0..LANES {
            lanes[l] += f(x[l], y[l]);
        }
    }
    lanes.iter().sum::<f64>() + tail
}

/// The `k` (clipped to the row length) calibration indices of highest correlation in
/// `row`, in order of decreasing correlation, ties to the lower index; and the weight:
/// the mean of their correlations, clipped below at 0.
///
/// Correlations are compared on the [`CORRELATION_GRID`]; the weight uses raw values.
pub fn top_k(row: &[f64], k: usize) -> (Vec<usize>, f64) {
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

/// [`top_k`] from screened correlations `screen` (each within `error` of the `f64`
/// one) and `exact(i)`, the `f64` correlation with calibration query `i`, which is only
/// asked for the queries the bound cannot rule out.
///
/// If the k-th largest screened value is `a`, at least `k` correlations are at least
/// `a - error`; any query screened below `a - 2 error - 2 grid` is more than a grid
/// step below all of those, so it can neither enter the top `k` nor tie into it.
pub(crate) fn screened_top_k(screen: &[f64], k: usize, error: f64, exact: impl Fn(usize) -> f64) -> (Vec<usize>, f64) {
    let k = k.min(screen.len());
    let mut values = screen.to_vec();
    let (_, &mut kth, _) = values.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
    let cut = kth - 2.0 * (error + CORRELATION_GRID);
    let pairs = (screen.iter().enumerate())
        .filter(|&(_, &a)| a >= cut)
        .map(|(i, _)| (i, exact(i)))
        .collect();
    top_k_of(pairs, k)
}

/// The full |Qval| x |Qcal| ranked-correlation matrix `R` of semantics §4, in `f64`,
/// the same values the transfer ranks neighbours by.
///
/// # Errors
/// Empty or non-finite scores, or a different number of database rows.
pub fn ranked_correlation<T: Score, U: Score>(val: ArrayView2<'_, T>, cal: ArrayView2<'_, U>) -> Result<Array2<f64>> {
    threads::install(|| {
        let zero = Reference::zero(cal.nrows());
        let cal = Ranked::new(Input::CalSimilarity, cal, 0, &zero)?;
        let val = Ranked::new(Input::DeploymentSimilarity, val, 0, &zero)?;
        if val.n_db != cal.n_db {
            return Err(Error::DatabaseMismatch {
                calibration: cal.n_db,
                deployment: val.n_db,
            });
        }
        let mut r = vec![0.0; val.ncols() * cal.ncols()];
        r.par_chunks_mut(cal.ncols()).enumerate().for_each_init(
            || vec![0.0; val.n_db],
            |u, (j, row)| {
                val.profile(j, u);
                row.iter_mut().enumerate().for_each(|(i, r)| *r = cal.correlation(i, u));
            },
        );
        Ok(Array2::from_shape_vec((val.ncols(), cal.ncols()), r).expect("shape matches length"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, array};

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

    /// A fixed LCG in [0, 1).
    fn lcg(seed: u64) -> impl FnMut() -> f64 {
        let mut x = seed;
        move || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn screen_stays_within_its_bound() {
        // Profiles long enough for several product blocks, with an offset far from zero
        // (the hard case for centring) and near-identical columns (correlations near 1,
        // where the reference profile must make the bound tight), against the mean
        // calibration profile and against zero; for a block of deployment columns and
        // for one column alone (an online push, which takes another product kernel).
        let mut rand = lcg(3);
        let n_db = 2 * DEPTH + 77;
        let base: Vec<f64> = (0..n_db).map(|_| rand()).collect();
        let cal = Array2::from_shape_fn((n_db, 7), |(i, j)| 100.0 + base[i] + 0.01 * j as f64 * rand());
        let block = Array2::from_shape_fn((n_db, 5), |(i, _)| (100.0 + base[i] + 0.02 * rand()) as f32);
        let zero = Reference::zero(n_db);
        let mut cal = Ranked::new(Input::CalSimilarity, cal.view(), 0, &zero).unwrap();
        for (mean, val) in [false, true]
            .into_iter()
            .flat_map(|m| [(m, block.view()), (m, block.slice(s![.., 2..3]))])
        {
            let reference = if mean {
                Reference::mean_of(&cal)
            } else {
                Reference::zero(n_db)
            };
            cal.rescreen(&reference);
            let val = Ranked::new(Input::DeploymentSimilarity, val, 0, &reference).unwrap();
            let screen = val.screen().correlations(cal.screen(), &reference);
            let mut u = vec![0.0; n_db];
            for j in 0..val.ncols() {
                let error = val.screen().error(j, cal.screen().max_spread());
                assert!(error < if mean { 1e-6 } else { 1e-4 }, "{error}");
                val.profile(j, &mut u);
                for i in 0..cal.ncols() {
                    let exact = cal.correlation(i, &u);
                    assert!(exact > 0.9, "{exact}");
                    let off = (screen[j * cal.ncols() + i] - exact).abs();
                    assert!(off <= error, "screen off by {off}, bound {error}");
                }
            }
        }
    }

    #[test]
    fn screening_picks_the_same_neighbours() {
        // Rows of correlations with near-ties below, at and above the grid, and a screen
        // that errs by up to the full bound in either direction.
        let mut rand = lcg(11);
        let error = 1e-4;
        for case in 0..2000 {
            let n = 1 + case % 40;
            let k = 1 + case % 13;
            let row: Vec<f64> = (0..n)
                .map(|_| match (rand() * 4.0) as u32 {
                    0 => 0.5,
                    1 => 0.5 + 1e-15,
                    2 => 0.5 + error * (rand() - 0.5),
                    _ => rand(),
                })
                .collect();
            let screen: Vec<f64> = row.iter().map(|&r| r + error * (2.0 * rand() - 1.0)).collect();
            let expected = top_k(&row, k);
            let got = screened_top_k(&screen, k, error, |i| row[i]);
            assert_eq!(got.0, expected.0, "case {case}: {row:?}");
            assert_eq!(got.1.to_bits(), expected.1.to_bits(), "case {case}");
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
