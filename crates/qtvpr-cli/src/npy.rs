//! Reading `.npy` / `.npz` matrices (via npyz) into the types the core takes.
//!
//! Scores must be float32 or float64, ground truth bool or integer; C and Fortran order
//! are both read without reordering (Fortran becomes a column-major ndarray). Every
//! error names the file and says what is wrong with it.

use std::fs::File;
use std::io::{self, BufReader, Read};
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use ndarray::{Array2, ShapeBuilder};
use npyz::npz::NpzArchive;
use npyz::{DType, NpyFile, Order, TypeChar};
use qtvpr::GroundTruth;

/// A similarity matrix as read: float32 or float64.
pub enum Scores {
    /// float32 scores.
    F32(Array2<f32>),
    /// float64 scores.
    F64(Array2<f64>),
}

/// Call `$body` with `$v` bound to an `ArrayView2` of the scores, whatever their type.
macro_rules! with_view {
    ($scores:expr, |$v:ident| $body:expr) => {
        match $scores {
            $crate::npy::Scores::F32(a) => {
                let $v = a.view();
                $body
            }
            $crate::npy::Scores::F64(a) => {
                let $v = a.view();
                $body
            }
        }
    };
}
pub(crate) use with_view;

impl Scores {
    /// Transpose (no copy): query-major input becomes |DB| x |Q|.
    pub fn reversed_axes(self) -> Self {
        match self {
            Scores::F32(a) => Scores::F32(a.reversed_axes()),
            Scores::F64(a) => Scores::F64(a.reversed_axes()),
        }
    }

    /// Shape (rows, columns).
    pub fn dim(&self) -> (usize, usize) {
        with_view!(self, |v| v.dim())
    }
}

fn open(path: &Path) -> Result<NpyFile<BufReader<File>>> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    if file.metadata().is_ok_and(|m| m.is_dir()) {
        bail!("{} is a directory, not a .npy file", path.display());
    }
    NpyFile::new(BufReader::new(file)).map_err(|e| {
        // Header parse errors span several lines; the first says what is wrong.
        let e = e.to_string();
        anyhow!(
            "{} is not a valid .npy file: {}",
            path.display(),
            e.lines().next().unwrap_or_default().trim()
        )
    })
}

fn dtype_of<R: Read>(npy: &NpyFile<R>, path: &Path) -> Result<(TypeChar, u64)> {
    match npy.dtype() {
        DType::Plain(ts) => Ok((ts.type_char(), ts.size_field())),
        other => bail!(
            "{} has a structured dtype ({}), expected a plain numeric matrix",
            path.display(),
            other.descr()
        ),
    }
}

/// The dtype as NumPy spells it, e.g. `<c16`.
fn dtype_name<R: Read>(npy: &NpyFile<R>) -> String {
    match npy.dtype() {
        DType::Plain(ts) => ts.to_string().replace('\'', ""),
        other => other.descr(),
    }
}

fn read_matrix<T: npyz::Deserialize, R: Read>(npy: NpyFile<R>, path: &Path) -> Result<Array2<T>> {
    let shape = npy.shape().to_vec();
    let [rows, cols] = shape[..] else {
        bail!(
            "{} holds a {}-D array of shape {:?}, expected a 2-D matrix",
            path.display(),
            shape.len(),
            shape
        );
    };
    let (rows, cols) = (rows as usize, cols as usize);
    let order = npy.order();
    let data: Vec<T> = npy
        .into_vec()
        .map_err(|e| anyhow!("{} is truncated or corrupt: {e}", path.display()))?;
    let shape = match order {
        Order::C => (rows, cols).into_shape_with_order(),
        Order::Fortran => (rows, cols).f(),
    };
    Array2::from_shape_vec(shape, data).map_err(|_| {
        anyhow!(
            "{} holds fewer values than its shape {rows}x{cols} says",
            path.display()
        )
    })
}

/// Read a float32/float64 similarity matrix.
pub fn read_scores(path: &Path) -> Result<Scores> {
    let npy = open(path)?;
    match dtype_of(&npy, path)? {
        (TypeChar::Float, 4) => Ok(Scores::F32(read_matrix(npy, path)?)),
        (TypeChar::Float, 8) => Ok(Scores::F64(read_matrix(npy, path)?)),
        _ => bail!(
            "{} has dtype {}; similarity scores must be float32 or float64",
            path.display(),
            dtype_name(&npy)
        ),
    }
}

fn gt_from<R: Read>(npy: NpyFile<R>, path: &Path, soft: Option<GroundTruth>) -> Result<GroundTruth> {
    macro_rules! labels {
        ($t:ty) => {{
            let m = read_matrix::<$t, R>(npy, path)?;
            match soft {
                None => GroundTruth::new(m.view()),
                Some(hard) => hard.with_soft(m.view()),
            }
        }};
    }
    let gt = match dtype_of(&npy, path)? {
        (TypeChar::Bool, _) => labels!(bool),
        (TypeChar::Uint, 1) => labels!(u8),
        (TypeChar::Uint, 2) => labels!(u16),
        (TypeChar::Uint, 4) => labels!(u32),
        (TypeChar::Uint, 8) => labels!(u64),
        (TypeChar::Int, 1) => labels!(i8),
        (TypeChar::Int, 2) => labels!(i16),
        (TypeChar::Int, 4) => labels!(i32),
        (TypeChar::Int, 8) => labels!(i64),
        _ => bail!(
            "{} has dtype {}; ground truth must be bool or integer 0/1",
            path.display(),
            dtype_name(&npy)
        ),
    };
    gt.with_context(|| path.display().to_string())
}

/// Read hard ground truth, and soft ground truth if given, into one [`GroundTruth`].
///
/// `hard` may be an `.npy` file or an `.npz` archive in the VPR_Tutorial convention
/// (`GThard`, optional `GTsoft`); an explicit `soft` file takes precedence over `GTsoft`.
pub fn read_ground_truth(hard: &Path, soft: Option<&Path>) -> Result<GroundTruth> {
    let is_npz = hard.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let gt = if is_npz {
        let mut npz = NpzArchive::open(hard).map_err(|e| open_error(hard, e, ".npz archive"))?;
        let npy = npz
            .by_name("GThard")
            .map_err(|e| anyhow!("{}: cannot read GThard: {e}", hard.display()))?
            .ok_or_else(|| {
                anyhow!(
                    "{} has no array GThard (VPR_Tutorial convention: GThard, GTsoft)",
                    hard.display()
                )
            })?;
        let gt = gt_from(npy, hard, None)?;
        match (soft, npz.by_name("GTsoft")) {
            (None, Ok(Some(npy))) => return gt_from(npy, hard, Some(gt)),
            (None, Err(e)) => bail!("{}: cannot read GTsoft: {e}", hard.display()),
            _ => gt,
        }
    } else {
        gt_from(open(hard)?, hard, None)?
    };
    match soft {
        Some(path) => gt_from(open(path)?, path, Some(gt)),
        None => Ok(gt),
    }
}

fn open_error(path: &Path, e: io::Error, what: &str) -> anyhow::Error {
    match e.kind() {
        io::ErrorKind::NotFound => anyhow!("cannot open {}: {e}", path.display()),
        _ if path.is_dir() => anyhow!("{} is a directory, not a {what}", path.display()),
        _ => anyhow!("{} is not a valid {what}: {e}", path.display()),
    }
}
