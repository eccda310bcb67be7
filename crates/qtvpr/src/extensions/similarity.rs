//! Extension (not a section of the semantics): the similarity matrix from image descriptors.
//!
//! Researchers usually hold descriptors, not a similarity matrix: one row per image, e.g.
//! the `database_descriptors.npy` / `queries_descriptors.npy` that VPR-methods-evaluation
//! writes. [`cosine_similarity`] turns them into the |DB| x |Q| matrix the rest of the
//! crate takes: `S[i, j]` is the cosine of database row `i` and query row `j`, i.e. the
//! dot product of the L2-normalised rows, `normalize(db) @ normalize(q).T` in NumPy.
//! [`Descriptors`] holds the two descriptor matrices so that the transfer of a
//! [`ScoreSource::Descriptors`](crate::ScoreSource::Descriptors)
//! ([`Calibration::transfer`](crate::Calibration::transfer)) can compute the similarity
//! chunk by chunk instead: the |DB| x |Q| matrix then never exists.
//!
//! # Arithmetic: f64, rounded once to f32
//! Each row is widened to `f64` and made a unit vector as `(x * 2^-e) * (1 / |x 2^-e|)`,
//! with `2^e` the power of two at its largest magnitude (an exact scaling that keeps the
//! squares of the norm from overflowing or underflowing); the rows are multiplied by
//! faer's GEMM in `f64`, and each result is rounded once to `f32`, the type of the
//! output. Why `f64`, when an `f32` GEMM would be about twice as fast:
//! - semantics §1 does all arithmetic on scores in `f64`; the matrix made here is the
//!   input of that pipeline, and ties or near-ties in it decide best matches.
//! - The rounding error of an `f32` dot product grows with the descriptor dimension D
//!   (about `sqrt(D) * 6e-8` for unit vectors): harmless for D = 756, but at D = 4096 to
//!   32768 (NetVLAD, SALAD, BoQ) it approaches the 1e-5 this project promises against
//!   NumPy. In `f64` the result is the correctly rounded `f32` cosine up to ~1e-15,
//!   whatever D, whatever the input type, and whatever the thread count.
//!
//! # One kernel, one shape: the same bits whichever columns are asked for
//! The product is cut into tiles of [`TILE`] queries (aligned at multiples of [`TILE`]
//! from query 0) and blocks of [`BLOCK_ROWS`] database rows (aligned from row 0). Each
//! block is normalised and widened on the fly, and the last tile and block are padded
//! with zero rows, so that every GEMM call has exactly the same shape
//! ([`BLOCK_ROWS`] x D times D x [`TILE`]): faer's order of summation could otherwise
//! depend on the shape. Score `S[i, j]` is therefore always computed by the same call on
//! the same operands, and [`cosine_similarity`], [`Descriptors::similarity`] of any
//! range of queries and the fused transfer give identical bits by construction.
//!
//! # Checked up front, memory
//! The descriptors are checked (finite values, no all-zero row) in one cheap pass before
//! any product, so an error is never reported after minutes of work; the same pass
//! computes each row's two factors, so that a block of database rows is normalised with
//! two multiplications per value each time a tile of queries needs it. Beyond the
//! descriptors (which may be memory-mapped) and the output, the work takes the factors
//! (16 bytes a row), one `f64` copy of the query tiles being computed and, per thread,
//! one normalised block of database rows and one block of results (a few MB).

use std::ops::Range;

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use ndarray::{Array2, ArrayView1, ArrayView2, ArrayViewMut1, ArrayViewMut2, Axis, ShapeBuilder, Zip, s};
use rayon::prelude::*;

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::input::params::Options;
use crate::input::{Score, ScoresView, check_nonempty};
use crate::platform::threads;

/// Queries per tile of the product: the width of every GEMM call.
pub(crate) const TILE: usize = 16;
/// Database rows per block of the product: the height of every GEMM call.
pub const BLOCK_ROWS: usize = 256;
/// Scores per step of [`Descriptors::similarity`] (about 16 MB of `f32`).
const STEP_SCORES: usize = 1 << 22;

