//! The deployment scores a transfer reads, a chunk of columns at a time: from a matrix
//! (random access) or from descriptors, whose columns are computed where they are
//! sorted, left to right, so that the |DB| x |Qval| similarity never exists. At the
//! bottom of the operations: it knows ranked profiles and descriptors, nothing of a
//! transfer.

use std::ops::Range;

use ndarray::{ArrayView1, ArrayView2, ArrayViewMut2, ShapeBuilder};

use crate::error::Result;
use crate::error::names::Input;
use crate::extensions::similarity::DescriptorColumns;
use crate::input::Score;
use crate::rules::decisions::best_match;
use crate::rules::ranked_correlation::Ranked;

/// Deployment scores per chunk (32 MB of f64 working memory).
pub(crate) const CHUNK_SCORES: usize = 1 << 22;

/// Where a transfer reads its deployment scores: a matrix (random access), or
/// descriptors whose columns are computed chunk by chunk, left to right.
pub(crate) trait Chunks {
    /// The score type.
    type T: Score;
    /// (|DB|, |Qval|).
    fn dim(&self) -> (usize, usize);
    /// Every score, when the source holds them (a matrix): a source without it is read
    /// only in consecutive chunks.
    fn whole(&self) -> Option<ArrayView2<'_, Self::T>>;
    /// Gather, check, sort and standardise the scores of deployment queries `r` into
    /// `ranked`; with `best`, also write each query's best match (semantics §2: the
    /// first maximum of its column) there, before its column is sorted.
    fn rank(&mut self, ranked: &mut Ranked<Self::T>, r: Range<usize>, best: Option<&mut [usize]>) -> Result<()>;
}

/// The best match of each column of a column-major |DB| x n buffer, into `best`.
fn best_of_columns<T: Score>(n_db: usize, scores: &[T], best: &mut [usize]) {
    for (b, column) in best.iter_mut().zip(scores.chunks_exact(n_db)) {
        *b = best_match(ArrayView1::from(column));
    }
}

impl<T: Score> Chunks for ArrayView2<'_, T> {
    type T = T;
    fn dim(&self) -> (usize, usize) {
        ArrayView2::dim(self)
    }
    fn whole(&self) -> Option<ArrayView2<'_, T>> {
        Some(self.view())
    }
    fn rank(&mut self, ranked: &mut Ranked<T>, r: Range<usize>, best: Option<&mut [usize]>) -> Result<()> {
        let first = r.start;
        let columns = self.slice(ndarray::s![.., r]);
        ranked.refill(Input::DeploymentSimilarity, columns, first)?;
        if let Some(best) = best {
            for (b, column) in best.iter_mut().zip(columns.columns()) {
                *b = best_match(column);
            }
        }
        Ok(())
    }
}

/// The deployment similarity of a range of query descriptors.
pub(crate) struct Fused<'d, 'a> {
    pub(crate) columns: DescriptorColumns<'d, 'a>,
    /// (|DB|, the number of queries).
    pub(crate) dim: (usize, usize),
}

impl Chunks for Fused<'_, '_> {
    type T = f32;
    fn dim(&self) -> (usize, usize) {
        self.dim
    }
    fn whole(&self) -> Option<ArrayView2<'_, f32>> {
        None
    }
    fn rank(&mut self, ranked: &mut Ranked<f32>, r: Range<usize>, best: Option<&mut [usize]>) -> Result<()> {
        // Computed where they are sorted: the chunk is never copied.
        let shape = (self.dim.0, r.len());
        ranked.refill_with(Input::DeploymentSimilarity, shape, r.start, |out| {
            self.columns.fill(r, column_major(shape, &mut *out));
            if let Some(best) = best {
                best_of_columns(shape.0, out, best);
            }
        })
    }
}

/// A column-major `shape` view of `out`.
pub(crate) fn column_major(shape: (usize, usize), out: &mut [f32]) -> ArrayViewMut2<'_, f32> {
    ArrayViewMut2::from_shape(shape.f(), out).expect("a buffer of the shape")
}
