//! The embedded demo dataset: VPR-Bench Corridor scored by AMOSNet (see
//! `data/corridor/README.md` for attribution).
//!
//! The four `.npy` files of `data/corridor/` are compiled into the binary, so that
//! `qtvpr-cli evaluate` runs on real data with no file at hand. Calibration and
//! deployment halves are concatenated back into the 111 x 111 matrix they were cut
//! from; with the default protocol the first floor(10% of 111) = 11 queries
//! calibrate, which is exactly the split of the files.

use anyhow::{Context, Result};
use ndarray::{Array2, Axis, concatenate};
use qtvpr::npy::{ground_truth_from_bytes, scores_from_bytes};
use qtvpr::{GroundTruth, Score, with_scores};

/// What the table and figures call the embedded data.
pub const NAME: &str = "VPR-Bench Corridor, AMOSNet (embedded demo data)";

const CAL_S: &[u8] = include_bytes!("../../../data/corridor/cal_S.npy");
const CAL_GT: &[u8] = include_bytes!("../../../data/corridor/cal_GT.npy");
const DEPLOY_S: &[u8] = include_bytes!("../../../data/corridor/deploy_S.npy");
const DEPLOY_GT: &[u8] = include_bytes!("../../../data/corridor/deploy_GT.npy");

/// One embedded similarity matrix, read by the core's checked reader, in float64.
fn scores(name: &str, bytes: &[u8]) -> Result<Array2<f64>> {
    let s = scores_from_bytes(bytes, name).with_context(|| format!("embedded {name}"))?;
    Ok(with_scores!(s.view(), |v| v.mapv(Score::to_f64)))
}

/// One embedded ground truth, read by the core's checked reader.
fn ground_truth(name: &str, bytes: &[u8]) -> Result<GroundTruth> {
    ground_truth_from_bytes(bytes, name).with_context(|| format!("embedded {name}"))
}

/// The 111 x 111 float64 similarity matrix (|DB| x |Q|) and its ground truth.
pub fn corridor() -> Result<(Array2<f64>, GroundTruth)> {
    let s = concatenate(
        Axis(1),
        &[
            scores("cal_S.npy", CAL_S)?.view(),
            scores("deploy_S.npy", DEPLOY_S)?.view(),
        ],
    )?;
    let (cal, deploy) = (
        ground_truth("cal_GT.npy", CAL_GT)?,
        ground_truth("deploy_GT.npy", DEPLOY_GT)?,
    );
    let gt = GroundTruth::from_truth(concatenate(Axis(1), &[cal.view(), deploy.view()])?);
    Ok((s, gt))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_corridor_matrix_is_whole() {
        let (s, gt) = super::corridor().unwrap();
        assert_eq!((s.dim(), gt.dim()), ((111, 111), (111, 111)));
        // Query j matches database images j-2 ..= j+2 (clipped): 5 per inner column.
        use qtvpr::Truth;
        let gt = gt.view();
        assert!(gt.column(50).iter().filter(|&&g| g == Truth::True).count() == 5);
        assert!(gt[[48, 50]] == Truth::True && gt[[52, 50]] == Truth::True);
        assert!(s.iter().all(|v| v.is_finite()));
    }
}
