//! Property tests of invariants of the semantics on small random matrices (proptest, fixed seed).
//!
//! What is invariant under what, precisely:
//!
//! - **Permuting database rows** (the same permutation of the rows of S_cal, GT_cal and
//!   S_val) changes nothing: ranked profiles are sorted, so correlations, neighbours
//!   and weights are bit-for-bit the same; multi-mode candidates are a multiset; every
//!   quantile is of a multiset of scores. In single mode the best match is the *first*
//!   maximum of its column, so the property holds only when no column's maximum is
//!   tied (a permutation may reorder tied maxima); the generator makes them unique.
//! - **A strictly increasing transform f of every score** keeps every order, so it keeps
//!   best matches, candidates, decisions, hence `best_threshold(f(S)) = f(best_threshold(S))`,
//!   `counts(f(S), f(t)) = counts(S, t)`, subset thresholds `t_j' = f(t_j)` and subset
//!   quantiles `q_j' = q_j` *for the same neighbours*. It does **not** keep the
//!   correlations (Pearson correlation of sorted profiles is not rank-based), so
//!   neighbours and weights may change; the test fixes the neighbours by taking
//!   k >= |Qcal|. The segment quantile is then unchanged, and the segment threshold,
//!   an interpolation between two adjacent order statistics, makes the same decisions
//!   (accepts the same deployment entries) unless the interpolation weight is within
//!   rounding of 0.
//! - **A positive affine transform a*s + b** keeps the correlations (up to rounding:
//!   checked to 1e-9), and with a a power of two and b = 0 keeps them bit for bit, so
//!   that neighbours, weights and quantiles are unchanged and every threshold is scaled
//!   by a exactly.
//! - **Raising tau** never raises the recall of `best_threshold`.
//! - **The oracle** (`best_threshold` of a segment with its own ground truth) always
//!   meets tau on that segment, or rejects all.

use ndarray::{Array2, ArrayView2, Axis};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use qtvpr::{
    Calibration, Counts, Gate, GroundTruth, Matching, Params, Transfer, Truth, best_threshold, counts,
    ranked_correlation,
};

/// Deterministic: a fixed seed, no persistence files, a bounded number of cases.
fn config(cases: u32) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(0x5eed_0006),
        failure_persistence: None,
        ..Config::default()
    }
}

/// One small problem: calibration and deployment scores over the same database.
#[derive(Debug, Clone)]
struct Problem {
    s_cal: Array2<f64>,
    gt: GroundTruth,
    s_val: Array2<f64>,
    matching: Matching,
    tau: f64,
    k: usize,
    segment_size: Option<usize>,
}

impl Problem {
    fn params(&self) -> Params {
        Params {
            k: self.k,
            precision: self.tau,
            segment_size: self.segment_size,
            gate: Gate::None,
            sequence_gate: Default::default(),
        }
    }

    fn transfer(&self) -> Transfer {
        Calibration::new(self.s_cal.view(), &self.gt, self.matching)
            .unwrap()
            .transfer(self.s_val.view(), &self.params())
            .unwrap()
    }
}

/// Integer scores in -4..=4 (many ties), as f64. In single mode each column's maximum
/// is made unique (the first maximum gets +0.5) so that row permutations keep best matches.
fn scores(n_db: usize, n: usize, unique_max: bool) -> impl Strategy<Value = Array2<f64>> {
    proptest::collection::vec(-4i8..=4, n_db * n).prop_map(move |v| {
        let mut s = Array2::from_shape_fn((n_db, n), |(i, j)| f64::from(v[j * n_db + i]));
        if unique_max {
            for mut col in s.columns_mut() {
                let max = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let first = col.iter().position(|&x| x == max).unwrap();
                col[first] += 0.5;
            }
        }
        s
    })
}

fn ground_truth(n_db: usize, n: usize) -> impl Strategy<Value = GroundTruth> {
    // 0, 1: false; 2: true; 3: soft only (ignored).
    proptest::collection::vec(0u8..4, n_db * n).prop_map(move |v| {
        GroundTruth::from_truth(Array2::from_shape_fn((n_db, n), |(i, j)| match v[j * n_db + i] {
            2 => Truth::True,
            3 => Truth::Ignored,
            _ => Truth::False,
        }))
    })
}

const TAUS: [f64; 5] = [1.0, 0.9, 0.75, 0.6, 0.5];

