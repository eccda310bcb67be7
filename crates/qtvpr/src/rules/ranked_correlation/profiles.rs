//! Ranked profiles (semantics §4.1): a block of query columns, each sorted ascending in
//! the input's own type and standardised, and their correlations with a standardised
//! deployment profile.
//!
//! [`Ranked`] gathers a block of columns into a column-major buffer (tile by tile, so a
//! C-order matrix is read row-wise rather than with one cache miss per score), checks
//! every score is finite, and sorts and standardises each column while it is in cache.

use ndarray::{ArrayView2, ArrayViewMut1, ShapeBuilder, s};
use rayon::prelude::*;

#[cfg(test)]
use super::kernels::sum_lanes;
use super::kernels::{Correlations, GROUP, Standard, Standardise};
use crate::error::names::Input;
use crate::error::{Error, Result, try_reserve};
use crate::input::{Score, check_nonempty};
use crate::platform::threads;

/// What an allocation failure names: the sorted profiles of `n` columns of `n_db` scores.
fn profiles(what: Input, n_db: usize, n: usize) -> String {
    format!("the sorted profiles of the {what} ({n_db}x{n})")
}

/// A block of columns, each sorted ascending, column-major, in the input's type; with
/// each column's standardisation.
#[derive(Default)]
pub(crate) struct Ranked<T> {
    n_db: usize,
    sorted: Vec<T>,
    standard: Vec<Standard>,
}

impl<T: Score> Ranked<T> {
    /// Gather, check, sort and standardise the columns of `s`. `first_col` is the column
    /// index of `s`'s first column in the matrix `what` names, for error messages.
    ///
    /// # Errors
    /// [`Error::Empty`]; [`Error::NotFinite`] naming the first offending score in
    /// column-major order.
    pub(crate) fn new(what: Input, s: ArrayView2<'_, T>, first_col: usize) -> Result<Self> {
        let mut ranked = Self::default();
        ranked.refill(what, s, first_col)?;
        Ok(ranked)
    }

    /// [`Ranked::new`] in the buffers of `self`, for a stream of chunks (fresh buffers
    /// for each would cost the kernel zeroing their pages again and again).
    ///
    /// # Errors
    /// As [`Ranked::new`]; `self` is then left in an unspecified but valid state.
    pub(crate) fn refill(&mut self, what: Input, s: ArrayView2<'_, T>, first_col: usize) -> Result<()> {
        check_nonempty(what, s.dim())?;
        self.refill_with(what, s.dim(), first_col, |out| gather(s, out))
    }

    /// [`Ranked::refill`] with the |DB| x `n` scores written by `fill` into the
    /// column-major buffer it is given, where they are then sorted: the scores are never
    /// copied (the fused transfer computes them there).
    ///
    /// # Errors
    /// As [`Ranked::new`].
    pub(crate) fn refill_with(
        &mut self,
        what: Input,
        (n_db, n): (usize, usize),
        first_col: usize,
        fill: impl FnOnce(&mut [T]),
    ) -> Result<()> {
        self.n_db = n_db;
        let len = n_db.saturating_mul(n);
        let more = len.saturating_sub(self.sorted.len());
        try_reserve(&mut self.sorted, more, || profiles(what, n_db, n))?;
        self.sorted.resize(len, T::default());
        self.standard.clear();
        self.rank_from(what, first_col, fill)
    }

    /// No columns yet, room for `n` columns of `n_db` scores, to be added by
    /// [`Ranked::extend_with`] (a calibration built a few columns at a time).
    ///
    /// # Errors
    /// [`Error::Allocation`] when memory for them cannot be had.
    pub(crate) fn with_capacity(what: Input, n_db: usize, n: usize) -> Result<Self> {
        let mut sorted = Vec::new();
        try_reserve(&mut sorted, n_db.saturating_mul(n), || profiles(what, n_db, n))?;
        Ok(Self {
            n_db,
            sorted,
            standard: Vec::with_capacity(n),
        })
    }

