//! Criterion benches of the core's stages at the size of the real Nordland HOG case
//! (3576 database places, 357 calibration and 3219 deployment queries, f32 scores).
//!
//! The scores are synthetic (a fixed LCG with a diagonal match) so that the bench needs no
//! files; `benches/compare.py` at the repository root measures the real data end to end.
//! Stages are timed through the public API:
//! - `rank/…`: ranking profiles alone: gather, check, sort and standardise
//!   ([`ranked_correlation`] against a single calibration column, so the correlations
//!   are negligible);
//! - `ranked_correlation/…`: ranking plus every correlation exactly in `f64` (what the
//!   transfer avoids: its block-bound screen computes only about `k` per query);
//! - `calibrate`: [`Calibration::new`] (ranked calibration profiles and candidates);
//! - `transfer/…`: the whole transfer (neighbours, subset thresholds, segment quantiles);
//! - `segment_quantile`: one segment's deployment threshold ([`deployment_threshold`]);
//! - `best_threshold/…`: the exact sweep of a whole matrix.

use criterion::{Criterion, criterion_group, criterion_main};
use ndarray::{Array2, s};
use qtvpr::deployment_threshold;
use qtvpr::{Calibration, GroundTruth, Matching, Params, best_threshold, ranked_correlation};
use std::hint::black_box;

const N: usize = 3576;

fn scores() -> Array2<f32> {
    let mut x = 7u64;
    Array2::from_shape_fn((N, N), |(i, j)| {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let noise = (x >> 40) as f32 / (1u64 << 24) as f32;
        let d = (i as f32 - j as f32).abs();
        0.2 * noise + 0.5 * (-d / 3.0).exp() + 0.1 * (j as f32 / N as f32)
    })
}

fn stages(c: &mut Criterion) {
    let s = scores();
    let gt = Array2::from_shape_fn((N, N), |(i, j)| i.abs_diff(j) <= 1);
    let n_cal = N / 10;
    let (s_cal, s_val) = (s.slice(s![.., ..n_cal]), s.slice(s![.., n_cal..]));
    let gt_cal = GroundTruth::new(gt.slice(s![.., ..n_cal])).unwrap();
    let mut g = c.benchmark_group("nordland-size");
    g.sample_size(10);
    g.bench_function("rank/deployment", |b| {
        b.iter(|| ranked_correlation(s_val, s_cal.slice(s![.., ..1])).unwrap())
    });
    g.bench_function("ranked_correlation/deployment", |b| {
        b.iter(|| ranked_correlation(s_val, s_cal).unwrap())
    });
    g.bench_function("calibrate", |b| {
        b.iter(|| Calibration::new(s_cal, &gt_cal, Matching::Single).unwrap())
    });
    for matching in [Matching::Single, Matching::Multi] {
        let cal = Calibration::new(s_cal, &gt_cal, matching).unwrap();
        for precision in [1.0, 0.9] {
            let p = Params {
                k: 10,
                precision,
                segment_size: Some(36),
                ..Params::default()
            };
            g.bench_function(format!("transfer/{}/tau={precision}", matching.as_str()), |b| {
                b.iter(|| cal.transfer(s_val, &p).unwrap())
            });
        }
    }
    let segment = s_val.slice(s![.., ..36]);
    g.bench_function("segment_quantile", |b| {
        b.iter(|| deployment_threshold(segment, black_box(0.999)))
    });
    let gt_all = GroundTruth::new(gt.view()).unwrap();
    for matching in [Matching::Single, Matching::Multi] {
        g.bench_function(format!("best_threshold/{}", matching.as_str()), |b| {
            b.iter(|| best_threshold(s.view(), &gt_all, matching, 0.9).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, stages);
criterion_main!(benches);
