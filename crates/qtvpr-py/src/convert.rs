//! NumPy arguments in, core views out.
//!
//! Every matrix argument is borrowed read-only where it lies and handed to the core as
//! an [`ArrayView2`] with NumPy's strides (C, Fortran, sliced or negative), so nothing
//! is copied. The only copies are the rare inputs the core cannot read in place:
//! non-NumPy objects (converted by `numpy.asarray`), and arrays that are byte-swapped
//! or misaligned (converted to the native type by `astype`).
//!
//! The dtype is checked here because only the binding sees it: scores must be float32
//! or float64, ground truth bool or an integer type, anything else is a `TypeError`
//! naming the argument. Values (finiteness, 0/1 labels, shapes) are the core's to check.

use ndarray::ArrayView2;
use numpy::{
    Element, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArray2, PyUntypedArray, PyUntypedArrayMethods,
    dtype,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;

/// `numpy.asarray`, looked up once.
fn asarray(py: Python<'_>) -> PyResult<&Bound<'_, PyAny>> {
    static ASARRAY: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    ASARRAY.import(py, "numpy", "asarray")
}

/// `obj` as a NumPy array: itself if it is one, else `numpy.asarray(obj)`.
fn ndarray<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(array) = obj.cast::<PyUntypedArray>() {
        return Ok(array.clone());
    }
    Ok(asarray(obj.py())?.call1((obj,))?.cast_into::<PyUntypedArray>()?)
}

/// A 2-D array of element type `T`, borrowed read-only. `array`'s dtype must already
/// be known to be a (possibly byte-swapped) form of `T`.
fn borrow<'py, T: Element>(name: &str, array: Bound<'py, PyUntypedArray>) -> PyResult<PyReadonlyArray2<'py, T>> {
    if array.ndim() != 2 {
        let shape: Vec<String> = array.shape().iter().map(ToString::to_string).collect();
        let trailing = if shape.len() == 1 { "," } else { "" };
        return Err(PyValueError::new_err(format!(
            "{name} must be a 2-D matrix, got a {}-D array of shape ({}{trailing})",
            array.ndim(),
            shape.join(", ")
        )));
    }
    let py = array.py();
    let array = if array.is_aligned() && array.dtype().is_native_byteorder() != Some(false) {
        array
    } else {
        array
            .call_method1("astype", (dtype::<T>(py),))?
            .cast_into::<PyUntypedArray>()?
    };
    let array = array.cast_into::<PyArray2<T>>()?;
    array
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
}

/// Transpose for query-major input (a view, no copy).
fn oriented<T>(view: ArrayView2<'_, T>, query_major: bool) -> ArrayView2<'_, T> {
    if query_major { view.reversed_axes() } else { view }
}

/// A similarity-matrix argument.
pub(crate) enum Scores<'py> {
    /// float32 scores.
    F32(PyReadonlyArray2<'py, f32>),
    /// float64 scores.
    F64(PyReadonlyArray2<'py, f64>),
}

/// A similarity matrix as the core reads it, |DB| x |Q|.
#[derive(Clone, Copy)]
pub(crate) enum ScoreView<'a> {
    /// float32 scores.
    F32(ArrayView2<'a, f32>),
    /// float64 scores.
    F64(ArrayView2<'a, f64>),
}

/// Run `$body` with `$v` bound to the [`ScoreView`]'s typed `ArrayView2`.
macro_rules! with_scores {
    ($view:expr, $v:ident => $body:expr) => {
        match $view {
            $crate::convert::ScoreView::F32($v) => $body,
            $crate::convert::ScoreView::F64($v) => $body,
        }
    };
}
pub(crate) use with_scores;

impl<'py> Scores<'py> {
    /// Borrow argument `name` as a float32 or float64 matrix.
    ///
    /// # Errors
    /// `TypeError` for any other dtype, `ValueError` if it is not 2-D.
    pub(crate) fn extract(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        let array = ndarray(obj)?;
        let descr = array.dtype();
        match (descr.kind(), descr.itemsize()) {
            (b'f', 4) => Ok(Self::F32(borrow(name, array)?)),
            (b'f', 8) => Ok(Self::F64(borrow(name, array)?)),
            _ => Err(PyTypeError::new_err(format!(
                "{name} must be a float32 or float64 array, got {descr}"
            ))),
        }
    }

    /// The |DB| x |Q| view the core takes.
    pub(crate) fn view(&self, query_major: bool) -> ScoreView<'_> {
        match self {
            Self::F32(a) => ScoreView::F32(oriented(a.as_array(), query_major)),
            Self::F64(a) => ScoreView::F64(oriented(a.as_array(), query_major)),
        }
    }
}

/// Declares [`Labels`] and [`LabelView`] over every ground-truth element type the core
/// takes, keyed by NumPy dtype kind and item size.
macro_rules! labels {
    ($($variant:ident($t:ty) = ($kind:literal, $size:literal)),* $(,)?) => {
        /// A ground-truth argument: bool or an integer type.
        pub(crate) enum Labels<'py> {
            $(
                #[doc = concat!("`", stringify!($t), "` labels.")]
                $variant(PyReadonlyArray2<'py, $t>),
            )*
        }

        /// Ground truth as the core reads it, |DB| x |Q|.
        #[derive(Clone, Copy)]
        pub(crate) enum LabelView<'a> {
            $(
                #[doc = concat!("`", stringify!($t), "` labels.")]
                $variant(ArrayView2<'a, $t>),
            )*
        }

        impl<'py> Labels<'py> {
            /// Borrow argument `name` as a bool or integer matrix.
            ///
            /// # Errors
            /// `TypeError` for any other dtype, `ValueError` if it is not 2-D.
            pub(crate) fn extract(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
                let array = ndarray(obj)?;
                let descr = array.dtype();
                match (descr.kind(), descr.itemsize()) {
                    $(($kind, $size) => Ok(Self::$variant(borrow(name, array)?)),)*
                    _ => Err(PyTypeError::new_err(format!(
                        "{name} must be a bool or integer (0/1) array, got {descr}"
                    ))),
                }
            }

            /// The |DB| x |Q| view the core takes.
            pub(crate) fn view(&self, query_major: bool) -> LabelView<'_> {
                match self {
                    $(Self::$variant(a) => LabelView::$variant(oriented(a.as_array(), query_major)),)*
                }
            }
        }

        impl LabelView<'_> {
            /// Hard ground truth.
            fn hard(self) -> qtvpr::Result<qtvpr::GroundTruth> {
                match self {
                    $(Self::$variant(v) => qtvpr::GroundTruth::new(v),)*
                }
            }

            /// `gt` with these labels as its soft ground truth.
            fn soft(self, gt: qtvpr::GroundTruth) -> qtvpr::Result<qtvpr::GroundTruth> {
                match self {
                    $(Self::$variant(v) => gt.with_soft(v),)*
                }
            }
        }
    };
}