    /// Append `n` columns, written by `fill` as by [`Ranked::refill_with`]; `first_col`
    /// is the first's column index, for errors.
    ///
    /// # Errors
    /// As [`Ranked::new`].
    pub(crate) fn extend_with(
        &mut self,
        what: Input,
        n: usize,
        first_col: usize,
        fill: impl FnOnce(&mut [T]),
    ) -> Result<()> {
        let more = self.n_db.saturating_mul(n);
        try_reserve(&mut self.sorted, more, || profiles(what, self.n_db, n))?;
        self.sorted.resize(self.sorted.len() + more, T::default());
        self.rank_from(what, first_col, fill)
    }

    /// Fill the columns after the last standardised one with `fill`, then check, sort
    /// and standardise them: in parallel, or on the calling thread for one column (a
    /// push, which then never waits for the pool).
    fn rank_from(&mut self, what: Input, first_col: usize, fill: impl FnOnce(&mut [T])) -> Result<()> {
        let Self { n_db, sorted, standard } = self;
        let new = &mut sorted[standard.len() * *n_db..];
        fill(new);
        let base = standard.len();
        standard.resize(base + new.len() / *n_db, Standard::CONSTANT);
        let rank = |col: usize, (column, standard): (&mut [T], &mut Standard)| {
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
            *standard = pulp::Arch::new().dispatch(Standardise(column));
            None
        };
        let columns = new.chunks_mut(*n_db).zip(&mut standard[base..]);
        let bad = if columns.len() == 1 {
            columns.enumerate().find_map(|(col, c)| rank(col, c))
        } else {
            threads::install(|| {
                let columns = new.par_chunks_mut(*n_db).zip(&mut standard[base..]);
                columns.enumerate().find_map_first(|(col, c)| rank(col, c))
            })
        };
        bad.map_or(Ok(()), Err)
    }

    pub(crate) fn ncols(&self) -> usize {
        self.standard.len()
    }

