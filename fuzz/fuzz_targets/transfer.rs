//! The core on arbitrary small matrices and parameters: every call returns `Ok` or a
//! typed error, never panics, and on `Ok` the invariants of the semantics hold:
//!
//! - quantiles are in [0, 1], every segment threshold is finite (but see below for
//!   f64::MAX) and the segments tile the deployment queries;
//! - neighbours are distinct calibration indices, min(k, |Qcal|) per query, and
//!   weights are finite and >= 0;
//! - each query's subset threshold t_j is what `best_threshold` gives on its
//!   calibration subset, and applied to that subset attains the precision target (or is
//!   reject-all); its quantile q_j is (c - 1) / (n - 1) of the subset's scores;
//! - `best_threshold` and `counts` agree on the whole calibration matrix, and
//!   `ranked_correlation` is in [-1, 1].

#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use ndarray::{Array2, ArrayView2, Axis};
use qtvpr::{
    Calibration, Error, Gate, GroundTruth, Matching, Params, Truth, best_threshold, counts, ranked_correlation,
};

/// A score: mostly a small value (so that ties are common), sometimes any `f64`.
#[derive(Arbitrary, Debug, Clone, Copy)]
enum Score {
    Small(i8),
    Raw(f64),
}

impl Score {
    fn value(self) -> f64 {
        match self {
            Score::Small(v) => f64::from(v) / 8.0,
            Score::Raw(v) => v,
        }
    }
}

#[derive(Arbitrary, Debug)]
enum Precision {
    One,
    Table(u8),
    Raw(f64),
}

#[derive(Arbitrary, Debug)]
struct Input {
    n_db: u8,
    n_cal: u8,
    n_val: u8,
    scores: Vec<Score>,
    /// Per entry of the calibration ground truth: hard, soft-only or false.
    labels: Vec<u8>,
    k: u8,
    precision: Precision,
    segment_size: Option<u8>,
    multi: bool,
    float32: bool,
    /// Hand the core transposed (query-major) views.
    query_major: bool,
    /// Gate decisions on their margin (semantics §13; refused in multi matching).
    gate: bool,
}

/// An `n_db` x `n` matrix of the scores, cycled, starting at `offset`.
fn matrix(scores: &[Score], n_db: usize, n: usize, offset: usize) -> Array2<f64> {
    Array2::from_shape_fn((n_db, n), |(i, j)| {
        if scores.is_empty() {
            0.0
        } else {
            scores[(offset + j * n_db + i) % scores.len()].value()
        }
    })
}