/// Cosine similarity of every database descriptor with every query descriptor.
///
/// `db` is |DB| x D and `queries` |Q| x D, one descriptor per row, `f32` or `f64`, any
/// strides (a C- or Fortran-order array, a slice, a transposed view). The result is
/// |DB| x |Q| (`S[i, j]` = cosine of `db` row `i` and `queries` row `j`), in `f32`, in
/// standard (C) order. See the module docs of `extensions/similarity.rs` for why the arithmetic is `f64`.
///
/// # Errors
/// - [`Error::Empty`] when either matrix has no rows or no columns;
/// - [`Error::ColumnMismatch`] when the descriptor dimensions differ;
/// - [`Error::NotFinite`] for a NaN or infinite value (the first by row, then column);
/// - [`Error::ZeroNorm`] for an all-zero row, whose cosine is undefined.
///
/// Errors in `db` are reported before errors in `queries`.
pub fn cosine_similarity<T: Score, U: Score>(db: ArrayView2<'_, T>, queries: ArrayView2<'_, U>) -> Result<Array2<f32>> {
    let d = Descriptors::new(db, queries)?;
    d.similarity(0..d.shape().1)
}

/// Database rows per step of a product with `n_cols` query columns: whole blocks of
/// about [`STEP_SCORES`] scores.
fn step_rows(n_cols: usize) -> usize {
    (STEP_SCORES / n_cols.max(1) / BLOCK_ROWS).max(1) * BLOCK_ROWS
}

/// Columns `cols` of the similarity of checked descriptors, |DB| x `cols.len()` in C
/// order, computed `step` database rows at a time (a multiple of [`BLOCK_ROWS`]), with
/// `progress` after each step.
fn similarity_in_steps<T: Score, U: Score>(
    db: Rows<'_, T>,
    queries: Rows<'_, U>,
    cols: Range<usize>,
    step: usize,
    progress: impl Fn(usize, usize),
) -> Array2<f32> {
    let n_db = db.m.nrows();
    let mut out = Array2::zeros((n_db, cols.len()));
    let tiles = QueryTiles::new(queries, cols.clone());
    for (s, dst) in out.axis_chunks_iter_mut(Axis(0), step).enumerate() {
        let none = ArrayViewMut2::from_shape((dst.nrows(), 0), &mut []).expect("no columns");
        fill(db, s * step, &tiles, dst, none);
        progress((s * step + step).min(n_db), n_db);
    }
    out
}

/// How a checked row `x` becomes a unit vector: `(x * pow2) * inv_norm`, in `f64`.
///
/// `pow2` is a power of two that brings the row's largest magnitude into [1, 2) (for
/// rows of subnormal values, as close as `f64` allows), so that multiplying by it is
/// exact and the squares of the norm neither overflow nor underflow whatever the
/// magnitude of the descriptor. Both factors are computed once per row, in one pass
/// with the check; the product then only multiplies, where dividing every value of every
/// database row once per tile of queries took a third of a fused transfer's time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct RowScale {
    pow2: f64,
    inv_norm: f64,
}

/// Check descriptors before any product: both non-empty, of one dimension, every value
/// finite and no row all zeros; `db` first, then `queries`, each in row order. Returns
/// the scaling of every row of each.
fn scales<T: Score, U: Score>(
    db: ArrayView2<'_, T>,
    queries: ArrayView2<'_, U>,
) -> Result<(Vec<RowScale>, Vec<RowScale>)> {
    check_nonempty(Input::DbDescriptors, db.dim())?;
    check_nonempty(Input::QueryDescriptors, queries.dim())?;
    if queries.ncols() != db.ncols() {
        return Err(Error::ColumnMismatch {
            what: Input::QueryDescriptors,
            cols: queries.ncols(),
            other: Input::DbDescriptors,
            other_cols: db.ncols(),
        });
    }
    Ok((
        row_scales(Input::DbDescriptors, db)?,
        row_scales(Input::QueryDescriptors, queries)?,
    ))
}

/// The scaling of every row of `m`, in parallel, or the error of its first bad row (by
/// row order).
fn row_scales<T: Score>(what: Input, m: ArrayView2<'_, T>) -> Result<Vec<RowScale>> {
    threads::install(|| {
        let mut scales = vec![RowScale::default(); m.nrows()];
        let bad = scales
            .par_iter_mut()
            .enumerate()
            .find_map_first(|(row, out)| row_scale(what, row, m.row(row)).map(|s| *out = s).err());
        bad.map_or(Ok(scales), Err)
    })
}

