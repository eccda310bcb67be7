//! Writing the results of the `similarity`, `ground-truth` and `calibrate` commands:
//! the core's atomic writers ([`qtvpr::npy::write_npy`], [`qtvpr::npy::write_npz`]),
//! with the option that named the file in their errors.
//!
//! Reading is the core's ([`qtvpr::npy`]): every file the CLI opens goes through its
//! checked reader.

use std::path::Path;

use anyhow::{Context, Result};
use ndarray::ArrayView2;
use qtvpr::npy::NpyArray;

/// Write `m` as a C-order `.npy` file (`<f4`, `<f8` or `|b1`), atomically; `flag`
/// names the option in errors.
pub fn write_npy<'a>(path: &Path, flag: &str, m: impl Into<NpyArray<'a>>) -> Result<()> {
    qtvpr::npy::write_npy(path, m).with_context(|| flag.to_string())
}

/// Write bool matrices into one `.npz` archive (a VPR_Tutorial `GThard`/`GTsoft` file),
/// atomically.
pub fn write_npz(path: &Path, flag: &str, arrays: &[(&str, ArrayView2<'_, bool>)]) -> Result<()> {
    let arrays: Vec<(&str, NpyArray<'_>)> = arrays.iter().map(|&(n, m)| (n, NpyArray::Bool(m))).collect();
    qtvpr::npy::write_npz(path, &arrays).with_context(|| flag.to_string())
}
