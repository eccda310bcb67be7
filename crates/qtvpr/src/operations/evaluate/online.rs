//! semantics §11 in the protocol of §8: the online method, which decides every
//! deployment query at the threshold of its own causal window.

use std::ops::Range;
use std::sync::Arc;

use ndarray::ArrayView2;

use super::protocol::Protocol;
use super::results::{EPS, SegmentResult};
use crate::error::Result;
use crate::input::Score;
use crate::input::params::{Gate, OnlineParams};
use crate::operations::calibration::Calibration;
use crate::operations::online::Online;
use crate::rules::decisions::Candidates;

/// Online quantile transfer in the protocol (semantics §11): one window of the
/// segment size over the deployment queries (not reset at segment boundaries); every
/// query decided at its own threshold; a segment's counts are the sums over its
/// queries, and its threshold that of its last query.
pub(super) fn online_segments<T: Score>(
    cal: &Arc<Calibration>,
    s_dep: ArrayView2<'_, T>,
    deployment: &Candidates,
    ranges: &[Range<usize>],
    oracle: &[f64],
    protocol: &Protocol,
) -> Result<Vec<SegmentResult>> {
    let params = OnlineParams {
        k: protocol.k,
        precision: protocol.precision,
        window: ranges[0].len(),
        min_window: 1,
        gate: Gate::None,
        sequence_gate: protocol.sequence_gate,
    };
    let decisions = Online::new(Arc::clone(cal), params)?.push_many(s_dep)?;
    let segments = ranges
        .iter()
        .zip(oracle)
        .map(|(r, &oracle_threshold)| {
            let counts = r
                .clone()
                .map(|j| deployment.counts(j..j + 1, decisions[j].threshold))
                .sum();
            SegmentResult {
                start: r.start,
                end: r.end,
                threshold: decisions[r.end - 1].threshold,
                oracle_threshold,
                gate: None,
                consistency_level: None,
                counts,
                meets: counts.precision() >= protocol.precision - EPS,
            }
        })
        .collect();
    Ok(segments)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::GroundTruth;
    use crate::operations::evaluate::evaluate;
    use crate::operations::evaluate::protocol::{Method, Split};
    use crate::operations::evaluate::tests::run;
    use crate::rules::decisions::Matching;
    use ndarray::{Array2, s};

    #[test]
    fn quantile_transfer_online_per_query() {
        // Every query's subset is {c0, c1} (k clipped to 2): q = 4/5, as above. Window 2,
        // over the deployment queries only:
        // d0: {d0} ascending (0.2, 0.3, 0.7): h = 2 * 0.8 = 1.6 -> 0.3 + 0.6 * 0.4 = 0.54;
        //     its best 0.7 (T) is accepted.
        // d1: {d0, d1} (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): h = 4 -> 0.6; best 0.6 (F) accepted.
        // Segment 0: TP 1, FP 1, positives 2: precision 1/2 meets, recall 1/2; its
        //     threshold is d1's, 0.6.
        // d2: {d1, d2} (0.1, 0.3, 0.4, 0.5, 0.5, 0.6) -> 0.5: best 0.5 (F) accepted.
        // d3: {d2, d3} (0.1, 0.2, 0.3, 0.4, 0.5, 0.9) -> 0.5: best 0.9 (F) accepted.
        // Segment 1: FP 2, no positives: skipped. %Segs 100, AvgR 0.5, MSE (0.6 - 0.7)^2.
        let e = run(&[Method::QuantileTransferOnline]);
        let o = &e.methods[0];
        assert_eq!(o.method.as_str(), "quantile-transfer-online");
        let t: Vec<f64> = o.segments.iter().map(|g| g.threshold).collect();
        assert!((t[0] - 0.6).abs() < 1e-15 && (t[1] - 0.5).abs() < 1e-15, "{t:?}");
        let c: Vec<(usize, usize, usize)> = o
            .segments
            .iter()
            .map(|g| (g.counts.tp, g.counts.fp, g.counts.positives))
            .collect();
        assert_eq!(c, vec![(1, 1, 2), (0, 2, 0)]);
        assert_eq!((o.pct_segs, o.avg_recall), (Some(100.0), Some(0.5)));
        assert_eq!((o.segments_counted, o.segments_skipped), (1, 1));
        assert!((o.threshold_mse.unwrap() - 0.01).abs() < 1e-15);
    }

    #[test]
    fn quantile_transfer_online_is_online_over_the_deployment_queries() {
        // A fixed LCG matrix of 8 x 50: 5 calibration queries, segments of 6 from column 8
        // (columns 5..8 unused, deploy fraction 0.84): 7 full segments, 42 queries.
        let mut x = 7u64;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 100) as f64 / 100.0
        };
        let s = Array2::from_shape_fn((8, 50), |_| next());
        let gt = GroundTruth::new(Array2::from_shape_fn((8, 50), |(i, j)| i == j % 8).view()).unwrap();
        for matching in [Matching::Single, Matching::Multi] {
            let p = Protocol {
                calibration: Split::Count(5),
                deploy_fraction: Some(0.84),
                segment: Split::Count(6),
                k: 3,
                precision: 0.9,
                matching,
                ..Protocol::default()
            };
            let e = evaluate(s.view(), &gt, &p, &[Method::QuantileTransferOnline]).unwrap();
            assert_eq!((e.layout.deployment_start, e.layout.segments), (8, 7));
            let cal = Calibration::new(
                s.slice(s![.., ..5]),
                &GroundTruth::from_truth(gt.view().slice(s![.., ..5]).to_owned()),
                matching,
            )
            .unwrap();
            let params = OnlineParams {
                k: 3,
                precision: 0.9,
                window: 6,
                min_window: 1,
                gate: Gate::None,
                sequence_gate: Default::default(),
            };
            let decisions = Online::new(Arc::new(cal), params)
                .unwrap()
                .push_many(s.slice(s![.., 8..50]))
                .unwrap();
            for (g, segment) in e.methods[0].segments.iter().zip(0..) {
                let queries = &decisions[6 * segment..6 * (segment + 1)];
                assert_eq!(g.threshold.to_bits(), queries[5].threshold.to_bits());
                // Counts by hand from the decisions and the ground truth.
                let (mut tp, mut fp, mut positives) = (0, 0, 0);
                for d in queries {
                    let col = 8 + d.query;
                    positives += 1; // every column has its match, row j % 8
                    match matching {
                        Matching::Single => {
                            if d.accept() {
                                if d.best == col % 8 { tp += 1 } else { fp += 1 }
                            }
                        }
                        Matching::Multi => {
                            let hit = usize::from(s[[col % 8, col]] >= d.threshold);
                            tp += hit;
                            fp += d.accepted - hit;
                        }
                    }
                }
                assert_eq!(
                    (g.counts.tp, g.counts.fp, g.counts.positives),
                    (tp, fp, positives),
                    "{matching:?} {segment}"
                );
            }
        }
    }
}