/// The scaling of row `x`, or why the row has no cosine.
fn row_scale<T: Score>(what: Input, row: usize, x: ArrayView1<'_, T>) -> Result<RowScale> {
    let mut largest = 0.0f64;
    for (col, v) in x.iter().enumerate() {
        let v = v.to_f64();
        if !v.is_finite() {
            return Err(Error::NotFinite {
                what,
                row,
                col,
                value: v,
            });
        }
        largest = largest.max(v.abs());
    }
    if largest == 0.0 {
        return Err(Error::ZeroNorm { what, row });
    }
    let pow2 = inverse_power_of_two(largest);
    let norm = x.iter().map(|v| (v.to_f64() * pow2).powi(2)).sum::<f64>().sqrt();
    Ok(RowScale {
        pow2,
        inv_norm: 1.0 / norm,
    })
}

/// A power of two `p` with `x * p` in [1, 2) for a positive finite `x` of normal
/// magnitude, `2^1022` for a subnormal `x` (`x * p` is then in [2^-52, 1): still far
/// from underflow when squared). Read off the exponent bits: exact, where `powi` or
/// `log2` would round.
fn inverse_power_of_two(x: f64) -> f64 {
    // x is in [2^(biased - 1023), 2^(biased - 1022)) for biased >= 1; subnormal x has 0.
    let biased = ((x.to_bits() >> 52) & 0x7ff) as i64;
    let e = (1023 - biased).min(1022);
    if e >= -1022 {
        f64::from_bits(((e + 1023) as u64) << 52)
    } else {
        f64::from_bits(1 << 51) // 2^-1023: subnormal, but exact
    }
}

/// A checked descriptor matrix with the scaling of each of its rows.
struct Rows<'a, T> {
    m: ArrayView2<'a, T>,
    scales: &'a [RowScale],
}

impl<T> Clone for Rows<'_, T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Rows<'_, T> {}

impl<'a, T: Score> Rows<'a, T> {
    fn new(m: ArrayView2<'a, T>, scales: &'a [RowScale]) -> Self {
        Self { m, scales }
    }

    /// Row `r` as a unit vector, into `out` (its length is D). `Zip` runs a contiguous
    /// row as a slice, so the loop is vectorised.
    fn unit(&self, r: usize, out: &mut [f64]) {
        let RowScale { pow2, inv_norm } = self.scales[r];
        Zip::from(ArrayViewMut1::from(out))
            .and(self.m.row(r))
            .for_each(|o, v| *o = (v.to_f64() * pow2) * inv_norm);
    }
}

/// The query tiles covering columns `cols`, normalised to `f64`, row-major
/// [`TILE`] x D each, zero-padded past the last query.
struct QueryTiles {
    /// Index of the first tile.
    first: usize,
    /// The columns asked for.
    cols: Range<usize>,
    /// The tiles, one after the other.
    unit: Vec<f64>,
    dim: usize,
}

impl QueryTiles {
    fn new<U: Score>(queries: Rows<'_, U>, cols: Range<usize>) -> Self {
        threads::install(|| {
            let dim = queries.m.ncols();
            let first = cols.start / TILE;
            let end = cols.end.div_ceil(TILE).max(first);
            let mut unit = vec![0.0; (end - first) * TILE * dim];
            let n_q = queries.m.nrows();
            unit.par_chunks_mut(dim).enumerate().for_each(|(r, out)| {
                let q = first * TILE + r;
                if q < n_q {
                    queries.unit(q, out);
                }
            });
            Self { first, cols, unit, dim }
        })
    }

    /// The number of tiles.
    fn len(&self) -> usize {
        self.unit.len() / (TILE * self.dim)
    }

    /// Tile `t` (counted from the first) as the D x [`TILE`] right-hand side.
    fn rhs(&self, t: usize) -> MatRef<'_, f64> {
        let size = TILE * self.dim;
        MatRef::from_row_major_slice(&self.unit[t * size..(t + 1) * size], TILE, self.dim).transpose()
    }
}