labels! {
    Bool(bool) = (b'b', 1),
    I8(i8) = (b'i', 1),
    I16(i16) = (b'i', 2),
    I32(i32) = (b'i', 4),
    I64(i64) = (b'i', 8),
    U8(u8) = (b'u', 1),
    U16(u16) = (b'u', 2),
    U32(u32) = (b'u', 4),
    U64(u64) = (b'u', 8),
}

/// Hard and optional soft ground-truth arguments, borrowed.
pub(crate) struct GroundTruthArgs<'py> {
    hard: Labels<'py>,
    soft: Option<Labels<'py>>,
}

impl<'py> GroundTruthArgs<'py> {
    /// Borrow the hard ground truth (argument `name`) and the optional `gt_soft`.
    ///
    /// # Errors
    /// As [`Labels::extract`].
    pub(crate) fn extract(name: &str, hard: &Bound<'py, PyAny>, soft: Option<&Bound<'py, PyAny>>) -> PyResult<Self> {
        Ok(Self {
            hard: Labels::extract(name, hard)?,
            soft: soft.map(|s| Labels::extract("gt_soft", s)).transpose()?,
        })
    }

    /// Views of both, |DB| x |Q|, to build the core's ground truth from without the GIL.
    pub(crate) fn view(&self, query_major: bool) -> GroundTruthView<'_> {
        GroundTruthView {
            hard: self.hard.view(query_major),
            soft: self.soft.as_ref().map(|s| s.view(query_major)),
        }
    }
}

/// Hard and optional soft ground truth, as views the core reads.
#[derive(Clone, Copy)]
pub(crate) struct GroundTruthView<'a> {
    hard: LabelView<'a>,
    soft: Option<LabelView<'a>>,
}

impl GroundTruthView<'_> {
    /// The core's ground truth (this is where labels are checked to be 0/1).
    ///
    /// # Errors
    /// The core's errors: empty matrices, values other than 0/1, soft ground truth of
    /// another shape.
    pub(crate) fn build(self) -> qtvpr::Result<qtvpr::GroundTruth> {
        let gt = self.hard.hard()?;
        match self.soft {
            Some(soft) => soft.soft(gt),
            None => Ok(gt),
        }
    }
}

/// A count argument (`k`, `segment_size`) as the core's `usize`.
///
/// A negative value is rejected here with the core's wording, since it does not fit
/// the core's type; 0 and values too large are left to the core.
///
/// # Errors
/// `ValueError` for a negative value.
pub(crate) fn count(name: &str, value: i64) -> PyResult<usize> {
    usize::try_from(value).map_err(|_| PyValueError::new_err(format!("{name} must be >= 1, got {value}")))
}
