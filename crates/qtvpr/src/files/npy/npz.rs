//! The arrays of an `.npz` archive (a calibration file, a VPR_Tutorial ground truth):
//! each member's `.npy` header read first, through the checked zip layer
//! ([`Archive`]), and checked (dtype, rank, the size the zip directory declares)
//! before any of its data is decompressed; then read as a matrix or a string.

use std::io::{self, BufReader, Cursor, Read};
use std::path::{Path, PathBuf};

use npyz::{DType, NpyFile, TypeChar};
use rawzip::ReaderAt;

use super::archive::{Archive, Member, member_label};
use super::header::{MATRIX, dtype_name, parse_header, plain_dtype, read_header, shape_2d, too_large};
use super::open::file_error;
use super::read::read_matrix;
use crate::error::{Error, Result};

/// The longest 0-d string member an archive may have: a calibration file's `meta`, a
/// ground truth's `labels` (their JSON is a few hundred bytes).
const MAX_TEXT_BYTES: u64 = 1 << 20;

/// What an array of an archive must be; its header is held to it before its data is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    /// A float32/float64 matrix.
    Scores,
    /// A bool matrix.
    Bool,
    /// A bool or integer matrix (ground truth, whose values are checked as read).
    Labels,
    /// A 0-d unicode string (a calibration's `meta`, a ground truth's `labels`).
    Text,
}

impl Kind {
    /// What the dtype must be, for errors.
    const fn rule(self) -> &'static str {
        match self {
            Kind::Scores => "expected float32 or float64 similarity scores",
            Kind::Bool => "expected bool",
            Kind::Labels => "expected bool or integer 0/1 ground truth",
            Kind::Text => "expected a 0-d unicode string",
        }
    }

    fn takes(self, kind: TypeChar, size: u64) -> bool {
        match self {
            Kind::Scores => kind == TypeChar::Float && matches!(size, 4 | 8),
            Kind::Bool => kind == TypeChar::Bool,
            Kind::Labels => {
                kind == TypeChar::Bool
                    || (matches!(kind, TypeChar::Int | TypeChar::Uint) && matches!(size, 1 | 2 | 4 | 8))
            }
            Kind::Text => kind == TypeChar::UnicodeStr,
        }
    }
}

/// The decompressed stream of a member after its header (buffered: npyz reads value by
/// value).
pub(crate) type MemberData<'a, R> = io::Chain<Cursor<Vec<u8>>, BufReader<Member<'a, R>>>;

/// An array of an archive whose header has been checked, its data not yet read.
pub(crate) struct NpzArray<'a, R: ReaderAt> {
    /// The array, ready to be read.
    pub npy: NpyFile<MemberData<'a, R>>,
    /// `FILE (array NAME)`, for errors.
    pub label: PathBuf,
}

impl<R: ReaderAt> NpzArray<'_, R> {
    /// The shape of a 2-D array (checked when the header was read).
    pub(crate) fn dims(&self) -> (usize, usize) {
        match self.npy.shape() {
            &[r, c] => (r as usize, c as usize),
            _ => (0, 0),
        }
    }
}