/// The kernel: rows `first_row..first_row + dst.nrows()` (`first_row` a multiple of
/// [`BLOCK_ROWS`]) of the columns `tiles.cols` into `dst` (any layout) and, past its
/// columns, into `spill` (the same rows, any layout; no columns for none): the columns a
/// caller keeps for later of the last tile it had to compute. In parallel over blocks of
/// database rows, each normalised once and multiplied by every tile.
fn fill<T: Score>(
    db: Rows<'_, T>,
    first_row: usize,
    tiles: &QueryTiles,
    mut dst: ArrayViewMut2<'_, f32>,
    mut spill: ArrayViewMut2<'_, f32>,
) {
    threads::install(|| {
        let dim = db.m.ncols();
        let cols = tiles.cols.clone();
        let mid = cols.start + dst.ncols();
        debug_assert_eq!(mid + spill.ncols(), cols.end, "dst and spill hold the columns");
        let blocks: Vec<_> = dst
            .axis_chunks_iter_mut(Axis(0), BLOCK_ROWS)
            .zip(spill.axis_chunks_iter_mut(Axis(0), BLOCK_ROWS))
            .collect();
        blocks.into_par_iter().enumerate().for_each_init(
            || (vec![0.0f64; BLOCK_ROWS * dim], vec![0.0f64; BLOCK_ROWS * TILE]),
            |(lhs, prod), (b, (mut out, mut spill))| {
                let row0 = first_row + b * BLOCK_ROWS;
                let rows = out.nrows();
                for (r, unit) in lhs.chunks_mut(dim).enumerate() {
                    if r < rows {
                        db.unit(row0 + r, unit);
                    } else {
                        unit.fill(0.0);
                    }
                }
                let lhs = MatRef::from_row_major_slice(lhs, BLOCK_ROWS, dim);
                for t in 0..tiles.len() {
                    let dst = MatMut::from_row_major_slice_mut(prod, BLOCK_ROWS, TILE);
                    matmul(dst, Accum::Replace, lhs, tiles.rhs(t), 1.0, Par::Seq);
                    let q0 = (tiles.first + t) * TILE;
                    let prod = ArrayView2::from_shape((BLOCK_ROWS, TILE), &prod[..]).expect("a block of the tile");
                    // The tile's columns that are asked for, as output columns, and
                    // those kept for later.
                    for (to, from) in [(&mut out, cols.start..mid), (&mut spill, mid..cols.end)] {
                        let (lo, hi) = (q0.max(from.start), (q0 + TILE).min(from.end));
                        if lo < hi {
                            Zip::from(to.slice_mut(s![.., lo - from.start..hi - from.start]))
                                .and(prod.slice(s![..rows, lo - q0..hi - q0]))
                                .for_each(|o, &p| *o = p as f32);
                        }
                    }
                }
            },
        );
    })
}

/// Database and query descriptors, checked once, from which the similarity of any range
/// of queries is computed on demand. As a [`ScoreSource::Descriptors`] (a range of its
/// queries) it stands in for a similarity matrix wherever one is read: the fused
/// transfer ([`Calibration::transfer`]) never holds it whole. The descriptors are not
/// copied (the views may be memory-mapped files); what is kept beside them is two `f64`
/// factors per row (16 MB per million descriptors).
///
/// Columns are computed in tiles aligned at query 0 of `queries` (see the
/// module docs of `extensions/similarity.rs`), so `similarity(a..b)` is exactly columns `a..b` of
/// [`cosine_similarity`]`(db, queries)`, whatever `a` and `b`.
///
/// [`ScoreSource::Descriptors`]: crate::ScoreSource::Descriptors
/// [`Calibration::transfer`]: crate::Calibration::transfer
#[derive(Debug, Clone)]
pub struct Descriptors<'a> {
    db: ScoresView<'a>,
    queries: ScoresView<'a>,
    db_scales: Vec<RowScale>,
    q_scales: Vec<RowScale>,
}

impl<'a> Descriptors<'a> {
    /// Check `db` (|DB| x D) and `queries` (|Q| x D), `f32` or `f64`, any strides, in one
    /// pass over each.
    ///
    /// # Errors
    /// As [`cosine_similarity`]: empty, different dimensions, a NaN or infinite value, an
    /// all-zero row; errors in `db` before errors in `queries`.
    pub fn new(db: impl Into<ScoresView<'a>>, queries: impl Into<ScoresView<'a>>) -> Result<Self> {
        let (db, queries) = (db.into(), queries.into());
        let (db_scales, q_scales) = with_scores!(db, |d| with_scores!(queries, |q| scales(d, q)))?;
        Ok(Self {
            db,
            queries,
            db_scales,
            q_scales,
        })
    }

