//! Extension (not a section of the semantics): the similarity matrix from image descriptors.
//!
//! Researchers usually hold descriptors, not a similarity matrix: one row per image, e.g.
//! the `database_descriptors.npy` / `queries_descriptors.npy` that VPR-methods-evaluation
//! writes. [`cosine_similarity`] turns them into the |DB| x |Q| matrix the rest of the
//! crate takes: `S[i, j]` is the cosine of database row `i` and query row `j`, i.e. the
//! dot product of the L2-normalised rows, `normalize(db) @ normalize(q).T` in NumPy.
//!
//! # Arithmetic: f64, rounded once to f32
//! The rows are normalised into `f64` copies and multiplied by faer's parallel GEMM in
//! `f64`; each result is rounded once to `f32`, the type of the output. Why `f64`, when
//! an `f32` GEMM would be about twice as fast:
//! - semantics §1 does all arithmetic on scores in `f64`; the matrix made here is the
//!   input of that pipeline, and ties or near-ties in it decide best matches.
//! - The rounding error of an `f32` dot product grows with the descriptor dimension D
//!   (about `sqrt(D) * 6e-8` for unit vectors): harmless for D = 756, but at D = 4096 to
//!   32768 (NetVLAD, SALAD, BoQ) it approaches the 1e-5 this project promises against
//!   NumPy. In `f64` the result is the correctly rounded `f32` cosine up to ~1e-15,
//!   whatever D, whatever the input type, and whatever the thread count.
//! - Normalising needs a copy of the descriptors anyway (NumPy's `normalize` makes one
//!   too), so widening while copying costs no extra pass; the copy is |DB|·D + |Q|·D,
//!   small next to the |DB|·|Q|·D product.
//!
//! The product runs in blocks of database rows, so the `f64` scratch stays at 32 MB
//! whatever the size of the `f32` result.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use ndarray::{Array2, ArrayView1, ArrayView2};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::input::{Score, check_nonempty};
use crate::names::{DB_DESCRIPTORS, QUERY_DESCRIPTORS};

/// `f64` elements of the scratch block of the product (32 MB).
const BLOCK_ELEMENTS: usize = 1 << 22;

/// Cosine similarity of every database descriptor with every query descriptor.
///
/// `db` is |DB| x D and `queries` |Q| x D, one descriptor per row, `f32` or `f64`, any
/// strides (a C- or Fortran-order array, a slice, a transposed view). The result is
/// |DB| x |Q| (`S[i, j]` = cosine of `db` row `i` and `queries` row `j`), in `f32`, in
/// standard (C) order. See the [module docs](self) for why the arithmetic is `f64`.
///
/// # Errors
/// - [`Error::Empty`] when either matrix has no rows or no columns;
/// - [`Error::ColumnMismatch`] when the descriptor dimensions differ;
/// - [`Error::NotFiniteValue`] for a NaN or infinite value (the first by row, then column);
/// - [`Error::ZeroNorm`] for an all-zero row, whose cosine is undefined.
///
/// Errors in `db` are reported before errors in `queries`.
pub fn cosine_similarity<T: Score, U: Score>(db: ArrayView2<'_, T>, queries: ArrayView2<'_, U>) -> Result<Array2<f32>> {
    cosine_in_blocks(db, queries, BLOCK_ELEMENTS, |_, _| ())
}

/// [`cosine_similarity`], calling `progress(done, total)` after each block of database
/// rows: `done` of the `total` = |DB| rows of the result are finished (for a progress
/// bar; called from the calling thread, not at all when the input is rejected).
///
/// # Errors
/// As [`cosine_similarity`].
pub fn cosine_similarity_with_progress<T: Score, U: Score>(
    db: ArrayView2<'_, T>,
    queries: ArrayView2<'_, U>,
    progress: impl Fn(usize, usize),
) -> Result<Array2<f32>> {
    cosine_in_blocks(db, queries, BLOCK_ELEMENTS, progress)
}

/// [`cosine_similarity_with_progress`] with a scratch of `block_elements` (at least one row).
fn cosine_in_blocks<T: Score, U: Score>(
    db: ArrayView2<'_, T>,
    queries: ArrayView2<'_, U>,
    block_elements: usize,
    progress: impl Fn(usize, usize),
) -> Result<Array2<f32>> {
    check_nonempty(DB_DESCRIPTORS, db.dim())?;
    check_nonempty(QUERY_DESCRIPTORS, queries.dim())?;
    if queries.ncols() != db.ncols() {
        return Err(Error::ColumnMismatch {
            what: QUERY_DESCRIPTORS,
            cols: queries.ncols(),
            other: DB_DESCRIPTORS,
            other_cols: db.ncols(),
        });
    }
    let dim = db.ncols();
    let db_unit = unit_rows(DB_DESCRIPTORS, db)?;
    let q_unit = unit_rows(QUERY_DESCRIPTORS, queries)?;
    let (n_db, n_q) = (db.nrows(), queries.nrows());
    let q_mat = MatRef::from_row_major_slice(&q_unit, n_q, dim);

    // Row-major |DB| x |Q|, filled one block of database rows at a time.
    let mut out = vec![0.0f32; n_db * n_q];
    let block_rows = (block_elements / n_q).clamp(1, n_db);
    let mut scratch = vec![0.0f64; block_rows * n_q];
    for (b, out_block) in out.chunks_mut(block_rows * n_q).enumerate() {
        let rows = out_block.len() / n_q;
        let first = b * block_rows;
        let lhs = MatRef::from_row_major_slice(&db_unit[first * dim..(first + rows) * dim], rows, dim);
        let scratch = &mut scratch[..rows * n_q];
        let dst = MatMut::from_row_major_slice_mut(scratch, rows, n_q);
        matmul(dst, Accum::Replace, lhs, q_mat.transpose(), 1.0, Par::rayon(0));
        out_block
            .par_chunks_mut(n_q)
            .zip(scratch.par_chunks(n_q))
            .for_each(|(o, s)| o.iter_mut().zip(s).for_each(|(o, &s)| *o = s as f32));
        progress(first + rows, n_db);
    }
    Ok(Array2::from_shape_vec((n_db, n_q), out).expect("shape matches length"))
}

