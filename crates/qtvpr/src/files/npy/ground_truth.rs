//! Ground truth files: bool or integer 0/1 `.npy` files, and `.npz` archives in the
//! VPR_Tutorial convention (`GThard`, optional `GTsoft`), which qtvpr's self-motion
//! labels (semantics §16) extend with a member `labels`: the record of how they were
//! made, a 0-d string of JSON that VPR_Tutorial code, reading `GThard` and `GTsoft`
//! only, never sees.

use std::io::{self, Read};
use std::path::Path;

use npyz::{NpyFile, TypeChar};

use rawzip::ReaderAt;

use ndarray::ArrayView2;

use super::archive::{Archive, open_npz_file};
use super::guard::guarded;
use super::header::{MATRIX, dtype_name, parse, plain_dtype};
use super::npz::{Kind, npz_array, read_string};
use super::open::{ZIP_LOCAL_HEADER, file_error, open_file};
use super::read::read_matrix;
use super::write::{NpyArray, write_npz};
use crate::error::{Error, Result};
use crate::input::{GroundTruth, LabelRecord};
use crate::signals::self_motion::check_record;

/// The archive's member of the hard ground truth (VPR_Tutorial's name).
const HARD: &str = "GThard";
/// The soft ground truth's.
const SOFT: &str = "GTsoft";
/// The record of self-motion labels (semantics §16), qtvpr's own.
const LABELS: &str = "labels";

/// Read ground truth from the bytes of a `.npy` file (hard ground truth), or of an
/// `.npz` archive in the VPR_Tutorial convention (`GThard`, and `GTsoft` if it has one),
/// as [`scores_from_bytes`](crate::files::npy::scores_from_bytes); `name` names it in errors.
///
/// # Errors
/// As [`read_ground_truth`].
pub fn ground_truth_from_bytes(bytes: &[u8], name: &str) -> Result<GroundTruth> {
    let path = Path::new(name);
    guarded(path, || {
        if bytes.starts_with(ZIP_LOCAL_HEADER) {
            archive_ground_truth(&Archive::new(bytes, bytes.len() as u64, path)?, true)
        } else {
            ground_truth_of(parse(bytes, path)?, path, None)
        }
    })
}

/// Labels of one ground-truth array, added to `hard` as soft ground truth if given.
fn ground_truth_of<R: Read>(npy: NpyFile<R>, path: &Path, hard: Option<GroundTruth>) -> Result<GroundTruth> {
    macro_rules! labels {
        ($t:ty) => {{
            let m = read_matrix::<$t, R>(npy, path, MATRIX)?.into_array();
            match hard {
                None => GroundTruth::new(m.view()),
                Some(hard) => hard.with_soft(m.view()),
            }
        }};
    }
    const RULE: &str = "expected bool or integer 0/1 ground truth";
    let gt = match plain_dtype(&npy, path, RULE)? {
        (TypeChar::Bool, _, _) => labels!(bool),
        (TypeChar::Uint, 1, _) => labels!(u8),
        (TypeChar::Uint, 2, _) => labels!(u16),
        (TypeChar::Uint, 4, _) => labels!(u32),
        (TypeChar::Uint, 8, _) => labels!(u64),
        (TypeChar::Int, 1, _) => labels!(i8),
        (TypeChar::Int, 2, _) => labels!(i16),
        (TypeChar::Int, 4, _) => labels!(i32),
        (TypeChar::Int, 8, _) => labels!(i64),
        _ => {
            return Err(Error::Dtype {
                path: path.display().to_string(),
                dtype: dtype_name(&npy),
                expected: RULE,
            });
        }
    };
    gt.map_err(|e| Error::InFile {
        path: path.display().to_string(),
        error: Box::new(e),
    })
}

/// Read hard ground truth, and soft ground truth if given, into one [`GroundTruth`].
///
/// `hard` may be an `.npy` file or an `.npz` archive in the VPR_Tutorial convention
/// (`GThard`, optional `GTsoft`); an explicit `soft` file takes precedence over `GTsoft`.
/// The result is in the files' orientation, as are the positions in its errors.
///
/// # Errors
/// As [`read_scores`](crate::files::npy::read_scores) (with bool/integer in place of float), an
/// `.npz` without `GThard`, and [`Error::InFile`] around [`Error::BadLabel`] /
/// [`Error::ShapeMismatch`] for the labels.
pub fn read_ground_truth(hard: &Path, soft: Option<&Path>) -> Result<GroundTruth> {
    let gt = if is_npz(hard) {
        guarded(hard, || archive_ground_truth(&open_npz_file(hard)?, soft.is_none()))?
    } else {
        read_hard_ground_truth(hard)?
    };
    match soft {
        Some(path) => add_soft_ground_truth(gt, path),
        None => Ok(gt),
    }
}