    /// The database descriptors, |DB| x D.
    pub fn db(&self) -> ScoresView<'a> {
        self.db
    }

    /// The query descriptors, |Q| x D.
    pub fn queries(&self) -> ScoresView<'a> {
        self.queries
    }

    /// The shape of their similarity matrix: (|DB|, |Q|).
    pub fn shape(&self) -> (usize, usize) {
        (self.db.dim().0, self.queries.dim().0)
    }

    /// Columns `queries` of the similarity: |DB| x `queries.len()`, `f32`, C order,
    /// equal bit for bit to those columns of [`cosine_similarity`]. With a progress
    /// callback ([`Options::progress`]), `progress(done, total)` is called after each
    /// step of database rows: `done` of the `total` = |DB| rows are finished.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a range that is empty or not within 0..|Q|.
    pub fn similarity<'p>(&self, queries: impl Into<Options<'p, Range<usize>>>) -> Result<Array2<f32>> {
        let options = queries.into();
        let queries = options.params.clone();
        self.check_range(&queries)?;
        let step = step_rows(queries.len());
        Ok(with_scores!(self.db, |d| with_scores!(self.queries, |q| {
            similarity_in_steps(
                Rows::new(d, &self.db_scales),
                Rows::new(q, &self.q_scales),
                queries.clone(),
                step,
                |done, total| options.report(done, total),
            )
        })))
    }

    /// Check that `r` is a non-empty range of queries.
    pub(crate) fn check_range(&self, r: &Range<usize>) -> Result<()> {
        let n_q = self.shape().1;
        if r.is_empty() || r.end > n_q {
            return Err(Error::param(
                "queries",
                format!(
                    "must be a non-empty range of the {n_q} query descriptors, got {}..{}",
                    r.start, r.end
                ),
            ));
        }
        Ok(())
    }

    /// Columns `cols` into `dst` (|DB| x its columns, any layout), then the columns after
    /// them into `spill` (|DB| x its columns, any layout).
    fn fill_columns(&self, cols: Range<usize>, dst: ArrayViewMut2<'_, f32>, spill: ArrayViewMut2<'_, f32>) {
        with_scores!(self.db, |d| with_scores!(self.queries, |q| {
            fill(
                Rows::new(d, &self.db_scales),
                0,
                &QueryTiles::new(Rows::new(q, &self.q_scales), cols),
                dst,
                spill,
            )
        }));
    }
}

/// The columns of a range of queries of [`Descriptors`], computed as a transfer asks for
/// them, chunk after chunk from left to right, straight into the caller's buffer. The
/// columns of the last tile computed that the chunk did not ask for are kept (fewer than
/// [`TILE`]) and handed to the next chunk, so each tile is computed once and nothing but
/// those columns is held beside the chunk.
pub(crate) struct DescriptorColumns<'d, 'a> {
    descriptors: &'d Descriptors<'a>,
    /// The first query of the range (chunks count from it).
    offset: usize,
    /// Column-major |DB| x (end - start): the kept columns, of queries `start..end`.
    kept: Vec<f32>,
    start: usize,
    end: usize,
}

impl<'d, 'a> DescriptorColumns<'d, 'a> {
    /// The columns of queries `offset..`.
    pub(crate) fn new(descriptors: &'d Descriptors<'a>, offset: usize) -> Self {
        Self {
            descriptors,
            offset,
            kept: Vec::new(),
            start: offset,
            end: offset,
        }
    }

