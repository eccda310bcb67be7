//! NumPy arguments (or files) in, core views out.
//!
//! Every matrix argument is borrowed read-only where it lies and handed to the core as
//! an [`ArrayView2`] with NumPy's strides (C, Fortran, sliced or negative), so nothing
//! is copied. The only copies are the rare inputs the core cannot read in place:
//! non-NumPy objects (converted by `numpy.asarray`), and arrays that are byte-swapped
//! or misaligned (converted to the native type by `astype`).
//!
//! A matrix argument may also be a path (`str` or `os.PathLike`) to a `.npy` file
//! (ground truth: `.npy` or a VPR_Tutorial `.npz`). It is read by the core's
//! [`qtvpr::npy`] reader, the CLI's, with the GIL released: similarity matrices are
//! memory-mapped, so a path is also the zero-copy way to pass a matrix larger than RAM.
//!
//! The dtype of an array is checked here because only the binding sees it: scores must
//! be float32 or float64, ground truth bool or an integer type, anything else is a
//! `TypeError` naming the argument (the reader does the same for files). Values
//! (finiteness, 0/1 labels, shapes) are the core's to check.
//!
//! Why not rust-numpy's `PyArrayLike2` or a derived `FromPyObject` enum over
//! `PyReadonlyArray2<f32>` / `<f64>`: the derived enum tries its variants in turn, so
//! its failure is one generic message for all of them instead of `s must be a float32
//! or float64 array, got int64` or `s must be a 2-D matrix, got a 1-D array`; a
//! `PyArrayLike2<f32>` force-casts a list (or, with `AllowTypeChange`, an array) to
//! the first variant's type, which would silently round float64 data to float32; and
//! neither takes a byte-swapped or misaligned array, which `borrow` converts. The
//! dispatch below is on the dtype NumPy reports, once.

use std::path::{Path, PathBuf};

use ndarray::{ArrayView2, Axis, Dimension, Ix2};
use numpy::{
    Element, PyArray, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArray, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArray, PyUntypedArrayMethods, dtype,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyBool, PyString};
use qtvpr::ScoresView;
use qtvpr::npy::FloatMatrix;

use crate::error::input_error;
use crate::self_motion::SelfMotionLabels;

/// `numpy.asarray`, looked up once.
fn asarray(py: Python<'_>) -> PyResult<&Bound<'_, PyAny>> {
    static ASARRAY: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    ASARRAY.import(py, "numpy", "asarray")
}

/// `obj` as a path if it is a `str` or an `os.PathLike`, else `None`.
fn path_of(obj: &Bound<'_, PyAny>) -> PyResult<Option<PathBuf>> {
    static PATH_LIKE: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    if obj.is_instance_of::<PyString>() || obj.is_instance(PATH_LIKE.import(obj.py(), "os", "PathLike")?)? {
        return Ok(Some(obj.extract::<PathBuf>()?));
    }
    Ok(None)
}

/// `obj` as a NumPy array: itself if it is one, else `numpy.asarray(obj)`.
fn ndarray<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(array) = obj.cast::<PyUntypedArray>() {
        return Ok(array.clone());
    }
    Ok(asarray(obj.py())?.call1((obj,))?.cast_into::<PyUntypedArray>()?)
}

/// The shape of `array` as Python writes it: `(3,)`, `(3, 2)`.
fn shape_of(array: &Bound<'_, PyUntypedArray>) -> String {
    let shape: Vec<String> = array.shape().iter().map(ToString::to_string).collect();
    let trailing = if shape.len() == 1 { "," } else { "" };
    format!("({}{trailing})", shape.join(", "))
}

/// A 2-D array of element type `T`, borrowed read-only. `array`'s dtype must already
/// be known to be a (possibly byte-swapped) form of `T`.
fn borrow<'py, T: Element>(name: &str, array: Bound<'py, PyUntypedArray>) -> PyResult<PyReadonlyArray2<'py, T>> {
    if array.ndim() != 2 {
        return Err(PyValueError::new_err(format!(
            "{name} must be a 2-D matrix, got a {}-D array of shape {}",
            array.ndim(),
            shape_of(&array)
        )));
    }
    borrow_as::<T, Ix2>(name, array)
}

