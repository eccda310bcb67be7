//! The similarity an operation reads, and the options every operation shares.
//!
//! A [`ScoreSource`] is either a similarity matrix (|DB| x |Q|, any strides, `f32` or
//! `f64`) or the cosine similarity of database and query descriptors for a range of
//! queries, which is computed when it is needed (see [`crate::extensions::similarity`]). Every
//! operation that reads similarity scores takes one: [`Calibration::new`],
//! [`Calibration::transfer`], [`evaluate`](crate::operations::evaluate()) and
//! [`ablation`](crate::ablation()). A front end converts its input into a source once
//! and never dispatches on matrices and descriptors itself.
//!
//! Beside it, every such operation takes [`Options`](crate::Options): its parameters with an optional
//! progress callback, `cal.transfer(s, &params)` for none,
//! `cal.transfer(s, Options::new(params).progress(&bar))` for a progress bar.
//!
//! [`Calibration::new`]: crate::Calibration::new
//! [`Calibration::transfer`]: crate::Calibration::transfer

use std::ops::Range;

use ndarray::{Array2, ArrayView2, s};

use crate::error::Result;
use crate::extensions::similarity::Descriptors;
use crate::input::{Score, ScoresView};

/// The similarity scores an operation reads.
///
/// ```
/// use ndarray::array;
/// use qtvpr::{Descriptors, ScoreSource};
///
/// // A matrix, or its transpose for a query-major one.
/// let s = array![[0.9f32, 0.2, 0.4], [0.1, 0.8, 0.3]];
/// assert_eq!(ScoreSource::from(s.view()).dim(), (2, 3));
/// assert_eq!(ScoreSource::from(s.t()).dim(), (3, 2));
/// // Queries 1..3 of descriptors: their similarity is 2 x 2, never computed here.
/// let (db, q) = (array![[1.0f32, 0.0], [0.0, 1.0]], array![[1.0f32, 1.0], [1.0, 0.0], [0.0, 2.0]]);
/// let d = Descriptors::new(db.view(), q.view())?;
/// let source = ScoreSource::Descriptors(&d, 1..3);
/// assert_eq!(source.dim(), (2, 2));
/// assert_eq!(source.columns(1..2).dim(), (2, 1));
/// # Ok::<(), qtvpr::Error>(())
/// ```
#[derive(Debug, Clone)]
pub enum ScoreSource<'a, 'd> {
    /// A |DB| x |Q| similarity matrix (pass `.t()` of a query-major one).
    Matrix(ScoresView<'a>),
    /// Columns `queries` of the cosine similarity of descriptors: bit for bit the
    /// columns of [`cosine_similarity`](crate::cosine_similarity). A transfer computes
    /// them chunk by chunk and never holds them whole; an operation that needs every
    /// score at once (a calibration, an evaluation) computes them in memory. A range
    /// that is empty or beyond |Q| is refused by the operation
    /// ([`Error::InvalidParameter`](crate::Error::InvalidParameter) `queries`).
    Descriptors(&'a Descriptors<'d>, Range<usize>),
}

impl ScoreSource<'_, '_> {
    /// (|DB|, |Q|) of the similarity: of the matrix, or of the range of queries.
    pub fn dim(&self) -> (usize, usize) {
        match self {
            ScoreSource::Matrix(s) => s.dim(),
            ScoreSource::Descriptors(d, r) => (d.shape().0, r.len()),
        }
    }

    /// Columns `r` of this source (counted from its first column) as a source: a view
    /// of a matrix, a narrower range of descriptors. This is how a split of one set of
    /// queries ([`QuerySplit`](crate::QuerySplit)) becomes its calibration and its
    /// deployment scores.
    ///
    /// # Panics
    /// When `r` is not within `0..self.dim().1`, as slicing does.
    #[must_use]
    pub fn columns(&self, r: Range<usize>) -> Self {
        let n = self.dim().1;
        assert!(
            r.start <= r.end && r.end <= n,
            "columns {r:?} of a source of {n} columns"
        );
        match self {
            ScoreSource::Matrix(v) => ScoreSource::Matrix(with_scores!(*v, |v| v.slice_move(s![.., r]).into())),
            ScoreSource::Descriptors(d, q) => ScoreSource::Descriptors(d, q.start + r.start..q.start + r.end),
        }
    }

    /// Run `f` on every score of the source at once: the matrix itself, or the
    /// similarity of the descriptors computed in memory (checked range first).
    pub(crate) fn with_matrix<R>(&self, f: impl FnOnce(ScoresView<'_>) -> Result<R>) -> Result<R> {
        match self {
            ScoreSource::Matrix(v) => f(*v),
            ScoreSource::Descriptors(d, r) => {
                let s: Array2<f32> = d.similarity(r.clone())?;
                f(s.view().into())
            }
        }
    }
}

impl<'a, T: Score> From<ArrayView2<'a, T>> for ScoreSource<'a, '_> {
    fn from(v: ArrayView2<'a, T>) -> Self {
        ScoreSource::Matrix(T::view(v))
    }
}

impl<'a> From<ScoresView<'a>> for ScoreSource<'a, '_> {
    fn from(v: ScoresView<'a>) -> Self {
        ScoreSource::Matrix(v)
    }
}

impl<'a, 'd> From<&'a Descriptors<'d>> for ScoreSource<'a, 'd> {
    /// Every query of the descriptors.
    fn from(d: &'a Descriptors<'d>) -> Self {
        ScoreSource::Descriptors(d, 0..d.shape().1)
    }
}
