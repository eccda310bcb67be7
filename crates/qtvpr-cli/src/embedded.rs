//! The embedded demo dataset: VPR-Bench Corridor scored by AMOSNet (see
//! `data/corridor/README.md` for attribution).
//!
//! The four `.npy` files of `data/corridor/` are compiled into the binary, so that
//! `qtvpr-cli evaluate` runs on real data with no file at hand. Calibration and
//! deployment halves are concatenated back into the 111 x 111 matrix they were cut
//! from; with the default protocol the first floor(10% of 111) = 11 queries
//! calibrate, which is exactly the split of the files.

use anyhow::{Context, Result};
use ndarray::{Array2, Axis, ShapeBuilder, concatenate};
use npyz::{NpyFile, Order};

/// What the table and figures call the embedded data.
pub const NAME: &str = "VPR-Bench Corridor, AMOSNet (embedded demo data)";

const CAL_S: &[u8] = include_bytes!("../../../data/corridor/cal_S.npy");
const CAL_GT: &[u8] = include_bytes!("../../../data/corridor/cal_GT.npy");
const DEPLOY_S: &[u8] = include_bytes!("../../../data/corridor/deploy_S.npy");
const DEPLOY_GT: &[u8] = include_bytes!("../../../data/corridor/deploy_GT.npy");

fn matrix<T: npyz::Deserialize>(name: &str, bytes: &[u8]) -> Result<Array2<T>> {
    let npy = NpyFile::new(bytes).with_context(|| format!("embedded {name}"))?;
    let shape = npy.shape().to_vec();
    let order = npy.order();
    let data: Vec<T> = npy.into_vec().with_context(|| format!("embedded {name}"))?;
    let (rows, cols) = (shape[0] as usize, shape[1] as usize);
    let shape = match order {
        Order::C => (rows, cols).into_shape_with_order(),
        Order::Fortran => (rows, cols).f(),
    };
    Ok(Array2::from_shape_vec(shape, data)?)
}

/// The 111 x 111 float64 similarity matrix (|DB| x |Q|) and its bool ground truth.
pub fn corridor() -> Result<(Array2<f64>, Array2<bool>)> {
    let s = concatenate(
        Axis(1),
        &[
            matrix::<f64>("cal_S.npy", CAL_S)?.view(),
            matrix::<f64>("deploy_S.npy", DEPLOY_S)?.view(),
        ],
    )?;
    let gt = concatenate(
        Axis(1),
        &[
            matrix::<bool>("cal_GT.npy", CAL_GT)?.view(),
            matrix::<bool>("deploy_GT.npy", DEPLOY_GT)?.view(),
        ],
    )?;
    Ok((s, gt))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_corridor_matrix_is_whole() {
        let (s, gt) = super::corridor().unwrap();
        assert_eq!((s.dim(), gt.dim()), ((111, 111), (111, 111)));
        // Query j matches database images j-2 ..= j+2 (clipped): 5 per inner column.
        assert!(gt.column(50).iter().filter(|&&g| g).count() == 5 && gt[[48, 50]] && gt[[52, 50]]);
        assert!(s.iter().all(|v| v.is_finite()));
    }
}
