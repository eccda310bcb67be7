//! `Descriptors`: database and query descriptors in place of a similarity matrix, for
//! `Calibration`, `Calibration.transfer` and `evaluate`.

use std::ops::Range;

use numpy::{IntoPyArray, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use qtvpr::ScoreSource;
use qtvpr::npy::FloatMatrix;

use crate::convert::{Int, MatrixArg, non_negative};
use crate::error::named_error;

/// Database and query descriptors, accepted wherever a similarity matrix is:
/// ``Calibration(Descriptors(db, q, stop=n), gt_cal)``,
/// ``cal.transfer(Descriptors(db, q, start=n))`` and ``evaluate(Descriptors(db, q), gt)``.
///
/// ``db`` (|DB| x D) and ``queries`` (|Q| x D) hold one descriptor per row, float32 or
/// float64, as arrays (borrowed, not copied) or ``.npy`` paths (memory-mapped). The
/// object stands for the similarity matrix ``cosine_similarity(db, queries)[:,
/// start:stop]``, bit for bit, without computing it: ``Calibration.transfer`` computes
/// it chunk by chunk and never holds it whole (memory: the descriptors, the calibration
/// and one chunk of scores); ``Calibration`` and ``evaluate`` build it in memory (they
/// need all of it). ``start`` and ``stop`` select queries (default: all) so that a
/// split of one set of queries gives exactly the columns of the whole matrix.
///
/// Raises ``TypeError`` for a dtype other than float32/float64 and ``ValueError`` for
/// descriptors that are empty, of different dimensions, hold NaN or infinity (naming
/// the row and column) or an all-zero row (naming the row), or an empty range.
#[pyclass(name = "Descriptors", module = "qtvpr", frozen)]
pub(crate) struct PyDescriptors {
    db: Py<PyAny>,
    queries: Py<PyAny>,
    range: Range<usize>,
    n_db: usize,
}

#[pymethods]
impl PyDescriptors {
    #[new]
    #[pyo3(signature = (db, queries, *, start = Int::Small(0), stop = None), text_signature = "(db, queries, *, start=0, stop=None)")]
    fn new(
        py: Python<'_>,
        db: &Bound<'_, PyAny>,
        queries: &Bound<'_, PyAny>,
        start: Int,
        stop: Option<Int>,
    ) -> PyResult<Self> {
        let (n_db, n_q) = with_arrays(py, db, queries, |d| Ok(d.shape()))?.map_err(named_error)?;
        let start = non_negative("start", start)?;
        let stop = stop.map(|s| non_negative("stop", s)).transpose()?.unwrap_or(n_q);
        if start >= stop || stop > n_q {
            return Err(PyValueError::new_err(format!(
                "start and stop must select at least one of the {n_q} queries, got start={start}, stop={stop}"
            )));
        }
        Ok(Self {
            db: db.clone().unbind(),
            queries: queries.clone().unbind(),
            range: start..stop,
            n_db,
        })
    }

    /// (|DB|, number of queries selected): the shape of the similarity it stands for.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.n_db, self.range.len())
    }

    /// The first query selected.
    #[getter]
    fn start(&self) -> usize {
        self.range.start
    }

    /// One past the last query selected.
    #[getter]
    fn stop(&self) -> usize {
        self.range.end
    }

    /// The similarity it stands for, |DB| x (stop - start) float32: exactly
    /// ``cosine_similarity(db, queries)[:, start:stop]``.
    pub(crate) fn similarity<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let s = self.with(py, |d, r| d.similarity(r))?.map_err(named_error)?;
        Ok(s.into_pyarray(py))
    }

    fn __repr__(&self) -> String {
        let (r, c) = self.shape();
        format!(
            "Descriptors(|DB|={r}, queries {}..{} ({c}))",
            self.range.start, self.range.end
        )
    }
}

impl PyDescriptors {
    /// `s` as descriptors, if it is a ``Descriptors``: the one check of every function
    /// that takes them in place of a matrix. ``query_major=True`` with descriptors is a
    /// ``ValueError``: their similarity is |DB| x |Q| by construction.
    pub(crate) fn of<'a, 'py>(s: &'a Bound<'py, PyAny>, query_major: bool) -> PyResult<Option<&'a Bound<'py, Self>>> {
        let Ok(d) = s.cast::<Self>() else {
            return Ok(None);
        };
        if query_major {
            return Err(PyValueError::new_err(
                "query_major=True does not apply to Descriptors, whose similarity is |DB| x |Q|",
            ));
        }
        Ok(Some(d))
    }

