//! semantics §1: scores, ground truth and their validation.
//!
//! Scores are read where they lie (any [`ArrayView2`], any strides) as `f32` or `f64`
//! and widened to `f64` value by value; nothing is copied up front. Ground truth is
//! turned once into a compact [`Truth`] matrix, because every later step asks the same
//! three-way question of it: true, false, or ignored.

use ndarray::{Array2, ArrayView2, Zip};
use rayon::prelude::*;

use crate::error::names::Input;
use crate::error::{Error, Result, try_reserve};
use crate::platform::threads;

mod sealed {
    pub trait Sealed {}
}

/// A similarity score type: `f32` or `f64`. Every result is computed in `f64`.
pub trait Score: Copy + Default + Send + Sync + PartialOrd + sealed::Sealed + 'static {
    /// The NumPy name of the type, for messages.
    const DTYPE: &'static str;
    /// Widen to `f64` (exact for both types).
    fn to_f64(self) -> f64;
    /// Round an `f64` to this type (what a computed score, such as a sequence-matched
    /// one, is stored as).
    fn from_f64(v: f64) -> Self;
    /// Sort ascending in IEEE total order (-0.0 before +0.0): a vectorised quicksort
    /// where the CPU has AVX-512, else a radix sort.
    fn sort_ascending(v: &mut [Self]);
    /// An owned copy of `s` in its own type.
    fn to_matrix(s: ArrayView2<'_, Self>) -> ScoreMatrix;
    /// `s` as a view of either type, for code that dispatches at run time.
    fn view(s: ArrayView2<'_, Self>) -> ScoresView<'_>;
}

/// An owned score matrix in its own type: what a [`crate::Calibration`] keeps of its
/// input so that it can be saved.
#[derive(Debug, Clone, PartialEq)]
pub enum ScoreMatrix {
    /// float32 scores.
    F32(Array2<f32>),
    /// float64 scores.
    F64(Array2<f64>),
}

impl ScoreMatrix {
    /// Shape (rows, columns).
    pub fn dim(&self) -> (usize, usize) {
        match self {
            ScoreMatrix::F32(m) => m.dim(),
            ScoreMatrix::F64(m) => m.dim(),
        }
    }

    /// The NumPy name of the element type (`float32` or `float64`).
    pub fn dtype(&self) -> &'static str {
        match self {
            ScoreMatrix::F32(_) => f32::DTYPE,
            ScoreMatrix::F64(_) => f64::DTYPE,
        }
    }

    /// A view of it, for generic code through [`with_scores!`](crate::with_scores).
    pub fn view(&self) -> ScoresView<'_> {
        match self {
            ScoreMatrix::F32(m) => ScoresView::F32(m.view()),
            ScoreMatrix::F64(m) => ScoresView::F64(m.view()),
        }
    }
}

impl sealed::Sealed for f32 {}
impl sealed::Sealed for f64 {}