    /// |DB|: the length of every column.
    pub(super) fn n_db(&self) -> usize {
        self.n_db
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

    /// The correlation of column `j` with a standardised profile `u`, in `f64`: one
    /// [`sum_lanes`], the order [`Ranked::correlations`] keeps in its groups.
    #[cfg(test)]
    pub(super) fn correlation(&self, j: usize, u: &[f64]) -> f64 {
        let standard = self.standard[j];
        sum_lanes(u, self.column(j), |a, x| a * standard.apply(x))
    }

    /// The correlations of columns `js` with a standardised profile `u` into `out`, each
    /// the same bits as [`Ranked::correlation`]'s: [`GROUP`] columns in one pass over
    /// `u`, so that `u` is read once a group and the group's sums run side by side
    /// (one column's sum is a chain of dependent additions, which alone leaves the
    /// core waiting on each).
    pub(crate) fn correlations(&self, js: &[usize], u: &[f64], out: &mut [f64]) {
        let arch = pulp::Arch::new();
        for (js, out) in js.chunks(GROUP).zip(out.chunks_mut(GROUP)) {
            // A short group repeats its last column, whose sums are then dropped.
            let j = |m: usize| js[m.min(js.len() - 1)];
            let sums = Correlations {
                u,
                columns: std::array::from_fn(|m| self.column(j(m))),
                standard: std::array::from_fn(|m| self.standard[j(m)]),
            }
            .sums(arch);
            out.copy_from_slice(&sums[..out.len()]);
        }
    }
}

/// Copy the columns of `s` into `out`, column-major: one column (a push) on the calling
/// thread; contiguous columns (a Fortran-order matrix) as slices; otherwise a tile of
/// columns at a time in parallel, in blocks of rows (so that a C-order matrix is read
/// row by row).
fn gather<T: Score>(s: ArrayView2<'_, T>, out: &mut [T]) {
    let n_db = s.nrows();
    if s.ncols() == 1 {
        ArrayViewMut1::from(out).assign(&s.column(0));
        return;
    }
    if s.strides()[0] == 1 {
        threads::install(|| {
            out.par_chunks_mut(n_db).enumerate().for_each(|(j, out)| {
                out.copy_from_slice(s.column(j).to_slice().expect("a column of unit stride"));
            });
        });
        return;
    }
    threads::install(|| gather_tiles(s, out));
}

/// [`gather`] of a matrix whose columns are strided, in parallel over tiles of columns.
fn gather_tiles<T: Score>(s: ArrayView2<'_, T>, out: &mut [T]) {
    const TILE: usize = 64;
    let n_db = s.nrows();
    out.par_chunks_mut(n_db * TILE).enumerate().for_each(|(tile, out)| {
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
}

#[cfg(test)]
mod tests {
    use super::super::tests::lcg;
    use super::*;
    #[cfg(target_arch = "x86_64")]
    use crate::rules::ranked_correlation::kernels::Explicit;
    use ndarray::Array2;

    #[test]
    fn grouped_correlations_are_single_sums_bit_for_bit() {
        // Lengths with and without a tail of the 8 lanes; groups of every size, short
        // ones included, in any order and with repeats.
        for n_db in [1, 7, 8, 29, 64, 203] {
            let mut next = lcg(n_db as u64);
            let cal = Array2::from_shape_fn((n_db, 11), |_| next() * 2.0 - 1.0);
            let cal = Ranked::new(Input::CalSimilarity, cal.view(), 0).unwrap();
            let val = Array2::from_shape_fn((n_db, 1), |_| next());
            let val = Ranked::new(Input::DeploymentSimilarity, val.view(), 0).unwrap();
            let mut u = vec![0.0; n_db];
            val.profile(0, &mut u);
            for len in 1..=9 {
                let is: Vec<usize> = (0..len).map(|m| (7 * m + len) % 11).collect();
                let mut got = vec![f64::NAN; len];
                cal.correlations(&is, &u, &mut got);
                for (&i, c) in is.iter().zip(&got) {
                    assert_eq!(
                        c.to_bits(),
                        cal.correlation(i, &u).to_bits(),
                        "|DB| {n_db}, group {is:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn every_kernel_gives_the_bits_of_a_single_sum() {
        // The explicit AVX-512 and AVX2 kernels and the portable one (whichever this CPU
        // runs), on f32 and f64 columns, with and without a tail of the 8 lanes, against
        // `Ranked::correlation`.
        fn check<T: Score>(cal: &Ranked<T>, u: &[f64]) -> usize {
            let js = [3, 0, 5, 3];
            let group = || Correlations {
                u,
                columns: std::array::from_fn(|m| cal.column(js[m])),
                standard: std::array::from_fn(|m| cal.standard[js[m]]),
            };
            let want = js.map(|j| cal.correlation(j, u).to_bits());
            let mut kernels = vec![("portable", pulp::Simd::vectorize(pulp::Scalar, group()))];
            #[cfg(target_arch = "x86_64")]
            {
                if let Some(simd) = pulp::x86::V3::try_new() {
                    kernels.push(("AVX2", pulp::Simd::vectorize(simd, Explicit(simd, group()))));
                }
                if let Some(simd) = pulp::x86::V4::try_new() {
                    kernels.push(("AVX-512", pulp::Simd::vectorize(simd, Explicit(simd, group()))));
                }
            }
            for (name, got) in &kernels {
                assert_eq!(
                    got.map(f64::to_bits),
                    want,
                    "{name} kernel, {}, |DB| {}",
                    T::DTYPE,
                    u.len()
                );
            }
            kernels.len()
        }
        for n_db in [1, 7, 8, 29, 203, 1000] {
            let mut next = lcg(n_db as u64 + 100);
            // Columns of different scales, so that each has its own standardisation.
            let cal = Array2::from_shape_fn((n_db, 6), |(_, j)| (next() * 2.0 - 1.0) * 10f64.powi(j as i32 - 3));
            let val = Array2::from_shape_fn((n_db, 1), |_| next());
            let val = Ranked::new(Input::DeploymentSimilarity, val.view(), 0).unwrap();
            let mut u = vec![0.0; n_db];
            val.profile(0, &mut u);
            let ran = check(&Ranked::new(Input::CalSimilarity, cal.view(), 0).unwrap(), &u);
            let cal = cal.mapv(|v| v as f32);
            assert_eq!(
                check(&Ranked::new(Input::CalSimilarity, cal.view(), 0).unwrap(), &u),
                ran
            );
        }
    }
}