fn check<T: qtvpr::Score>(
    s_cal: ArrayView2<'_, T>,
    gt: &GroundTruth,
    s_val: ArrayView2<'_, T>,
    matching: Matching,
    params: &Params,
) {
    let to_f64 = |v: ArrayView2<'_, T>| v.mapv(qtvpr::Score::to_f64);
    let tau = params.precision;

    // The whole calibration matrix: best threshold and counts agree.
    match best_threshold(s_cal, gt, matching, tau) {
        Ok(t) => {
            let c = counts(s_cal, gt, matching, t).expect("counts fails where best_threshold succeeds");
            assert!(
                t == f64::INFINITY || (c.tp > 0 && c.tp as f64 >= tau * (c.tp + c.fp) as f64 - 1e-12),
                "{t} {c:?}"
            );
        }
        Err(e) => drop(e.to_string()),
    }
    match ranked_correlation(s_val, s_cal) {
        Ok(r) => assert!(r.iter().all(|x| x.is_finite() && x.abs() <= 1.0 + 1e-9), "{r}"),
        Err(e) => drop(e.to_string()),
    }

    let cal = match Calibration::new(s_cal, gt, matching) {
        Ok(cal) => cal,
        Err(e) => return drop(e.to_string()),
    };
    let out = match cal.transfer(s_val, params) {
        Ok(out) => out,
        Err(e) => {
            assert!(!matches!(
                e,
                Error::Io { .. } | Error::File { .. } | Error::Dtype { .. }
            ));
            return drop(e.to_string());
        }
    };
    let (n_cal, n_val) = (s_cal.ncols(), s_val.ncols());
    let k = params.k.min(n_cal);
    // The gate: m* is a margin or reject-all, every margin finite and non-negative,
    // both present exactly when it is on, and the thresholds those of no gate.
    assert_eq!(out.gate.is_some(), params.gate == Gate::Margin);
    assert_eq!(out.query_margins.is_some(), params.gate == Gate::Margin);
    if let (Some(m_star), Some(margins)) = (out.gate, &out.query_margins) {
        assert!(m_star == f64::INFINITY || (m_star.is_finite() && m_star >= 0.0), "{m_star}");
        assert!(margins.iter().all(|m| m.is_finite() && *m >= 0.0), "{margins:?}");
        let plain = cal.transfer(s_val, &Params { gate: Gate::None, ..*params }).unwrap();
        assert_eq!(plain.segments, out.segments);
    }

    let mut next = 0;
    for seg in &out.segments {
        assert_eq!(seg.start, next);
        assert!(seg.end > seg.start && seg.end <= n_val);
        next = seg.end;
        assert!((0.0..=1.0).contains(&seg.quantile), "{seg:?}");
        // Finite, except reject-all (q = 1) above a batch maximum of f64::MAX, where no
        // finite threshold accepts nothing and +inf is the only honest answer.
        let max = s_val
            .slice(ndarray::s![.., seg.start..seg.end])
            .iter()
            .map(|v| v.to_f64())
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(
            seg.threshold.is_finite() || (seg.quantile == 1.0 && max == f64::MAX),
            "{seg:?}"
        );
    }
    assert_eq!(next, n_val);

    let s_cal64 = to_f64(s_cal);
    assert_eq!(out.neighbours.dim(), (n_val, k));
    for j in 0..n_val {
        let nb: Vec<usize> = out.neighbours.row(j).to_vec();
        let mut sorted = nb.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), k, "neighbours of {j} not distinct: {nb:?}");
        assert!(nb.iter().all(|&i| i < n_cal));
        let w = out.query_weights[j];
        assert!(w.is_finite() && w >= 0.0, "weight {w}");
        let q = out.query_quantiles[j];
        assert!((0.0..=1.0).contains(&q), "quantile {q}");

        // The subset threshold is the best threshold of the subset, and meets tau there.
        let t = out.query_thresholds[j];
        let sub = s_cal64.select(Axis(1), &nb);
        let sub_gt = GroundTruth::from_truth(gt.view().select(Axis(1), &nb));
        assert_eq!(
            t,
            best_threshold(sub.view(), &sub_gt, matching, tau).unwrap(),
            "query {j}"
        );
        if t != f64::INFINITY {
            let c = counts(sub.view(), &sub_gt, matching, t).unwrap();
            assert!(
                c.tp > 0 && c.tp as f64 >= tau * (c.tp + c.fp) as f64 - 1e-12,
                "query {j}: {c:?} at {t}"
            );
            // q_j = (c - 1) / (n - 1), c = #scores <= t_j.
            let n = sub.len();
            let below = sub.iter().filter(|&&x| x <= t).count();
            let want = if n == 1 {
                0.0
            } else {
                (below - 1) as f64 / (n - 1) as f64
            };
            assert_eq!(q, want, "query {j}");
        } else {
            assert_eq!(q, 1.0);
        }
    }
}

fuzz_target!(
    init: {
        // One rayon thread, and it is this one: parallel loops run inline instead of
        // handing every small job to a worker thread and waiting (many times faster).
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .use_current_thread()
            .build_global()
            .unwrap();
    },
    |input: Input| {
    let n_db = usize::from(input.n_db % 9);
    let n_cal = usize::from(input.n_cal % 9);
    let n_val = usize::from(input.n_val % 12);
    let s_cal = matrix(&input.scores, n_db, n_cal, 0);
    let s_val = matrix(&input.scores, n_db, n_val, 7);
    let labels = Array2::from_shape_fn((n_db, n_cal), |(i, j)| {
        let l = input.labels.get(j * n_db + i).copied().unwrap_or(0);
        match l % 4 {
            0 | 1 => Truth::False,
            2 => Truth::True,
            _ => Truth::Ignored,
        }
    });
    let gt = GroundTruth::from_truth(labels);
    let matching = if input.multi { Matching::Multi } else { Matching::Single };
    let precision = match input.precision {
        Precision::One => 1.0,
        Precision::Table(i) => [0.5, 0.6, 0.75, 0.9, 0.99, 1e-9, 1.0 / 3.0, 0.0, 1.5][usize::from(i) % 9],
        Precision::Raw(p) => p,
    };
    let params = Params {
        k: usize::from(input.k % 12),
        precision,
        segment_size: input.segment_size.map(|m| usize::from(m % 14)),
        gate: if input.gate { Gate::Margin } else { Gate::None },
        sequence_gate: Default::default(),
    };
    // Query-major callers hand the core transposed views of |Q| x |DB| arrays.
    let (cal_t, val_t) = (s_cal.t().to_owned(), s_val.t().to_owned());
    let (cal, val) = if input.query_major { (cal_t.t(), val_t.t()) } else { (s_cal.view(), s_val.view()) };
    if input.float32 {
        let (c, v) = (cal.mapv(|x| x as f32), val.mapv(|x| x as f32));
        check(c.view(), &gt, v.view(), matching, &params);
    } else {
        check(cal, &gt, val, matching, &params);
    }
}
);