impl Score for f32 {
    const DTYPE: &'static str = "float32";
    fn sort_ascending(v: &mut [Self]) {
        crate::platform::sort::sort_f32(v);
    }
    fn to_matrix(s: ArrayView2<'_, Self>) -> ScoreMatrix {
        ScoreMatrix::F32(s.to_owned())
    }
    fn view(s: ArrayView2<'_, Self>) -> ScoresView<'_> {
        ScoresView::F32(s)
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl Score for f64 {
    const DTYPE: &'static str = "float64";
    fn sort_ascending(v: &mut [Self]) {
        crate::platform::sort::sort_f64(v);
    }
    fn to_matrix(s: ArrayView2<'_, Self>) -> ScoreMatrix {
        ScoreMatrix::F64(s.to_owned())
    }
    fn view(s: ArrayView2<'_, Self>) -> ScoresView<'_> {
        ScoresView::F64(s)
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// A borrowed similarity (or descriptor, position) matrix of either score type: what a
/// front end holds when the dtype is known only at run time (a file, a NumPy array).
/// [`with_scores!`](crate::with_scores) calls generic code on the typed view inside.
#[derive(Debug, Clone, Copy)]
pub enum ScoresView<'a> {
    /// float32 values.
    F32(ArrayView2<'a, f32>),
    /// float64 values.
    F64(ArrayView2<'a, f64>),
}

/// Call generic code on the typed view inside a [`ScoresView`] (defined here, beside it; exported at the crate root): `$body` is compiled
/// once with `$v` an `ArrayView2<'_, f32>` and once with an `ArrayView2<'_, f64>`, the
/// only f32/f64 dispatch a front end needs.
///
/// ```
/// use ndarray::array;
/// use qtvpr::{ScoresView, with_scores};
///
/// let s = array![[0.5f32, 0.25]];
/// let view = ScoresView::from(s.view());
/// let sum = with_scores!(view, |v| v.iter().map(|x| f64::from(*x)).sum::<f64>());
/// assert_eq!(sum, 0.75);
/// ```
#[macro_export]
macro_rules! with_scores {
    ($view:expr, |$v:ident| $body:expr) => {
        match $view {
            $crate::ScoresView::F32($v) => $body,
            $crate::ScoresView::F64($v) => $body,
        }
    };
}

impl<'a> ScoresView<'a> {
    /// The transpose (no copy): a query-major matrix becomes |DB| x |Q|.
    #[must_use]
    pub fn t(self) -> Self {
        match self {
            ScoresView::F32(v) => ScoresView::F32(v.reversed_axes()),
            ScoresView::F64(v) => ScoresView::F64(v.reversed_axes()),
        }
    }

    /// The |DB| x |Q| view the core computes on, of a matrix stored query-major
    /// (|Q| x |DB|, as VPR-Bench stores them) when `query_major`: the one orientation
    /// rule of every front end. Errors of the computation are turned back into the
    /// caller's orientation by [`Error::oriented`] with the same flag.
    #[must_use]
    pub fn oriented(self, query_major: bool) -> Self {
        if query_major { self.t() } else { self }
    }

    /// Shape (rows, columns).
    pub fn dim(&self) -> (usize, usize) {
        match self {
            ScoresView::F32(v) => v.dim(),
            ScoresView::F64(v) => v.dim(),
        }
    }
}

impl<'a, T: Score> From<ArrayView2<'a, T>> for ScoresView<'a> {
    fn from(v: ArrayView2<'a, T>) -> Self {
        T::view(v)
    }
}

/// A ground-truth element type: `bool` or an integer holding 0/1.
pub trait Label: Copy + Send + Sync + 'static {
    /// The value as an integer, for the 0/1 check and for messages.
    fn to_i128(self) -> i128;
}

impl Label for bool {
    #[inline]
    fn to_i128(self) -> i128 {
        i128::from(self)
    }
}

macro_rules! int_label {
    ($($t:ty),*) => {$(
        impl Label for $t {
            #[inline]
            fn to_i128(self) -> i128 {
                i128::from(self)
            }
        }
    )*};
}
int_label!(u8, i8, u16, i16, u32, i32, u64, i64);

/// What the ground truth says of one (database, query) entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Truth {
    /// Not a match.
    False = 0,
    /// A hard match.
    True = 1,
    /// Soft but not hard: counts as neither true nor false.
    Ignored = 2,
}

/// Hard ground truth with optional soft ground truth, as one |DB| x |Q| matrix of [`Truth`],
/// and, when its labels are not places' but were inferred, the record of how
/// ([`LabelRecord`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTruth {
    labels: Array2<Truth>,
    record: Option<LabelRecord>,
}

/// How ground truth was labelled when not from places: the JSON object of semantics §16's
/// self-motion labels (`{"labels": "self-motion", "neighbours": 5, ...}`: the rule, its
/// parameters, its counts). It travels with the labels, from the ground-truth `.npz`
/// that holds it (its `labels` member) to the calibration file made from them (`meta`'s
/// `"labels"`), so that a calibration says that its labels are self-supervised. Made by
/// [`crate::SelfMotionLabels::record`] and checked wherever it is read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LabelRecord {
    /// The object, as compact JSON.
    json: String,
}

impl LabelRecord {
    /// A record from its JSON text, which the caller has checked (made and read with
    /// the `npy` feature's JSON).
    #[cfg_attr(not(feature = "npy"), allow(dead_code))]
    pub(crate) fn new(json: String) -> Self {
        Self { json }
    }

    /// The record as compact JSON.
    pub fn json(&self) -> &str {
        &self.json
    }
}

impl GroundTruth {
    /// Hard ground truth only (`GThard`).
    ///
    /// # Errors
    /// [`Error::Empty`] for an empty matrix, [`Error::BadLabel`] for a value other than 0/1.
    pub fn new<L: Label>(hard: ArrayView2<'_, L>) -> Result<Self> {
        check_nonempty(Input::GroundTruth, hard.dim())?;
        check_labels(Input::GroundTruth, hard)?;
        let (rows, cols) = hard.dim();
        let mut labels = Vec::new();
        try_reserve(&mut labels, hard.len(), || {
            format!("the {} ({rows}x{cols})", Input::GroundTruth)
        })?;
        labels.extend(
            hard.iter()
                .map(|h| if h.to_i128() == 1 { Truth::True } else { Truth::False }),
        );
        let labels = Array2::from_shape_vec(hard.dim(), labels).expect("one label per entry, in logical order");
        Ok(Self { labels, record: None })
    }

    /// Add soft ground truth (`GTsoft`): entries soft but not hard become [`Truth::Ignored`].
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if the shapes differ, [`Error::BadLabel`] for a value other than 0/1.
    pub fn with_soft<L: Label>(mut self, soft: ArrayView2<'_, L>) -> Result<Self> {
        if soft.dim() != self.labels.dim() {
            return Err(Error::ShapeMismatch {
                what: Input::SoftGroundTruth,
                shape: soft.dim(),
                other: Input::GroundTruth,
                other_shape: self.labels.dim(),
            });
        }
        check_labels(Input::SoftGroundTruth, soft)?;
        Zip::from(&mut self.labels).and(&soft).for_each(|t, s| {
            if s.to_i128() == 1 && *t == Truth::False {
                *t = Truth::Ignored;
            }
        });
        Ok(self)
    }

    /// Build directly from a [`Truth`] matrix.
    pub fn from_truth(labels: Array2<Truth>) -> Self {
        Self { labels, record: None }
    }

    /// The same labels with the record of how they were made (semantics §16).
    #[must_use]
    pub fn with_record(self, record: Option<LabelRecord>) -> Self {
        Self { record, ..self }
    }

    /// How the labels were made, when they are self-motion labels (semantics §16).
    pub fn record(&self) -> Option<&LabelRecord> {
        self.record.as_ref()
    }

    /// The |DB| x |Q| matrix of [`Truth`].
    pub fn view(&self) -> ArrayView2<'_, Truth> {
        self.labels.view()
    }

    /// Shape |DB| x |Q|.
    pub fn dim(&self) -> (usize, usize) {
        self.labels.dim()
    }

    /// The transpose, for query-major (VPR-Bench) input.
    pub fn reversed_axes(self) -> Self {
        Self {
            labels: self.labels.reversed_axes(),
            record: self.record,
        }
    }

    /// The |DB| x |Q| ground truth of labels stored query-major when `query_major`, as
    /// [`ScoresView::oriented`].
    #[must_use]
    pub fn oriented(self, query_major: bool) -> Self {
        if query_major { self.reversed_axes() } else { self }
    }
}

/// Every label of `m` is 0 or 1 (the first other one is named).
fn check_labels<L: Label>(what: Input, m: ArrayView2<'_, L>) -> Result<()> {
    if let Some(((row, col), v)) = m.indexed_iter().find(|(_, v)| !matches!(v.to_i128(), 0 | 1)) {
        return Err(Error::BadLabel {
            what,
            row,
            col,
            value: v.to_i128(),
        });
    }
    Ok(())
}

/// A matrix of shape (`rows`, `cols`) that `what` names has at least one row and one
/// column: what a front end asks of a whole input (a deployment traverse of no query is
/// refused by `qtvpr-cli stream` as by `threshold`, while [`Online::push_many`] of no
/// column is no decision).
///
/// # Errors
/// [`Error::Empty`].
///
/// [`Online::push_many`]: crate::Online::push_many
pub fn check_nonempty(what: Input, (rows, cols): (usize, usize)) -> Result<()> {
    if rows == 0 || cols == 0 {
        return Err(Error::Empty { what, rows, cols });
    }
    Ok(())
}

/// Check that a similarity matrix is non-empty and entirely finite.
///
/// # Errors
/// [`Error::Empty`] or [`Error::NotFinite`] (naming the first offending entry in
/// column-major order).
pub fn validate_scores<T: Score>(what: Input, s: ArrayView2<'_, T>) -> Result<()> {
    threads::install(|| {
        check_nonempty(what, s.dim())?;
        let bad = (0..s.ncols()).into_par_iter().find_map_first(|col| {
            let column = s.column(col);
            let (row, v) = column.iter().enumerate().find(|(_, v)| !v.to_f64().is_finite())?;
            Some(Error::NotFinite {
                what,
                row,
                col,
                value: v.to_f64(),
            })
        });
        bad.map_or(Ok(()), Err)
    })
}

/// Check that ground truth has the shape of the similarity matrix it labels.
///
/// # Errors
/// [`Error::ShapeMismatch`].
pub fn check_gt_shape(gt: &GroundTruth, similarity: Input, shape: (usize, usize)) -> Result<()> {
    if gt.dim() != shape {
        return Err(Error::ShapeMismatch {
            what: Input::GroundTruth,
            shape: gt.dim(),
            other: similarity,
            other_shape: shape,
        });
    }
    Ok(())
}

/// Check the precision target `tau` is in (0, 1].
///
/// # Errors
/// [`Error::InvalidParameter`].
pub fn check_precision(tau: f64) -> Result<()> {
    if !(tau > 0.0 && tau <= 1.0) {
        return Err(Error::param("precision", format!("must be in (0, 1], got {tau}")));
    }
    Ok(())
}

// After `with_scores!`, so that it is in scope in them.
pub(crate) mod orientation;
pub(crate) mod params;

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn labels_must_be_zero_or_one() {
        let err = GroundTruth::new(array![[0i64, 1], [2, 0]].view()).unwrap_err();
        assert_eq!(
            err,
            Error::BadLabel {
                what: Input::GroundTruth,
                row: 1,
                col: 0,
                value: 2
            }
        );
        assert_eq!(
            err.to_string(),
            "ground truth has value 2 at row 1, column 0; ground truth must be 0/1 or bool"
        );
        let hard = GroundTruth::new(array![[true, false]].view()).unwrap();
        let err = hard.with_soft(array![[0i8, -1]].view()).unwrap_err();
        assert_eq!(
            err,
            Error::BadLabel {
                what: Input::SoftGroundTruth,
                row: 0,
                col: 1,
                value: -1
            }
        );
    }