/// The rows of `m`, each scaled to unit L2 norm, widened to `f64`, row-major.
fn unit_rows<T: Score>(what: &'static str, m: ArrayView2<'_, T>) -> Result<Vec<f64>> {
    let dim = m.ncols();
    let mut unit = vec![0.0; m.nrows() * dim];
    let errors: Vec<Option<Error>> = unit
        .par_chunks_mut(dim)
        .enumerate()
        .map(|(row, out)| unit_row(what, row, m.row(row), out).err())
        .collect();
    match errors.into_iter().flatten().next() {
        Some(err) => Err(err),
        None => Ok(unit),
    }
}

/// Write `x / |x|` into `out`. The norm is taken of `x / max|x|`, so that squares
/// neither overflow nor underflow whatever the magnitude of the descriptor.
fn unit_row<T: Score>(what: &'static str, row: usize, x: ArrayView1<'_, T>, out: &mut [f64]) -> Result<()> {
    let mut scale = 0.0f64;
    for (col, v) in x.iter().enumerate() {
        let v = v.to_f64();
        if !v.is_finite() {
            return Err(Error::NotFiniteValue {
                what,
                row,
                col,
                value: v,
            });
        }
        scale = scale.max(v.abs());
    }
    if scale == 0.0 {
        return Err(Error::ZeroNorm { what, row });
    }
    for (o, v) in out.iter_mut().zip(x.iter()) {
        *o = v.to_f64() / scale;
    }
    let norm = out.iter().map(|v| v * v).sum::<f64>().sqrt();
    out.iter_mut().for_each(|o| *o /= norm);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    fn close(a: f32, b: f64) -> bool {
        (f64::from(a) - b).abs() < 1e-7
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
    fn blocks_of_rows_give_the_same_result() {
        // 1-D descriptors: every cosine is the product of the signs. Blocks of 1, 2 and
        // 3 database rows (the last block shorter) must all give the same matrix.
        let db = array![[2.0f32], [-0.5], [7.0], [-1.0], [3.0]];
        let q = array![[1.0f64], [-3.0], [0.25]];
        let want = array![
            [1.0f32, -1.0, 1.0],
            [-1.0, 1.0, -1.0],
            [1.0, -1.0, 1.0],
            [-1.0, 1.0, -1.0],
            [1.0, -1.0, 1.0]
        ];
        for block in [1, 3, 6, 9, 100] {
            assert_eq!(
                cosine_in_blocks(db.view(), q.view(), block, |_, _| ()).unwrap(),
                want,
                "{block}"
            );
        }
    }

    #[test]
    fn progress_after_each_block_of_rows() {
        // 5 database rows, 3 queries: a scratch of 6 elements holds 6 / 3 = 2 rows, so
        // blocks of rows 0..2, 2..4, 4..5, reported as 2, 4 and 5 of 5 done.
        let db = array![[2.0f32], [-0.5], [7.0], [-1.0], [3.0]];
        let q = array![[1.0f64], [-3.0], [0.25]];
        let calls = std::cell::RefCell::new(vec![]);
        let s = cosine_in_blocks(db.view(), q.view(), 6, |done, total| {
            calls.borrow_mut().push((done, total))
        });
        assert_eq!(s.unwrap(), cosine_similarity(db.view(), q.view()).unwrap());
        assert_eq!(calls.into_inner(), [(2, 5), (4, 5), (5, 5)]);
        // The public one: one block of all 5 rows (the scratch holds 2^22 elements).
        let calls = std::cell::RefCell::new(vec![]);
        cosine_similarity_with_progress(db.view(), q.view(), |d, t| calls.borrow_mut().push((d, t))).unwrap();
        assert_eq!(calls.into_inner(), [(5, 5)]);
        // Rejected input: no call.
        let calls = std::cell::Cell::new(0);
        let zero = array![[0.0f32]];
        assert!(cosine_similarity_with_progress(zero.view(), q.view(), |_, _| calls.set(calls.get() + 1)).is_err());
        assert_eq!(calls.get(), 0);
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
                what: DB_DESCRIPTORS,
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
    }
}
