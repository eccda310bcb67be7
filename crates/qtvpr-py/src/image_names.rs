//! `utm_positions` and `image_paths`: positions from image names
//! ([`qtvpr::image_names`]).

use std::ffi::OsString;
use std::path::PathBuf;

use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;

use crate::error::named_error;

/// UTM positions from image names: an ``(n, 2)`` float64 array of east, north.
///
/// ``paths`` is a list of ``str`` or ``os.PathLike`` in the order of the descriptor
/// rows. Each position is fields 1 and 2 of the *file name* split on ``@``, the
/// VPR-methods-evaluation / VG benchmark format
/// ``@UTM_east@UTM_north@zone_number@zone_letter@lat@lon@...@.jpg``; a directory name
/// holding an ``@`` does not shift them. The files are not opened.
///
/// >>> qtvpr.utm_positions(["db/@549373.5@4178869.25@10@S@.jpg"])
/// array([[ 549373.5 , 4178869.25]])
///
/// Feed the result to ``ground_truth_positions`` (25 m in those benchmarks).
///
/// Raises ``ValueError`` naming the index and the name (``paths[2]: image name
/// 'x.jpg' has fewer than two '@'; ...``) when a name has fewer than two ``@``, or a
/// field is not a finite number, and ``TypeError`` when ``paths`` is not a list of paths.
#[pyfunction]
#[pyo3(signature = (paths))]
pub(crate) fn utm_positions<'py>(py: Python<'py>, paths: Vec<PathBuf>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let positions = qtvpr::utm_positions(&paths).map_err(named_error)?;
    Ok(positions.into_pyarray(py))
}

/// The image paths of ``source``, a dataset folder or a text file, in the order of the
/// descriptor rows, as a list of ``str``.
///
/// - A directory: if ``DIR_images_paths.txt`` exists next to it, its lines, each
///   joined to ``DIR``; otherwise every ``.jpg``, ``.jpeg`` or ``.png`` file (any case)
///   at any depth below it, names beginning with ``.`` skipped, sorted by path. That is
///   VPR-methods-evaluation's ``read_images_paths``, which orders the rows of its
///   ``database_descriptors.npy`` and ``queries_descriptors.npy``.
/// - A text file: one path per line, in order (a final newline ends the last line; an
///   empty line is an error).
///
/// ``qtvpr.utm_positions(qtvpr.image_paths("database"))`` gives the positions.
///
/// Raises ``FileNotFoundError`` (or another ``OSError``) when ``source`` cannot be read,
/// and ``ValueError`` for a directory without images, an empty text file, or an empty
/// or non-UTF-8 line (naming the line, 1-based).
#[pyfunction]
#[pyo3(signature = (source))]
pub(crate) fn image_paths(py: Python<'_>, source: PathBuf) -> PyResult<Vec<OsString>> {
    let images = py.detach(|| qtvpr::image_paths(&source)).map_err(named_error)?;
    Ok(images.paths.into_iter().map(PathBuf::into_os_string).collect())
}