    #[test]
    fn soft_but_not_hard_is_ignored() {
        let gt = GroundTruth::new(array![[1u8, 0, 0]].view())
            .unwrap()
            .with_soft(array![[1u8, 1, 0]].view())
            .unwrap();
        assert_eq!(gt.view(), array![[Truth::True, Truth::Ignored, Truth::False]]);
    }

    #[test]
    fn shapes_must_agree() {
        let hard = GroundTruth::new(array![[true, false]].view()).unwrap();
        let err = hard.clone().with_soft(array![[true], [false]].view()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "soft ground truth shape 2x1 does not match ground truth shape 1x2"
        );
        let err = check_gt_shape(&hard, Input::CalSimilarity, (2, 1)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "ground truth shape 1x2 does not match calibration similarity shape 2x1"
        );
    }

    #[test]
    fn scores_must_be_finite_and_non_empty() {
        let s = array![[0.1, 0.2], [0.3, f64::NAN]];
        let err = validate_scores(Input::DeploymentSimilarity, s.view()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "deployment similarity contains NaN at row 1, column 1; scores must be finite"
        );
        let s = array![[0.1f32, f32::NEG_INFINITY]];
        assert!(
            validate_scores(Input::Similarity, s.view())
                .unwrap_err()
                .to_string()
                .contains("-inf at row 0, column 1")
        );
        let empty = ndarray::Array2::<f64>::zeros((0, 3));
        assert_eq!(
            validate_scores(Input::Similarity, empty.view())
                .unwrap_err()
                .to_string(),
            "similarity is empty (shape 0x3)"
        );
        assert!(GroundTruth::new(ndarray::Array2::<bool>::default((2, 0)).view()).is_err());
    }
}