/// Read hard ground truth only: an `.npy` file, or `GThard` of an `.npz` archive (its
/// `GTsoft`, if any, is not read). For a caller that has the soft ground truth elsewhere.
///
/// # Errors
/// As [`read_ground_truth`].
pub fn read_hard_ground_truth(path: &Path) -> Result<GroundTruth> {
    guarded(path, || {
        if is_npz(path) {
            archive_ground_truth(&open_npz_file(path)?, false)
        } else {
            ground_truth_of(parse(io::BufReader::new(open_file(path)?), path)?, path, None)
        }
    })
}

/// Add the soft ground truth of `.npy` file `path` to `hard` (entries soft but not hard
/// become ignored).
///
/// # Errors
/// As [`read_ground_truth`]; a shape other than `hard`'s is an [`Error::InFile`] around
/// [`Error::ShapeMismatch`].
pub fn add_soft_ground_truth(hard: GroundTruth, path: &Path) -> Result<GroundTruth> {
    guarded(path, || {
        ground_truth_of(parse(io::BufReader::new(open_file(path)?), path)?, path, Some(hard))
    })
}

fn is_npz(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"))
}

/// The ground truth of a VPR_Tutorial archive: `GThard`, with `GTsoft` added if
/// `with_soft` and the archive has it, and the record of its `labels` member if it has
/// one. Every array's header is read, and the matrices' shapes compared, before any data
/// is decompressed.
fn archive_ground_truth<R: ReaderAt>(npz: &Archive<R>, with_soft: bool) -> Result<GroundTruth> {
    let path = npz.path();
    let hard = npz_array(npz, HARD, Kind::Labels)?
        .ok_or_else(|| file_error(path, "has no array GThard (VPR_Tutorial convention: GThard, GTsoft)"))?;
    let soft = npz_array(npz, SOFT, Kind::Labels)?;
    let record = npz_array(npz, LABELS, Kind::Text)?;
    if let Some(soft) = &soft
        && soft.dims() != hard.dims()
    {
        return Err(Error::InFile {
            path: path.display().to_string(),
            error: Box::new(Error::ShapeMismatch {
                what: crate::error::names::Input::SoftGroundTruth,
                shape: soft.dims(),
                other: crate::error::names::Input::GroundTruth,
                other_shape: hard.dims(),
            }),
        });
    }
    let gt = ground_truth_of(hard.npy, &hard.label, None)?;
    let gt = match soft {
        Some(soft) if with_soft => ground_truth_of(soft.npy, &soft.label, Some(gt))?,
        _ => gt,
    };
    let record = match record {
        Some(member) => {
            let text = read_string(member.npy, &member.label)?;
            let value =
                serde_json::from_str(&text).map_err(|e| file_error(&member.label, format!("is not JSON: {e}")))?;
            let record = check_record(value).map_err(|why| {
                file_error(
                    &member.label,
                    format!("is not a record of self-motion labels: it {why}"),
                )
            })?;
            Some(record)
        }
        None => None,
    };
    npz.check_unread_members()?;
    Ok(gt.with_record(record))
}

/// Write ground truth as a VPR_Tutorial `.npz`, atomically: `GThard`, `GTsoft` if
/// given, and with a `record` of self-motion labels its member `labels` (semantics §16),
/// which [`read_ground_truth`] gives back with the labels. `np.load` reads every member.
///
/// # Errors
/// [`Error::Write`] naming `path`.
pub fn write_ground_truth(
    path: &Path,
    hard: ArrayView2<'_, bool>,
    soft: Option<ArrayView2<'_, bool>>,
    record: Option<&LabelRecord>,
) -> Result<()> {
    let mut arrays = vec![(HARD, NpyArray::Bool(hard))];
    arrays.extend(soft.map(|soft| (SOFT, NpyArray::Bool(soft))));
    arrays.extend(record.map(|r| (LABELS, NpyArray::Str(r.json()))));
    write_npz(path, &arrays)
}