fn problem(unique_max_in_single: bool) -> impl Strategy<Value = Problem> {
    (1usize..8, 1usize..6, 1usize..8, any::<bool>())
        .prop_flat_map(move |(n_db, n_cal, n_val, multi)| {
            let unique = unique_max_in_single && !multi;
            (
                scores(n_db, n_cal, unique),
                ground_truth(n_db, n_cal),
                scores(n_db, n_val, false),
                Just(multi),
                0..TAUS.len(),
                1usize..8,
                proptest::option::of(1..=n_val),
            )
        })
        .prop_map(|(s_cal, gt, s_val, multi, tau, k, segment_size)| Problem {
            s_cal,
            gt,
            s_val,
            matching: if multi { Matching::Multi } else { Matching::Single },
            tau: TAUS[tau],
            k,
            segment_size,
        })
}

fn permute_rows<T: Clone>(a: ArrayView2<'_, T>, perm: &[usize]) -> Array2<T> {
    a.select(Axis(0), perm)
}

fn meets(c: &Counts, tau: f64) -> bool {
    c.tp + c.fp == 0 || c.tp as f64 >= tau * (c.tp + c.fp) as f64 - 1e-12
}

proptest! {
    #![proptest_config(config(300))]

    #[test]
    fn permuting_database_rows_changes_nothing(p in problem(true), seed in any::<u64>()) {
        let n_db = p.s_cal.nrows();
        let mut perm: Vec<usize> = (0..n_db).collect();
        // A Fisher-Yates shuffle driven by the seed.
        let mut x = seed | 1;
        for i in (1..n_db).rev() {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            perm.swap(i, (x % (i as u64 + 1)) as usize);
        }
        let q = Problem {
            s_cal: permute_rows(p.s_cal.view(), &perm),
            gt: GroundTruth::from_truth(permute_rows(p.gt.view(), &perm)),
            s_val: permute_rows(p.s_val.view(), &perm),
            ..p.clone()
        };
        prop_assert_eq!(p.transfer(), q.transfer());
        let t = best_threshold(p.s_cal.view(), &p.gt, p.matching, p.tau).unwrap();
        prop_assert_eq!(t, best_threshold(q.s_cal.view(), &q.gt, q.matching, q.tau).unwrap());
        for t in [t, 0.0, 1.0] {
            prop_assert_eq!(
                counts(p.s_cal.view(), &p.gt, p.matching, t).unwrap(),
                counts(q.s_cal.view(), &q.gt, q.matching, t).unwrap()
            );
        }
    }

    #[test]
    fn a_strictly_increasing_transform_keeps_decisions(
        p in problem(false),
        steps in proptest::collection::vec(1u32..1000, 9),
        base in -50.0f64..50.0,
    ) {
        // f maps the 9 score values -4..=4 (and the +0.5 values between) to an increasing
        // table of random gaps: strictly increasing, and exact.
        let mut table = vec![base];
        for s in &steps {
            table.push(table.last().unwrap() + f64::from(*s) / 64.0);
        }
        let f = |x: f64| table[(x + 4.0) as usize]; // scores are integers here
        let fs_cal = p.s_cal.mapv(f);
        let fs_val = p.s_val.mapv(f);

        let t = best_threshold(p.s_cal.view(), &p.gt, p.matching, p.tau).unwrap();
        let ft = best_threshold(fs_cal.view(), &p.gt, p.matching, p.tau).unwrap();
        prop_assert_eq!(ft, if t.is_finite() { f(t) } else { t });
        for t in [-4.0, -1.0, 0.0, 2.0, 4.0] {
            prop_assert_eq!(
                counts(p.s_cal.view(), &p.gt, p.matching, t).unwrap(),
                counts(fs_cal.view(), &p.gt, p.matching, f(t)).unwrap()
            );
        }

        // Same neighbours (every calibration query): same subset thresholds up to f,
        // same quantiles, same decisions.
        let k = p.s_cal.ncols();
        let a = Problem { k, ..p.clone() }.transfer();
        let b = Problem { k, s_cal: fs_cal, s_val: fs_val.clone(), ..p.clone() }.transfer();
        // Every query's neighbours are all the calibration queries (their order, by
        // correlation, may differ; the subset does not).
        let all = |r: ndarray::ArrayView1<'_, usize>| {
            let mut r = r.to_vec();
            r.sort_unstable();
            r == (0..k).collect::<Vec<_>>()
        };
        prop_assert!(a.neighbours.rows().into_iter().chain(b.neighbours.rows()).all(all));
        prop_assert_eq!(&a.query_quantiles, &b.query_quantiles);
        for (ta, tb) in a.query_thresholds.iter().zip(&b.query_thresholds) {
            prop_assert_eq!(*tb, if ta.is_finite() { f(*ta) } else { *ta });
        }
        for (sa, sb) in a.segments.iter().zip(&b.segments) {
            prop_assert_eq!(sa.quantile, sb.quantile);
            let n = (sa.end - sa.start) * p.s_val.nrows();
            let h = (n - 1) as f64 * sa.quantile;
            let frac = h - h.floor();
            if sa.quantile < 1.0 && frac > 0.0 && frac < 1e-6 {
                continue; // the interpolation weight is within rounding of 0: see the module doc
            }
            let accepted = |s: &Array2<f64>, t: f64| {
                s.slice(ndarray::s![.., sa.start..sa.end]).iter().filter(|&&x| x >= t).count()
            };
            prop_assert_eq!(accepted(&p.s_val, sa.threshold), accepted(&fs_val, sb.threshold), "{:?} {:?}", sa, sb);
        }
    }

    #[test]
    fn a_positive_affine_transform_keeps_correlations(
        p in problem(false),
        a in 0.01f64..100.0,
        b in -100.0f64..100.0,
        exponent in -4i32..5,
    ) {
        let r = ranked_correlation(p.s_val.view(), p.s_cal.view()).unwrap();
        let affine = ranked_correlation(p.s_val.mapv(|x| a * x + b).view(), p.s_cal.mapv(|x| a * x + b).view()).unwrap();
        for (x, y) in r.iter().zip(&affine) {
            // A constant profile correlates 0 before and after.
            prop_assert!((x - y).abs() <= 1e-9, "{} vs {}", x, y);
        }
        // Scaling by a power of two is exact: everything is the same, thresholds scaled.
        let scale = 2f64.powi(exponent);
        let scaled = Problem { s_cal: p.s_cal.mapv(|x| x * scale), s_val: p.s_val.mapv(|x| x * scale), ..p.clone() };
        let (x, y) = (p.transfer(), scaled.transfer());
        prop_assert_eq!(&x.neighbours, &y.neighbours);
        prop_assert_eq!(&x.query_weights, &y.query_weights);
        prop_assert_eq!(&x.query_quantiles, &y.query_quantiles);
        for (sx, sy) in x.segments.iter().zip(&y.segments) {
            prop_assert_eq!(sx.quantile, sy.quantile);
            if sx.quantile < 1.0 {
                prop_assert_eq!(sx.threshold * scale, sy.threshold);
            } else {
                // Reject-all: the next f64 above each batch's maximum.
                prop_assert_eq!(sy.threshold, (sx.threshold.next_down() * scale).next_up());
            }
        }
        let t = x.query_thresholds.iter().map(|t| t * scale).collect::<Vec<_>>();
        prop_assert_eq!(t, y.query_thresholds);
    }

    #[test]
    fn raising_tau_never_raises_recall(p in problem(false)) {
        let recall = |tau: f64| {
            let t = best_threshold(p.s_cal.view(), &p.gt, p.matching, tau).unwrap();
            counts(p.s_cal.view(), &p.gt, p.matching, t).unwrap().recall()
        };
        let mut taus: Vec<f64> = TAUS.to_vec();
        taus.extend([0.01, 0.3, 0.999]);
        taus.sort_by(f64::total_cmp);
        let recalls: Vec<f64> = taus.iter().map(|&t| recall(t)).collect();
        for w in recalls.windows(2) {
            prop_assert!(w[1] <= w[0], "recall rises with tau: {:?} at {:?}", recalls, taus);
        }
    }

    #[test]
    fn the_oracle_meets_tau_on_its_own_segment(
        p in problem(false),
        gt_val in (1usize..8, 1usize..8).prop_flat_map(|(r, c)| ground_truth(r, c)),
    ) {
        // The deployment matrix with ground truth of its own shape, segmented.
        let (rows, cols) = gt_val.dim();
        let s = Array2::from_shape_fn((rows, cols), |(i, j)| p.s_val[[i % p.s_val.nrows(), j % p.s_val.ncols()]]);
        let m = p.segment_size.unwrap_or(cols).min(cols);
        for start in (0..cols).step_by(m) {
            let r = start..(start + m).min(cols);
            let seg = s.slice(ndarray::s![.., r.clone()]);
            let seg_gt = GroundTruth::from_truth(gt_val.view().slice(ndarray::s![.., r.clone()]).to_owned());
            let t = best_threshold(seg, &seg_gt, p.matching, p.tau).unwrap();
            let c = counts(seg, &seg_gt, p.matching, t).unwrap();
            prop_assert!(meets(&c, p.tau), "segment {:?}: {:?} at {}", r, c, t);
            if t.is_finite() {
                prop_assert!(c.tp > 0);
            } else {
                prop_assert_eq!((c.tp, c.fp), (0, 0));
            }
        }
    }
}