    /// Columns `r` (counted from the offset) into `dst`, |DB| x `r.len()`, any layout.
    pub(crate) fn fill(&mut self, r: Range<usize>, mut dst: ArrayViewMut2<'_, f32>) {
        let (n_db, n_q) = self.descriptors.shape();
        let (a, b) = (self.offset + r.start, self.offset + r.end);
        debug_assert_eq!(dst.dim(), (n_db, r.len()));
        if a != self.start {
            // Not the next chunk: what was kept is of no use.
            self.kept.clear();
            (self.start, self.end) = (a, a);
        }
        let from_kept = self.end.min(b) - a;
        let kept = ArrayView2::from_shape((n_db, self.end - self.start).f(), &self.kept[..])
            .expect("kept columns are |DB| long");
        dst.slice_mut(s![.., ..from_kept])
            .assign(&kept.slice(s![.., ..from_kept]));
        if b <= self.end {
            self.kept.drain(..from_kept * n_db);
            self.start = b;
            return;
        }
        let end = (b.div_ceil(TILE) * TILE).min(n_q);
        self.kept.clear();
        self.kept.resize((end - b) * n_db, 0.0);
        let spill = ArrayViewMut2::from_shape((n_db, end - b).f(), &mut self.kept[..]).expect("room for the spill");
        self.descriptors
            .fill_columns(self.end..end, dst.slice_mut(s![.., from_kept..]), spill);
        (self.start, self.end) = (b, end);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    /// [`similarity_in_steps`] of unchecked descriptors.
    fn in_steps(
        db: ArrayView2<'_, f32>,
        q: ArrayView2<'_, f32>,
        cols: Range<usize>,
        step: usize,
        progress: impl Fn(usize, usize),
    ) -> Array2<f32> {
        let (db_scales, q_scales) = scales(db, q).unwrap();
        similarity_in_steps(Rows::new(db, &db_scales), Rows::new(q, &q_scales), cols, step, progress)
    }

    fn close(a: f32, b: f64) -> bool {
        (f64::from(a) - b).abs() < 1e-7
    }

    /// `rows` x `dim` values in [-0.5, 0.5) from a fixed LCG.
    fn lcg(rows: usize, dim: usize, seed: u64) -> Array2<f32> {
        let mut x = seed;
        Array2::from_shape_simple_fn((rows, dim), || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 40) as f32) / (1u64 << 24) as f32 - 0.5
        })
    }

    #[test]
    fn hand_computed_cosines() {
        // db rows (3, 4) and (1, 0); query rows (4, 3), (0, 2), (-1, 0).
        // |(3,4)| = 5: with (4,3) -> 24/25 = 0.96, with (0,2) -> 8/10 = 0.8,
        // with (-1,0) -> -3/5 = -0.6. (1,0): 4/5 = 0.8, 0, -1.
        let db = array![[3.0f32, 4.0], [1.0, 0.0]];
        let q = array![[4.0f64, 3.0], [0.0, 2.0], [-1.0, 0.0]];
        let s = cosine_similarity(db.view(), q.view()).unwrap();
        let want = [[0.96, 0.8, -0.6], [0.8, 0.0, -1.0]];
        assert_eq!(s.dim(), (2, 3));
        for i in 0..2 {
            for j in 0..3 {
                assert!(close(s[[i, j]], want[i][j]), "{s}");
            }
        }
        assert!(s.is_standard_layout());
        let d = Descriptors::new(db.view(), q.view()).unwrap();
        assert_eq!(d.shape(), (2, 3));
        assert_eq!(d.similarity(1..3).unwrap(), s.slice(ndarray::s![.., 1..3]));
    }

    #[test]
    fn powers_of_two_bring_the_largest_value_into_1_2() {
        // 3 in [2, 4): 1/2, 3/2 = 1.5. 0.3 in [1/4, 1/2): 4, 1.2. 1: 1.
        assert_eq!(inverse_power_of_two(3.0), 0.5);
        assert_eq!(inverse_power_of_two(0.3), 4.0);
        assert_eq!(inverse_power_of_two(1.0), 1.0);
        // The extremes: f64::MAX in [2^1023, 2^1024) takes the subnormal 2^-1023 and
        // lands in [1, 2); the smallest normal 2^-1022 takes 2^1022 and lands on 1; the
        // smallest subnormal 2^-1074 takes 2^1022 too and lands on 2^-52.
        let max = inverse_power_of_two(f64::MAX);
        assert_eq!(max, 2f64.powi(-1023));
        assert!((1.0..2.0).contains(&(f64::MAX * max)));
        assert_eq!(inverse_power_of_two(f64::MIN_POSITIVE), 2f64.powi(1022));
        assert_eq!(f64::MIN_POSITIVE * 2f64.powi(1022), 1.0);
        assert_eq!(
            inverse_power_of_two(f64::from_bits(1)) * f64::from_bits(1),
            2f64.powi(-52)
        );
    }

    #[test]
    fn any_strides_and_scale_invariance() {
        // db is the transposed view of [[1, 3, 5], [2, 4, 6]]: rows (1,2), (3,4), (5,6).
        // Scaling a row by 1e200 or 1e-200 leaves its cosine unchanged:
        // (1,2).(3,4) / (sqrt 5 sqrt 25) = 11 / (5 sqrt 5) = 0.9838699100999074.
        let stored = array![[1.0f64, 3.0, 5.0], [2.0, 4.0, 6.0]];
        let db = stored.t();
        let q = array![[3e200, 4e200], [3e-200, 4e-200]];
        let s = cosine_similarity(db, q.view()).unwrap();
        assert!(close(s[[0, 0]], 11.0 / (5.0 * 5f64.sqrt())), "{s}");
        assert_eq!(s[[0, 0]], s[[0, 1]]);
        // (5,6).(3,4) = 39, |(5,6)| = sqrt 61: 39 / (5 sqrt 61) = 0.9986876634765226.
        assert!(close(s[[2, 1]], 39.0 / (5.0 * 61f64.sqrt())), "{s}");
    }

    #[test]
    fn ranges_steps_and_chunks_give_the_same_bits() {
        // 600 database rows = blocks of 256, 256 and 88; 150 queries = tiles of 64, 64
        // and 22. However the columns are asked for, each score comes from the same GEMM
        // call on the same operands, so the bits are those of the whole matrix.
        let (db, q) = (lcg(600, 7, 1), lcg(150, 7, 2));
        let full = cosine_similarity(db.view(), q.view()).unwrap();
        // The cosines are not trivial: they spread over most of [-1, 1].
        assert!(full.iter().any(|&v| v > 0.8) && full.iter().any(|&v| v < -0.8));
        let d = Descriptors::new(db.view(), q.view()).unwrap();
        for r in [0..150, 10..20, 60..70, 63..129, 64..128, 149..150] {
            assert_eq!(
                d.similarity(r.clone()).unwrap(),
                full.slice(ndarray::s![.., r.clone()]),
                "{r:?}"
            );
        }
        for step in [256, 512, 1024] {
            assert_eq!(in_steps(db.view(), q.view(), 0..150, step, |_, _| ()), full);
        }
        // Chunks of a transfer over queries 10..150, left to right, into buffers of
        // either order: chunks within the kept columns of the last tile (0..3, 3..5),
        // across them and into new tiles, a jump back (which drops what was kept).
        let mut columns = DescriptorColumns::new(&d, 10);
        for (i, r) in [0..3, 3..5, 5..60, 60..61, 61..62, 62..140, 20..30, 30..31]
            .into_iter()
            .enumerate()
        {
            let (a, b) = (r.start + 10, r.end + 10);
            let mut got = if i % 2 == 0 {
                Array2::from_elem((600, r.len()), f32::NAN)
            } else {
                Array2::from_elem((600, r.len()).f(), f32::NAN)
            };
            columns.fill(r, got.view_mut());
            assert_eq!(got, full.slice(ndarray::s![.., a..b]), "{a}..{b}");
            assert!(columns.kept.len() < TILE * 600, "fewer than a tile kept");
        }
    }

    #[test]
    fn a_column_of_a_product_has_the_same_bits_in_tiles_of_16_and_64() {
        // The kernel's tiles were 64 queries wide and are now 16: faer gives each column
        // the same bits whatever the width of the call (for widths of 2 and more), so
        // the similarity did not change with the width. Pinned here for faer's updates.
        let mut x = 5u64;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for dim in [64, 512, 2048] {
            let lhs: Vec<f64> = (0..BLOCK_ROWS * dim).map(|_| next()).collect();
            let rhs: Vec<f64> = (0..64 * dim).map(|_| next()).collect();
            let product = |cols: Range<usize>| {
                let mut out = vec![0.0; BLOCK_ROWS * cols.len()];
                matmul(
                    MatMut::from_row_major_slice_mut(&mut out, BLOCK_ROWS, cols.len()),
                    Accum::Replace,
                    MatRef::from_row_major_slice(&lhs, BLOCK_ROWS, dim),
                    MatRef::from_row_major_slice(&rhs[cols.start * dim..cols.end * dim], cols.len(), dim).transpose(),
                    1.0,
                    Par::Seq,
                );
                Array2::from_shape_vec((BLOCK_ROWS, cols.len()), out).unwrap()
            };
            let wide = product(0..64);
            for t in 0..4 {
                let narrow = product(t * 16..(t + 1) * 16);
                let bits = |a: ArrayView2<'_, f64>| a.mapv(f64::to_bits);
                assert_eq!(
                    bits(narrow.view()),
                    bits(wide.slice(s![.., t * 16..(t + 1) * 16])),
                    "D {dim}"
                );
            }
        }
    }

    #[test]
    fn progress_after_each_step_of_rows() {
        // 600 database rows in steps of 256: rows 0..256, 256..512, 512..600, reported as
        // 256, 512 and 600 of 600 done.
        let (db, q) = (lcg(600, 3, 3), lcg(5, 3, 4));
        let calls = std::cell::RefCell::new(vec![]);
        let s = in_steps(db.view(), q.view(), 0..5, 256, |done, total| {
            calls.borrow_mut().push((done, total))
        });
        assert_eq!(s, cosine_similarity(db.view(), q.view()).unwrap());
        assert_eq!(calls.into_inner(), [(256, 600), (512, 600), (600, 600)]);
        // The public one: steps of 2^22 / 5 scores, rounded down to whole blocks of 256
        // rows (3276 blocks): one step of all 600 rows.
        let calls = std::cell::RefCell::new(vec![]);
        let record = |d, t| calls.borrow_mut().push((d, t));
        let d = Descriptors::new(db.view(), q.view()).unwrap();
        d.similarity(Options::new(0..5).progress(&record)).unwrap();
        assert_eq!(calls.take(), [(600, 600)]);
        // A rejected range: no call.
        assert!(d.similarity(Options::new(0..6).progress(&record)).is_err());
        assert_eq!(calls.take(), []);
    }

    #[test]
    fn bad_descriptors() {
        let good = array![[1.0f32, 0.0], [0.0, 1.0]];
        let err = cosine_similarity(good.view(), array![[1.0f32, 0.0, 0.0]].view()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "query descriptor matrix has 3 columns but database descriptor matrix has 2; both must have the same dimension"
        );
        let zero = array![[1.0, 2.0], [0.0, 0.0], [0.0, -0.0]];
        let err = cosine_similarity(zero.view(), good.view()).unwrap_err();
        assert_eq!(
            err,
            Error::ZeroNorm {
                what: Input::DbDescriptors,
                row: 1
            }
        );
        assert_eq!(
            err.to_string(),
            "database descriptor matrix row 1 is all zeros; the cosine similarity of a zero vector is undefined"
        );
        let nan = array![[1.0f32, 2.0], [0.0, 0.0], [3.0, f32::NAN]];
        let err = cosine_similarity(good.view(), nan.view()).unwrap_err();
        // Row 1 is zero, but row order decides: it is reported first.
        assert_eq!(
            err.to_string().split(';').next(),
            Some("query descriptor matrix row 1 is all zeros")
        );
        // Database errors come first, whatever the queries hold.
        assert_eq!(
            Descriptors::new(zero.view(), nan.view()).unwrap_err(),
            Error::ZeroNorm {
                what: Input::DbDescriptors,
                row: 1
            }
        );
        let inf = array![[1.0f32, f32::NEG_INFINITY]];
        assert_eq!(
            cosine_similarity(good.view(), inf.view()).unwrap_err().to_string(),
            "query descriptor matrix contains -inf at row 0, column 1; every value must be finite"
        );
        let empty = Array2::<f64>::zeros((0, 2));
        assert_eq!(
            cosine_similarity(empty.view(), good.view()).unwrap_err().to_string(),
            "database descriptor matrix is empty (shape 0x2)"
        );
        let no_dims = Array2::<f64>::zeros((2, 0));
        assert!(matches!(
            cosine_similarity(good.view(), no_dims.view()),
            Err(Error::Empty { .. })
        ));
        let d = Descriptors::new(good.view(), good.view()).unwrap();
        for r in [1..1, 1..3] {
            assert_eq!(
                d.similarity(r.clone()).unwrap_err().to_string(),
                format!(
                    "queries must be a non-empty range of the 2 query descriptors, got {}..{}",
                    r.start, r.end
                )
            );
        }
    }
}