    /// Run `f` (without the GIL) on the core's descriptors and the selected queries.
    /// The outer error is about the descriptors (named `db` / `queries`); the inner one
    /// is `f`'s, for the caller to name.
    pub(crate) fn with<R: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&qtvpr::Descriptors<'_>, Range<usize>) -> qtvpr::Result<R> + Send,
    ) -> PyResult<qtvpr::Result<R>> {
        let range = self.range.clone();
        with_arrays(py, self.db.bind(py), self.queries.bind(py), |d| Ok(f(d, range)))?.map_err(named_error)
    }
}

/// A similarity argument as the core reads it: a matrix (an array or a `.npy` path,
/// |Q| x |DB| when `query_major`) or a ``Descriptors``. It is turned into a
/// [`ScoreSource`] once, in [`SourceArg::with`]; no function dispatches on the two.
pub(crate) enum SourceArg<'py> {
    /// A matrix, and whether it is stored query-major.
    Matrix(MatrixArg<'py>, bool),
    /// Descriptors and their range of queries.
    Descriptors(Bound<'py, PyDescriptors>),
}

impl<'py> SourceArg<'py> {
    /// Borrow argument `name`: ``Descriptors`` as they are, anything else as a matrix
    /// ([`MatrixArg::extract`]).
    ///
    /// # Errors
    /// Those of [`MatrixArg::extract`], and ``query_major=True`` with descriptors.
    pub(crate) fn extract(name: &str, obj: &Bound<'py, PyAny>, query_major: bool) -> PyResult<Self> {
        Ok(match PyDescriptors::of(obj, query_major)? {
            Some(d) => Self::Descriptors(d.clone()),
            None => Self::Matrix(MatrixArg::extract(name, obj)?, query_major),
        })
    }

    /// What was assumed of a matrix's orientation, with the evidence of `gt` (given in
    /// the matrix's orientation, and transposed with it); `None` for descriptors,
    /// which have but one. The core's warning, when the evidence contradicts the
    /// assumption, is issued as a `UserWarning`.
    pub(crate) fn orientation(&self, py: Python<'_>, gt: &qtvpr::GroundTruth) -> PyResult<Option<qtvpr::Orientation>> {
        let Self::Matrix(s, query_major) = self else {
            return Ok(None);
        };
        let orientation = qtvpr::Orientation::of(s.view(*query_major).dim(), Some(gt), *query_major);
        if let Some(warning) = orientation.warning("query_major=True") {
            let message = std::ffi::CString::new(warning).expect("a message without NUL");
            let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
            PyErr::warn(py, category.as_any(), &message, 1)?;
        }
        Ok(Some(orientation))
    }

    /// Run `f` (without the GIL) on the core's source. The outer error is about the
    /// descriptors themselves (named `db` / `queries`); the inner one is `f`'s, for the
    /// caller to name.
    pub(crate) fn with<R: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(ScoreSource<'_, '_>) -> qtvpr::Result<R> + Send,
    ) -> PyResult<qtvpr::Result<R>> {
        match self {
            Self::Matrix(s, query_major) => {
                let s = s.view(*query_major);
                Ok(py.detach(|| f(s.into())))
            }
            Self::Descriptors(d) => d.get().with(py, |d, r| f(ScoreSource::Descriptors(d, r))),
        }
    }
}

/// Borrow `db` and `queries`, check them as descriptors and run `f` on them without
/// the GIL.
fn with_arrays<R: Send>(
    py: Python<'_>,
    db: &Bound<'_, PyAny>,
    queries: &Bound<'_, PyAny>,
    f: impl FnOnce(&qtvpr::Descriptors<'_>) -> qtvpr::Result<R> + Send,
) -> PyResult<qtvpr::Result<R>> {
    let db = MatrixArg::extract_as("db", db, FloatMatrix::Descriptors)?;
    let queries = MatrixArg::extract_as("queries", queries, FloatMatrix::Descriptors)?;
    let (d, q) = (db.view(false), queries.view(false));
    Ok(py.detach(|| qtvpr::Descriptors::new(d, q).and_then(|d| f(&d))))
}