/// `array` borrowed read-only as an array of element type `T` and dimension `D`, which
/// the caller has checked; converted to the native type first if it is byte-swapped or
/// misaligned. An empty array is converted too (it costs nothing): NumPy calls every
/// empty array aligned, but one sliced from a misaligned array keeps its misaligned
/// pointer, which no view may hold.
fn borrow_as<'py, T: Element, D: Dimension>(
    name: &str,
    array: Bound<'py, PyUntypedArray>,
) -> PyResult<PyReadonlyArray<'py, T, D>> {
    let py = array.py();
    let array = if !array.is_empty() && array.is_aligned() && array.dtype().is_native_byteorder() != Some(false) {
        array
    } else {
        array
            .call_method1("astype", (dtype::<T>(py),))?
            .cast_into::<PyUntypedArray>()?
    };
    let array = array.cast_into::<PyArray<T, D>>()?;
    array
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
}

/// One query's scores (`Online.push`): a 1-D array, or a |DB| x 1 matrix read as its
/// only column; float32 or float64, any strides, borrowed in place.
pub(crate) enum Column<'py> {
    /// float32 scores.
    F32(PyReadonlyArray1<'py, f32>),
    /// float64 scores.
    F64(PyReadonlyArray1<'py, f64>),
    /// A |DB| x 1 float32 matrix.
    F32Matrix(PyReadonlyArray2<'py, f32>),
    /// A |DB| x 1 float64 matrix.
    F64Matrix(PyReadonlyArray2<'py, f64>),
}

impl<'py> Column<'py> {
    /// Borrow argument `name` as one query's scores.
    ///
    /// # Errors
    /// `TypeError` for a dtype other than float32 and float64, `ValueError` for an
    /// array that is neither 1-D nor a one-column matrix (its length is the core's to
    /// check).
    pub(crate) fn extract(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        let array = ndarray(obj)?;
        let descr = array.dtype();
        let float = match (descr.kind(), descr.itemsize()) {
            (b'f', 4) => false,
            (b'f', 8) => true,
            _ => {
                return Err(PyTypeError::new_err(format!(
                    "{name} must be a float32 or float64 array, got {descr}"
                )));
            }
        };
        match (array.ndim(), array.shape().get(1), float) {
            (1, _, false) => Ok(Self::F32(borrow_as(name, array)?)),
            (1, _, true) => Ok(Self::F64(borrow_as(name, array)?)),
            (2, Some(1), false) => Ok(Self::F32Matrix(borrow_as(name, array)?)),
            (2, Some(1), true) => Ok(Self::F64Matrix(borrow_as(name, array)?)),
            _ => Err(PyValueError::new_err(format!(
                "{name} must hold one query's scores, a 1-D array or a |DB| x 1 matrix, got shape {}",
                shape_of(&array)
            ))),
        }
    }

    /// The scores as a |DB| x 1 view: the core's one f32/f64 dispatch
    /// ([`qtvpr::with_scores!`]) then serves a column too.
    pub(crate) fn view(&self) -> ScoresView<'_> {
        match self {
            Self::F32(a) => ScoresView::F32(a.as_array().insert_axis(Axis(1))),
            Self::F64(a) => ScoresView::F64(a.as_array().insert_axis(Axis(1))),
            Self::F32Matrix(a) => ScoresView::F32(a.as_array()),
            Self::F64Matrix(a) => ScoresView::F64(a.as_array()),
        }
    }
}

/// A matrix argument: a float32 or float64 array (borrowed), or a `.npy` path.
pub(crate) enum MatrixArg<'py> {
    /// float32 scores.
    F32(PyReadonlyArray2<'py, f32>),
    /// float64 scores.
    F64(PyReadonlyArray2<'py, f64>),
    /// A `.npy` file, memory-mapped where possible.
    File(qtvpr::npy::MatrixFile),
}

impl<'py> MatrixArg<'py> {
    /// Borrow similarity-matrix argument `name` as a float32 or float64 matrix.
    /// A `str` or `os.PathLike` is read as a `.npy` file.
    ///
    /// # Errors
    /// `TypeError` for any other dtype, `ValueError` if it is not 2-D; for a file, the
    /// reader's errors as [`input_error`]s (`OSError`s for a file that cannot be read).
    pub(crate) fn extract(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        Self::extract_as(name, obj, FloatMatrix::Similarity)
    }

    /// [`MatrixArg::extract`] of a matrix holding `what` (descriptors, positions), for the
    /// messages about a file.
    pub(crate) fn extract_as(name: &str, obj: &Bound<'py, PyAny>, what: FloatMatrix) -> PyResult<Self> {
        if let Some(path) = path_of(obj)? {
            let scores = obj.py().detach(|| qtvpr::npy::read_float_matrix(&path, what));
            return scores.map(Self::File).map_err(|e| input_error(name, e));
        }
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

    /// The view the core takes: |DB| x |Q| for a similarity matrix stored query-major
    /// when `query_major` ([`ScoresView::oriented`]).
    pub(crate) fn view(&self, query_major: bool) -> ScoresView<'_> {
        let view = match self {
            Self::F32(a) => ScoresView::F32(a.as_array()),
            Self::F64(a) => ScoresView::F64(a.as_array()),
            Self::File(scores) => scores.view(),
        };
        view.oriented(query_major)
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

            /// The array as the caller gave it.
            pub(crate) fn view(&self) -> LabelView<'_> {
                match self {
                    $(Self::$variant(a) => LabelView::$variant(a.as_array()),)*
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

/// One ground-truth argument: an array, the path of a file, or self-motion labels.
pub(crate) enum LabelArg<'py> {
    /// A bool or integer array, borrowed.
    Array(Labels<'py>),
    /// A `.npy` file (or, for hard ground truth, a VPR_Tutorial `.npz`), read when the
    /// ground truth is built.
    File(PathBuf),
    /// A `SelfMotionLabels` (semantics §16): hard and soft ground truth with their record.
    SelfMotion(Py<SelfMotionLabels>),
}

impl<'py> LabelArg<'py> {
    fn extract(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        if let Ok(labels) = obj.cast::<SelfMotionLabels>() {
            return Ok(Self::SelfMotion(labels.clone().unbind()));
        }
        match path_of(obj)? {
            Some(path) => Ok(Self::File(path)),
            None => Ok(Self::Array(Labels::extract(name, obj)?)),
        }
    }

    fn view(&self) -> LabelSource<'_> {
        match self {
            Self::Array(labels) => LabelSource::Array(labels.view()),
            Self::File(path) => LabelSource::File(path),
            Self::SelfMotion(labels) => LabelSource::Truth(labels.get().truth()),
        }
    }
}

/// Hard and optional soft ground-truth arguments, borrowed.
pub(crate) struct GroundTruthArgs<'py> {
    name: &'static str,
    hard: LabelArg<'py>,
    soft: Option<LabelArg<'py>>,
}

impl<'py> GroundTruthArgs<'py> {
    /// Borrow the hard ground truth (argument `name`) and the optional `gt_soft`.
    ///
    /// # Errors
    /// As [`Labels::extract`] for arrays; files are only read by
    /// [`GroundTruthView::build`].
    pub(crate) fn extract(
        name: &'static str,
        hard: &Bound<'py, PyAny>,
        soft: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        Ok(Self {
            name,
            hard: LabelArg::extract(name, hard)?,
            soft: soft.map(|s| LabelArg::extract("gt_soft", s)).transpose()?,
        })
    }

    /// What [`GroundTruthView::build`] needs, without the GIL.
    pub(crate) fn view(&self, query_major: bool) -> GroundTruthView<'_> {
        GroundTruthView {
            name: self.name,
            hard: self.hard.view(),
            soft: self.soft.as_ref().map(LabelArg::view),
            query_major,
        }
    }
}

/// A ground-truth argument as the core reads it.
#[derive(Clone, Copy)]
enum LabelSource<'a> {
    Array(LabelView<'a>),
    File(&'a Path),
    Truth(&'a qtvpr::GroundTruth),
}

/// Hard and optional soft ground truth, as views or paths the core reads.
#[derive(Clone, Copy)]
pub(crate) struct GroundTruthView<'a> {
    name: &'static str,
    hard: LabelSource<'a>,
    soft: Option<LabelSource<'a>>,
    query_major: bool,
}

impl GroundTruthView<'_> {
    /// The core's |DB| x |Q| ground truth (this is where labels are checked to be 0/1
    /// and files are read). Call it without the GIL.
    ///
    /// The labels are combined in the caller's orientation and only then transposed for
    /// query-major input, so positions and shapes in errors are the caller's. An explicit
    /// `gt_soft` takes precedence over the `GTsoft` of an `.npz`.
    ///
    /// # Errors
    /// The core's errors as [`input_error`]s naming the argument: a file that cannot be
    /// read, empty matrices, values other than 0/1, soft ground truth of another shape.
    pub(crate) fn build(self) -> PyResult<qtvpr::GroundTruth> {
        use qtvpr::npy::{add_soft_ground_truth, read_ground_truth, read_hard_ground_truth};
        let gt = match self.hard {
            LabelSource::Array(labels) => labels.hard(),
            LabelSource::File(path) if self.soft.is_some() => read_hard_ground_truth(path),
            LabelSource::File(path) => read_ground_truth(path, None),
            LabelSource::Truth(_) if self.soft.is_some() => {
                return Err(PyValueError::new_err(format!(
                    "gt_soft: {} is self-motion labels, which hold their own soft ground truth; give no gt_soft",
                    self.name
                )));
            }
            LabelSource::Truth(gt) => Ok(gt.clone()),
        }
        .map_err(|e| input_error(self.name, e))?;
        let gt = match self.soft {
            None => Ok(gt),
            Some(LabelSource::Array(labels)) => labels.soft(gt),
            Some(LabelSource::File(path)) => add_soft_ground_truth(gt, path),
            Some(LabelSource::Truth(_)) => {
                return Err(PyValueError::new_err(format!(
                    "gt_soft: self-motion labels are hard and soft ground truth at once; give them as {}",
                    self.name
                )));
            }
        }
        .map_err(|e| input_error("gt_soft", e))?;
        Ok(gt.oriented(self.query_major))
    }
}

/// A ``gate=`` argument, parsed by the core: ``None`` leaves the calibration's default.
pub(crate) fn gate(gate: Option<&str>) -> qtvpr::Result<Option<qtvpr::Gate>> {
    gate.map(str::parse).transpose()
}

/// The sequence gate's keyword arguments (semantics §15: ``sequence_window``,
/// ``sequence_level``, ``sequence_speed``, ``sequence_tolerance``, ``sequence_drift``)
/// as given, each ``None`` taking the calibration's (its file's), else the default; the
/// core checks them.
pub(crate) fn sequence_gate(
    window: Option<Int>,
    level: Option<Real>,
    speed: Option<Real>,
    tolerance: Option<Real>,
    drift: Option<Real>,
) -> PyResult<qtvpr::SequenceOverrides> {
    Ok(qtvpr::SequenceOverrides {
        window: window.map(|w| count("sequence_window", w)).transpose()?,
        level: real("sequence_level", level)?,
        speed: real("sequence_speed", speed)?,
        tolerance: real("sequence_tolerance", tolerance)?,
        drift: real("sequence_drift", drift)?,
    })
}

/// An integer argument as Python gave it, however large. pyo3 names the argument of a
/// failed conversion only in a `TypeError`, so that `window=2**70` or `start=-1` into a
/// Rust integer would raise an `OverflowError` that names nothing; taken as this, every
/// int converts, and its check ([`count`], [`non_negative`]) names the argument.
#[derive(Debug, Clone)]
pub(crate) enum Int {
    /// Fits an `i64`.
    Small(i64),
    /// Does not: its decimal digits, for the message.
    Large(String),
    /// A bool, which Python counts as an int (`True == 1`): refused by [`Int::at_least`]
    /// with a `TypeError` naming the argument, since `k=True` is a mistake, not 1.
    Bool(bool),
}

impl From<usize> for Int {
    fn from(n: usize) -> Self {
        i64::try_from(n).map_or_else(|_| Int::Large(n.to_string()), Int::Small)
    }
}

impl FromPyObject<'_, '_> for Int {
    type Error = PyErr;

    fn extract(obj: Borrowed<'_, '_, PyAny>) -> PyResult<Self> {
        if let Ok(flag) = obj.cast::<PyBool>() {
            return Ok(Int::Bool(flag.is_true()));
        }
        match obj.extract::<i64>() {
            Ok(n) => Ok(Int::Small(n)),
            Err(e) if e.is_instance_of::<pyo3::exceptions::PyOverflowError>(obj.py()) => {
                Ok(Int::Large(obj.str()?.to_string()))
            }
            Err(e) => Err(e),
        }
    }
}

impl Int {
    /// As a `usize` of at least `min` (0 or 1), or a `ValueError` naming `name` that
    /// says what it must be (`rule`, e.g. ">= 1"); a bool is a `TypeError` naming it.
    pub(crate) fn at_least(&self, name: &str, min: usize, rule: &str) -> PyResult<usize> {
        let bad = |shown: &dyn std::fmt::Display| PyValueError::new_err(format!("{name} must be {rule}, got {shown}"));
        match self {
            Int::Bool(flag) => Err(PyTypeError::new_err(format!(
                "{name} must be an int, got a bool ({})",
                if *flag { "True" } else { "False" }
            ))),
            Int::Small(n) => match usize::try_from(*n) {
                Ok(n) if n >= min => Ok(n),
                _ => Err(bad(n)),
            },
            Int::Large(digits) if digits.starts_with('-') => Err(bad(digits)),
            Int::Large(digits) => Err(PyValueError::new_err(format!(
                "{name} must be at most {}, got {digits}",
                usize::MAX
            ))),
        }
    }
}

/// A float argument as Python gave it. pyo3 converts a bool to a float (`True` is 1.0,
/// a subclass of `int`), so that `precision=True` would silently be 1.0; taken as this,
/// every float argument keeps a bool apart, and [`Real::get`] (or [`real`]) refuses it
/// with a `TypeError` naming the argument, as [`Int::at_least`] does for an integer.
/// Anything else is as `f64` extracts it (a float, an int, a NumPy scalar, an object
/// with `__float__`).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Real {
    /// A number.
    Value(f64),
    /// A bool, refused by [`Real::get`].
    Bool(bool),
}

impl FromPyObject<'_, '_> for Real {
    type Error = PyErr;

    fn extract(obj: Borrowed<'_, '_, PyAny>) -> PyResult<Self> {
        if let Ok(flag) = obj.cast::<PyBool>() {
            return Ok(Real::Bool(flag.is_true()));
        }
        obj.extract::<f64>().map(Real::Value)
    }
}

impl Real {
    /// The number, or a `TypeError` naming `name` for a bool.
    pub(crate) fn get(self, name: &str) -> PyResult<f64> {
        match self {
            Real::Value(x) => Ok(x),
            Real::Bool(flag) => Err(PyTypeError::new_err(format!(
                "{name} must be a float, got a bool ({})",
                if flag { "True" } else { "False" }
            ))),
        }
    }
}

/// An optional float argument `name` as an `f64`: [`Real::get`] of it when given.
///
/// # Errors
/// `TypeError` naming the argument for a bool.
pub(crate) fn real(name: &str, value: Option<Real>) -> PyResult<Option<f64>> {
    value.map(|x| x.get(name)).transpose()
}

/// A count argument (`k`, `window`, `segment_size`) as the core's `usize`.
///
/// A negative value or one too large for a `usize` is refused here, since it does not
/// fit the core's type; 0 is left to the core, whose wording it then gets.
///
/// # Errors
/// `ValueError` naming the argument.
pub(crate) fn count(name: &str, value: Int) -> PyResult<usize> {
    value.at_least(name, 0, ">= 1")
}

/// A non-negative integer argument (an index, a tolerance).
///
/// # Errors
/// `ValueError` naming the argument.
pub(crate) fn non_negative(name: &str, value: Int) -> PyResult<usize> {
    value.at_least(name, 0, ">= 0")
}
