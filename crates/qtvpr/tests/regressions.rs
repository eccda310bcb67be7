//! Regression tests for inputs that fuzzing (fuzz/, see the README) or its review found
//! to break an invariant. Each test says what broke.

use ndarray::array;
use qtvpr::{Calibration, GroundTruth, Matching, Params};

/// Scores near +-f64::MAX: the interpolation `x_lo + f * (x_hi - x_lo)` overflowed
/// (x_hi - x_lo = inf) and gave an infinite segment threshold.
#[test]
fn interpolating_between_huge_scores_stays_finite() {
    // Calibration query [2, 1, 0] with hard GT rows 0 and 1, multi mode, tau = 1: the
    // threshold is 1 (the lowest correct score above the highest false one, 0); sample
    // {2, 1, 0}: c = 2, q = (2 - 1) / (3 - 1) = 0.5.
    let s_cal = array![[2.0], [1.0], [0.0]];
    let gt = GroundTruth::new(array![[true], [true], [false]].view()).unwrap();
    let cal = Calibration::new(s_cal.view(), &gt, Matching::Multi).unwrap();
    // Both deployment queries get q = 0.5. Their scores ascending are
    // [-M, -M, -M, M, M, M] (M = 1e308): h = 5 * 0.5 = 2.5, between x[2] = -M and
    // x[3] = M, so the threshold is -M + 0.5 * 2M = 0.
    // The same at f64::MAX itself.
    for m in [1e308, f64::MAX] {
        let s_val = array![[m, m], [m, -m], [-m, -m]];
        let out = cal
            .transfer(
                s_val.view(),
                &Params {
                    k: 1,
                    ..Params::default()
                },
            )
            .unwrap();
        assert_eq!(out.segments[0].quantile, 0.5, "{m}");
        assert_eq!(out.segments[0].threshold, 0.0, "{m}");
    }
}