/// Array `name` of `archive`, if it has one: its member's `.npy` header read and held
/// to `kind` (dtype, and 2-D or 0-d), and the size that header declares compared with
/// the zip directory's, so that a member that cannot be this array costs no more than
/// its header; none of its data is decompressed.
///
/// # Errors
/// [`Error::File`] / [`Error::Dtype`] naming the file and the array.
pub(crate) fn npz_array<'a, R: ReaderAt>(
    archive: &'a Archive<R>,
    name: &str,
    kind: Kind,
) -> Result<Option<NpzArray<'a, R>>> {
    let member = format!("{name}.npy");
    let label = member_label(archive.path(), &member);
    let Some((stream, size)) = archive.member(&member)? else {
        return Ok(None);
    };
    let mut stream = BufReader::new(stream);
    let header = read_header(&mut stream, &label)?;
    let header_len = header.len() as u64;
    let npy = parse_header(header, stream, &label)?;
    let takes = |npy: &NpyFile<_>| matches!(npy.dtype(), DType::Plain(t) if kind.takes(t.type_char(), t.size_field()));
    if kind == Kind::Text {
        if !takes(&npy) || !npy.shape().is_empty() {
            return Err(not_a_string(&npy, &label));
        }
    } else if !takes(&npy) {
        return Err(Error::Dtype {
            path: label.display().to_string(),
            dtype: dtype_name(&npy),
            expected: kind.rule(),
        });
    } else {
        shape_2d(&npy, &label, MATRIX)?;
    }
    let claim = npy.dtype().num_bytes().and_then(|item| {
        npy.shape()
            .iter()
            .try_fold(item as u64, |n, &d| n.checked_mul(d))
            .and_then(|n| n.checked_add(header_len))
    });
    match claim {
        Some(claim) if claim == size => {}
        Some(claim) => {
            return Err(file_error(
                &label,
                format!(
                    "is corrupt: the zip directory says it holds {size} bytes, its .npy header \
                     declares {claim}"
                ),
            ));
        }
        None => return Err(too_large(&label, npy.shape())),
    }
    if kind == Kind::Text && size > MAX_TEXT_BYTES {
        return Err(file_error(
            &label,
            format!(
                "is {size} bytes; a string of JSON (a calibration's meta, a ground truth's labels) is under {MAX_TEXT_BYTES}"
            ),
        ));
    }
    Ok(Some(NpzArray { npy, label }))
}

/// A float32/float64 matrix read into memory from `npy` (`path` names it).
pub(crate) fn read_owned_scores<R: Read>(npy: NpyFile<R>, path: &Path) -> Result<crate::input::ScoreMatrix> {
    use crate::input::ScoreMatrix;
    const RULE: &str = Kind::Scores.rule();
    match plain_dtype(&npy, path, RULE)? {
        (TypeChar::Float, 4, _) => Ok(ScoreMatrix::F32(read_matrix(npy, path, MATRIX)?.into_array())),
        (TypeChar::Float, 8, _) => Ok(ScoreMatrix::F64(read_matrix(npy, path, MATRIX)?.into_array())),
        _ => Err(Error::Dtype {
            path: path.display().to_string(),
            dtype: dtype_name(&npy),
            expected: RULE,
        }),
    }
}

/// A bool matrix read from `npy` (`path` names it); other dtypes are refused.
pub(crate) fn read_bool_matrix<R: Read>(npy: NpyFile<R>, path: &Path) -> Result<ndarray::Array2<bool>> {
    const RULE: &str = Kind::Bool.rule();
    match plain_dtype(&npy, path, RULE)? {
        (TypeChar::Bool, 1, _) => Ok(read_matrix(npy, path, MATRIX)?.into_array()),
        _ => Err(Error::Dtype {
            path: path.display().to_string(),
            dtype: dtype_name(&npy),
            expected: RULE,
        }),
    }
}

/// The 0-d unicode string of `npy` (its header held to [`Kind::Text`] by [`npz_array`];
/// `path` names it).
pub(crate) fn read_string<R: Read>(npy: NpyFile<R>, path: &Path) -> Result<String> {
    let mut values: Vec<String> = npy
        .into_vec()
        .map_err(|e| file_error(path, format!("is truncated or corrupt: {e}")))?;
    match values.len() {
        1 => Ok(values.pop().expect("one value")),
        _ => Err(file_error(path, "is truncated or corrupt: a 0-d array holds one value")),
    }
}

fn not_a_string<R: Read>(npy: &NpyFile<R>, path: &Path) -> Error {
    file_error(
        path,
        format!(
            "holds an array of dtype {} and shape {:?}, expected a 0-d unicode string",
            dtype_name(npy),
            npy.shape()
        ),
    )
}
