//! Ground truth files: bool or integer 0/1 `.npy` files, and `.npz` archives in the
//! VPR_Tutorial convention (`GThard`, optional `GTsoft`).

use std::io::{self, Read};
use std::path::Path;

use npyz::npz::NpzArchive;
use npyz::{NpyFile, TypeChar};

use super::header::{MATRIX, dtype_name, parse, plain_dtype};
use super::npz::{NpzInput, open_npz_file};
use super::open::{file_error, open_file};
use super::read::read_matrix;
use crate::error::{Error, Result};
use crate::input::GroundTruth;

/// Array `name` of an `.npz` archive, if it has one, read through [`parse`].
fn npz_array<'a, R: Read + io::Seek>(
    npz: &'a mut NpzArchive<R>,
    name: &str,
    path: &Path,
) -> Result<Option<NpyFile<impl Read + 'a>>> {
    let zip = npz.zip_archive();
    let member = format!("{name}.npy");
    if !zip.file_names().any(|n| n == member) {
        return Ok(None);
    }
    let file = zip
        .by_name(&member)
        .map_err(|e| file_error(path, format!("cannot read {name}: {e}")))?;
    parse(file, path).map(Some)
}

/// Read hard ground truth from the bytes of a `.npy` file, as
/// [`scores_from_bytes`](crate::npy::scores_from_bytes).
///
/// # Errors
/// As [`read_hard_ground_truth`].
pub fn ground_truth_from_bytes(bytes: &[u8], name: &str) -> Result<GroundTruth> {
    let path = Path::new(name);
    ground_truth_of(parse(bytes, path)?, path, None)
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
/// As [`read_scores`](crate::npy::read_scores) (with bool/integer in place of float), an
/// `.npz` without `GThard`, and [`Error::InFile`] around [`Error::BadLabel`] /
/// [`Error::ShapeMismatch`] for the labels.
pub fn read_ground_truth(hard: &Path, soft: Option<&Path>) -> Result<GroundTruth> {
    let gt = if is_npz(hard) {
        let (gt, mut npz) = read_gthard(hard)?;
        if soft.is_none()
            && let Some(npy) = npz_array(&mut npz, "GTsoft", hard)?
        {
            return ground_truth_of(npy, hard, Some(gt));
        }
        gt
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
    if is_npz(path) {
        Ok(read_gthard(path)?.0)
    } else {
        ground_truth_of(parse(io::BufReader::new(open_file(path)?), path)?, path, None)
    }
}

/// Add the soft ground truth of `.npy` file `path` to `hard` (entries soft but not hard
/// become ignored).
///
/// # Errors
/// As [`read_ground_truth`]; a shape other than `hard`'s is an [`Error::InFile`] around
/// [`Error::ShapeMismatch`].
pub fn add_soft_ground_truth(hard: GroundTruth, path: &Path) -> Result<GroundTruth> {
    ground_truth_of(parse(io::BufReader::new(open_file(path)?), path)?, path, Some(hard))
}

fn is_npz(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"))
}

/// `GThard` of an `.npz` archive, and the archive (for its `GTsoft`).
fn read_gthard(path: &Path) -> Result<(GroundTruth, NpzArchive<NpzInput>)> {
    let mut npz = open_npz_file(path)?;
    let npy = npz_array(&mut npz, "GThard", path)?
        .ok_or_else(|| file_error(path, "has no array GThard (VPR_Tutorial convention: GThard, GTsoft)"))?;
    let gt = ground_truth_of(npy, path, None)?;
    Ok((gt, npz))
}
