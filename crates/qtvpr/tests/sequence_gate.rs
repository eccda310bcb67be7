//! The sequence gate and online sequence matching (semantics §15) through every
//! operation of the core: the batch transfer, a split traverse, blocks of a stream,
//! `Online` (pushed one by one, in blocks, resumed), the protocol's methods and the
//! calibration file, on streams of best matches built by hand (a stop, a jump, a
//! reverse traverse, the start of a stream, a database that is not a sequence) and on
//! the real data of `../shared/data` (Corridor, Nordland).
#![cfg(feature = "npy")]

use std::sync::Arc;

use ndarray::{Array2, ArrayView2, s};
use qtvpr::{
    Calibration, Decision, Defaults, Gate, GroundTruth, Line, Matching, Method, Online, OnlineParams, Params, Protocol,
    QuerySplit, Score, Sequence, SequenceParams, Split, Transfer, evaluate, sequence_match,
};
use qtvpr_testkit::data;

/// |DB| of the streams built by hand.
const N_DB: usize = 40;

/// A fixed LCG in [0, 1).
fn lcg(seed: u64) -> impl FnMut() -> f64 {
    let mut x = seed;
    move || {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((x >> 33) % 1000) as f64 / 1000.0
    }
}

/// A similarity matrix whose column `j` peaks at row `best[j]` (score 0.9 + a little
/// noise), every other score below 0.5: its best matches are `best`.
fn stream(best: &[usize], seed: u64) -> Array2<f64> {
    let mut noise = lcg(seed);
    Array2::from_shape_fn((N_DB, best.len()), |(i, j)| {
        if i == best[j] {
            0.9 + 0.05 * noise()
        } else {
            0.5 * noise()
        }
    })
}

/// Ground truth that says every best match of `best` is right.
fn truth(best: &[usize]) -> GroundTruth {
    GroundTruth::new(Array2::from_shape_fn((N_DB, best.len()), |(i, j)| i == best[j]).view()).unwrap()
}

/// A calibration traverse of 8 queries along rows 2..10, all right.
fn calibration(matching: Matching) -> Calibration {
    let best: Vec<usize> = (2..10).collect();
    Calibration::new(stream(&best, 1).view(), &truth(&best), matching).unwrap()
}

/// The deployment stream: rows 10..=15 (queries 0..=5), a jump to 30..=34 (6..=10), a
/// stop at 34 (11..=13), then 35 (14).
const DEPLOYMENT: [usize; 15] = [10, 11, 12, 13, 14, 15, 30, 31, 32, 33, 34, 34, 34, 34, 35];

/// Their consistencies with the defaults (W = 5, v = 1, a = 2, b = 0.2), by hand:
/// - 0..=5: the start of the stream, min(j, 5) of 5 agree;
/// - 6 (the jump to 30): rows 15..11 predict 29..25, none is there: 0; 7..=10 as a new
///   start: 1, 2, 3, 4 agree;
/// - 11 (34 again): 34, 33, 32, 31, 30 against 33, 32, 31, 30, 29, each 1 away: 1;
/// - 12: 34, 34, 33, 32, 31 against 33, 32, 31, 30, 29: 1, 2, 2, 2, 2 within 2.2,
///   2.4, 2.6, 2.8, 3: 1;
/// - 13: 34, 34, 34, 33, 32 against 33, 32, 31, 30, 29: 1, 2, 3 (> 2.6), 3 (> 2.8),
///   3 (<= 3): 3 of 5;
/// - 14 (35): 34, 34, 34, 34, 33 against 34, 33, 32, 31, 30: 0, 1, 2, 3 (> 2.8), 3
///   (<= 3): 4 of 5.
const CONSISTENCY: [f64; 15] = [
    0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.0, 0.6, 0.8,
];

fn params(gate: Gate) -> Params {
    Params {
        k: 3,
        precision: 1.0,
        segment_size: Some(5),
        gate,
        sequence_gate: SequenceParams::default(),
    }
}

fn online_params(gate: Gate, window: usize) -> OnlineParams {
    OnlineParams {
        k: 3,
        precision: 1.0,
        window,
        min_window: 1,
        gate,
        sequence_gate: SequenceParams::default(),
    }
}

/// Each pushed one by one.
fn pushed<T: Score>(online: &mut Online, s: ArrayView2<'_, T>) -> Vec<Decision> {
    s.columns().into_iter().map(|c| online.push(c).unwrap()).collect()
}

#[test]
fn the_batch_and_a_stream_give_each_query_its_consistency() {
    let cal = Arc::new(calibration(Matching::Single));
    let s_val = stream(&DEPLOYMENT, 2);
    let out = cal.transfer(s_val.view(), &params(Gate::Sequence)).unwrap();
    assert_eq!(out.query_consistencies.as_deref(), Some(&CONSISTENCY[..]));
    assert_eq!((out.consistency_level, out.gate), (Some(0.8), None));
    // With both gates, both levels; the thresholds are those of no gate.
    let both = cal.transfer(s_val.view(), &params(Gate::MarginSequence)).unwrap();
    let none = cal.transfer(s_val.view(), &params(Gate::None)).unwrap();
    assert!(both.gate.is_some() && both.query_margins.is_some());
    assert_eq!(both.query_consistencies, out.query_consistencies);
    assert_eq!(both.segments, none.segments);
    assert_eq!((none.query_consistencies, none.consistency_level), (None, None));

    for window in [1, 4, 20] {
        let ungated = Online::new(Arc::clone(&cal), online_params(Gate::None, window))
            .unwrap()
            .push_many(s_val.view())
            .unwrap();
        let mut online = Online::new(Arc::clone(&cal), online_params(Gate::Sequence, window)).unwrap();
        let decisions = pushed(&mut online, s_val.view());
        for (j, (d, u)) in decisions.iter().zip(&ungated).enumerate() {
            assert_eq!((d.consistency, d.consistency_level), (Some(CONSISTENCY[j]), Some(0.8)));
            assert_eq!((d.margin, d.gate), (None, None));
            // The accept rule: the score, then the gate (0.8 inclusive).
            assert_eq!(d.best, DEPLOYMENT[j]);
            assert_eq!(d.threshold.to_bits(), u.threshold.to_bits());
            assert_eq!(d.accept(), u.accept() && CONSISTENCY[j] >= 0.8, "query {j}");
        }
        // The first 4 queries of a stream cannot pass; the jump and the 3 after it
        // neither; the stop passes two queries, then 13 (0.6) fails.
        let passing: Vec<usize> = (0..15).filter(|&j| CONSISTENCY[j] >= 0.8).collect();
        assert_eq!(passing, [4, 5, 10, 11, 12, 14]);
        // In blocks (push_many), the same records.
        let many = Online::new(Arc::clone(&cal), online_params(Gate::Sequence, window))
            .unwrap()
            .push_many(s_val.view())
            .unwrap();
        assert_eq!(many, decisions);
        // Resumed at every query from what it looks back at: max(window - 1, W = 5).
        for first in 1..15 {
            let mut resumed = Online::new(Arc::clone(&cal), online_params(Gate::Sequence, window)).unwrap();
            let lookback = resumed.lookback(first);
            assert_eq!(lookback, first.min((window - 1).max(5)), "window {window}");
            resumed
                .resume(first, s_val.slice(s![.., first - lookback..first]))
                .unwrap();
            let rest = resumed.push_many(s_val.slice(s![.., first..])).unwrap();
            assert_eq!(rest, decisions[first..], "window {window}, from {first}");
        }
    }
}

#[test]
fn a_reverse_traverse_passes_only_at_speed_minus_one() {
    // Rows 30, 29, ..., 16: at v = 1 a neighbour d back lies 2d from its prediction, so
    // only d = 1 agrees (2 <= 2.2): at most 0.2, nothing passes. At v = -1 the line is
    // the route driven backwards: as a forward traverse, from the fifth query on.
    let cal = Arc::new(calibration(Matching::Single));
    let best: Vec<usize> = (16..=30).rev().collect();
    let s_val = stream(&best, 3);
    let forward = cal.transfer(s_val.view(), &params(Gate::Sequence)).unwrap();
    let c = forward.query_consistencies.unwrap();
    assert_eq!(c[0], 0.0);
    assert!(c[1..].iter().all(|&c| c == 0.2), "{c:?}");
    let back = Params {
        sequence_gate: SequenceParams {
            line: Line {
                speed: -1.0,
                ..Line::default()
            },
            ..SequenceParams::default()
        },
        ..params(Gate::Sequence)
    };
    let c = cal.transfer(s_val.view(), &back).unwrap().query_consistencies.unwrap();
    assert_eq!(c[..6], [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
    assert!(c[5..].iter().all(|&c| c == 1.0));
}

#[test]
fn a_database_that_is_not_a_sequence_fails_safe() {
    // Best matches at rows permuted by a fixed LCG: consecutive queries' matches are
    // unrelated, so few agree and (almost) nothing passes. Rows 10, 23, 4, 37, ... from
    // the seed below: each query's consistency by the definition, and none reaches 0.8.
    let mut next = lcg(7);
    let best: Vec<usize> = (0..30).map(|_| (next() * N_DB as f64) as usize).collect();
    let cal = Arc::new(calibration(Matching::Single));
    let s_val = stream(&best, 4);
    let c = cal
        .transfer(s_val.view(), &params(Gate::Sequence))
        .unwrap()
        .query_consistencies
        .unwrap();
    let line = Line::default();
    for j in 0..30 {
        let agree = (1..=5.min(j))
            .filter(|&d| line.agrees(best[j], best[j - d], -(d as isize)))
            .count();
        assert_eq!(c[j], agree as f64 / 5.0, "query {j}");
    }
    assert!(c.iter().all(|&c| c < 0.8), "{c:?}");
    let decisions = Online::new(cal, online_params(Gate::Sequence, 5))
        .unwrap()
        .push_many(s_val.view())
        .unwrap();
    assert!(decisions.iter().all(|d| !d.accept()));
}

#[test]
fn a_split_traverse_looks_back_into_its_calibration_queries() {
    // One traverse along rows 2..25: the first 8 queries calibrate. The deployment
    // queries' windows reach back into the calibration queries, which are on the same
    // line: every deployment query passes (1.0); transferred alone, the deployment
    // matrix starts a stream of its own (0, 0.2, ...).
    let best: Vec<usize> = (2..25).collect();
    let s = stream(&best, 5);
    let gt = truth(&best);
    let split = QuerySplit::new(Split::Count(8), s.dim()).unwrap();
    let gt_cal = split.calibration_truth(&gt).unwrap();
    let (cal, out) = split
        .transfer(s.view(), gt_cal.clone(), Matching::Single, &params(Gate::Sequence))
        .unwrap();
    assert_eq!(out.query_consistencies, Some(vec![1.0; 15]));
    let alone = cal.transfer(s.slice(s![.., 8..]), &params(Gate::Sequence)).unwrap();
    let c = alone.query_consistencies.unwrap();
    assert_eq!(c[..5], [0.0, 0.2, 0.4, 0.6, 0.8]);
    // The thresholds are the transfer's of the deployment columns, whatever the gate.
    assert_eq!(out.segments, alone.segments);
    // 3 calibration queries only: the first deployment query sees 3 of 5.
    let split = QuerySplit::new(Split::Count(3), s.dim()).unwrap();
    let gt_cal = split.calibration_truth(&gt).unwrap();
    let (_, out) = split
        .transfer(s.view(), gt_cal, Matching::Single, &params(Gate::Sequence))
        .unwrap();
    assert_eq!(out.query_consistencies.unwrap()[..3], [0.6, 0.8, 1.0]);
    // An error in a deployment column names its column in the whole matrix.
    let mut bad = s.clone();
    bad[[4, 12]] = f64::NAN;
    let Err(err) = QuerySplit::new(Split::Count(8), s.dim()).unwrap().transfer(
        bad.view(),
        gt_cal_of(&gt, 8),
        Matching::Single,
        &params(Gate::Sequence),
    ) else {
        panic!("a NaN is an error");
    };
    assert_eq!(
        qtvpr::Error::from(err).to_string(),
        "deployment similarity contains NaN at row 4, column 12; scores must be finite"
    );
}

fn gt_cal_of(gt: &GroundTruth, n: usize) -> GroundTruth {
    GroundTruth::from_truth(gt.view().slice(s![.., ..n]).to_owned())
}

/// `transfer` of the whole stream, cut at `cut` into blocks transferred independently
/// with what they look back at, and put together again.
fn in_blocks(cal: &Calibration, s: ArrayView2<'_, f64>, p: &Params, cuts: &[usize]) -> Transfer {
    let n = s.ncols();
    let bounds: Vec<(usize, usize)> = [0]
        .iter()
        .chain(cuts)
        .zip(cuts.iter().chain([&n]))
        .map(|(&a, &b)| (a, b))
        .collect();
    let parts: Vec<Transfer> = bounds
        .iter()
        .map(|&(a, b)| {
            let before = a.min(cal.lookback(p.gate, &p.sequence_gate));
            cal.transfer_block(s.slice(s![.., a - before..b]), p, a, before)
                .unwrap()
        })
        .collect();
    let cat = |f: fn(&Transfer) -> &Vec<f64>| parts.iter().flat_map(|t| f(t).clone()).collect::<Vec<f64>>();
    Transfer {
        segments: parts.iter().flat_map(|t| t.segments.clone()).collect(),
        query_quantiles: cat(|t| &t.query_quantiles),
        query_thresholds: cat(|t| &t.query_thresholds),
        query_weights: cat(|t| &t.query_weights),
        neighbours: ndarray::concatenate(
            ndarray::Axis(0),
            &parts.iter().map(|t| t.neighbours.view()).collect::<Vec<_>>(),
        )
        .unwrap(),
        gate: parts[0].gate,
        query_margins: parts[0]
            .query_margins
            .as_ref()
            .map(|_| cat(|t| t.query_margins.as_ref().unwrap())),
        query_confidences: Some(cat(|t| t.query_confidences.as_ref().unwrap())),
        query_confidences_lower95: Some(cat(|t| t.query_confidences_lower95.as_ref().unwrap())),
        consistency_level: parts[0].consistency_level,
        query_consistencies: parts[0]
            .query_consistencies
            .as_ref()
            .map(|_| cat(|t| t.query_consistencies.as_ref().unwrap())),
    }
}

#[test]
fn blocks_of_a_stream_preceded_by_their_lookback_are_the_whole() {
    let s_val = stream(&DEPLOYMENT, 2);
    let best: Vec<usize> = (2..10).collect();
    let s_cal = stream(&best, 1);
    for length in [1, 3] {
        let cal = Calibration::new_sequence(s_cal.view(), &truth(&best), Matching::Single, length).unwrap();
        for gate in [Gate::None, Gate::Sequence, Gate::MarginSequence] {
            let p = params(gate);
            // The window of the consistency (5 with the gate) and L - 1 raw columns.
            let lookback = if gate.sequence() { 5 } else { 0 } + length - 1;
            assert_eq!(cal.lookback(gate, &p.sequence_gate), lookback);
            let whole = cal.transfer(s_val.view(), &p).unwrap();
            assert_eq!(
                in_blocks(&cal, s_val.view(), &p, &[5, 10]),
                whole,
                "L = {length}, {gate}"
            );
        }
    }
    let cal = calibration(Matching::Single);
    let p = params(Gate::Sequence);
    assert_eq!(
        cal.transfer_block(s_val.view(), &p, 2, 3).unwrap_err().to_string(),
        "before must be at most the block's first query (2) and leave a query of the 15 columns to threshold, got 3"
    );
}

#[test]
fn online_sequence_matching_is_the_causally_matched_matrix_then_the_batch_path() {
    // A calibration of sequence length L is that of the matched calibration traverse,
    // and a stream on it decides as a stream on the matched deployment matrix does: the
    // same bits, pushed one by one (f32 and f64), in blocks, resumed, and in a batch.
    let mut noise = lcg(9);
    let s_cal = Array2::from_shape_fn((N_DB, 12), |(i, j)| noise() + if i == 3 + j { 1.0 } else { 0.0 });
    let gt = GroundTruth::new(Array2::from_shape_fn((N_DB, 12), |(i, j)| i == 3 + j).view()).unwrap();
    let s_val = Array2::from_shape_fn((N_DB, 30), |(i, j)| noise() + if i == 5 + j / 2 { 0.8 } else { 0.0 });
    for length in [3, 5, 11] {
        let sequence = Sequence::causal(length);
        let cal = Arc::new(Calibration::new_sequence(s_cal.view(), &gt, Matching::Single, length).unwrap());
        let matched_cal = sequence_match(s_cal.view(), sequence).unwrap();
        let plain = Arc::new(Calibration::new(matched_cal.view(), &gt, Matching::Single).unwrap());
        assert_eq!((cal.sequence(), plain.sequence()), (length, 1));
        assert_eq!(cal.scores(), plain.scores());
        let matched_val = sequence_match(s_val.view(), sequence).unwrap();
        for gate in [Gate::None, Gate::Sequence, Gate::MarginSequence] {
            let p = online_params(gate, 6);
            let want = Online::new(Arc::clone(&plain), p)
                .unwrap()
                .push_many(matched_val.view())
                .unwrap();
            let mut online = Online::new(Arc::clone(&cal), p).unwrap();
            assert_eq!(pushed(&mut online, s_val.view()), want, "L = {length}, {gate}");
            let mut online = Online::new(Arc::clone(&cal), p).unwrap();
            assert_eq!(online.push_many(s_val.view()).unwrap(), want);
            // Resumed: the window and the consistency look back max(5, W) queries, each
            // matched from the L - 1 raw columns before it.
            for first in [1, 4, 9, 17, 29] {
                let mut resumed = Online::new(Arc::clone(&cal), p).unwrap();
                let lookback = resumed.lookback(first);
                // max(window - 1, W) = max(5, 5), with the gate's W or without it.
                let decided = 5;
                assert_eq!(lookback, first.min(decided + length - 1));
                resumed
                    .resume(first, s_val.slice(s![.., first - lookback..first]))
                    .unwrap();
                assert_eq!(resumed.push_many(s_val.slice(s![.., first..])).unwrap(), want[first..]);
            }
            let batch = Params { gate, ..params(gate) };
            assert_eq!(
                cal.transfer(s_val.view(), &batch).unwrap(),
                plain.transfer(matched_val.view(), &batch).unwrap()
            );
        }
        // float32 columns are matched and decided in float32, as the batch does.
        let s32 = s_val.mapv(|v| v as f32);
        let want = Online::new(Arc::clone(&plain), online_params(Gate::Sequence, 6))
            .unwrap()
            .push_many(sequence_match(s32.view(), sequence).unwrap().view())
            .unwrap();
        let mut online = Online::new(Arc::clone(&cal), online_params(Gate::Sequence, 6)).unwrap();
        assert_eq!(pushed(&mut online, s32.view()), want);
        // The file keeps the matched scores and L.
        let defaults = Defaults {
            gate: Gate::Sequence,
            window: Some(6),
            ..Defaults::default()
        };
        let loaded = Calibration::from_bytes(&cal.to_bytes(&defaults).unwrap(), "cal.npz").unwrap();
        assert_eq!((loaded.sequence(), loaded.scores()), (length, cal.scores()));
        assert_eq!(loaded.defaults(), &defaults);
    }
    let cal = Calibration::new_sequence(s_cal.view(), &gt, Matching::Single, 11).unwrap();
    cal.check_sequence(None).unwrap();
    cal.check_sequence(Some(11)).unwrap();
    assert_eq!(
        cal.check_sequence(Some(5)).unwrap_err().to_string(),
        "sequence 5 is not the calibration's sequence length 11: the length belongs to the calibration, whose \
         scores were matched over it (calibrate with that length instead)"
    );
    assert_eq!(
        Calibration::new_sequence(s_cal.view(), &gt, Matching::Single, 4)
            .err()
            .unwrap()
            .to_string(),
        "sequence length must be odd and >= 1, got 4"
    );
    // A bad raw score is named as pushed, and leaves the state as it was.
    let mut online = Online::new(Arc::new(cal), online_params(Gate::None, 6)).unwrap();
    online.push(s_val.column(0)).unwrap();
    let mut bad = s_val.column(1).to_owned();
    bad[7] = f64::INFINITY;
    assert_eq!(
        online.push(bad.view()).unwrap_err().to_string(),
        "deployment similarity contains inf at row 7, column 1; scores must be finite"
    );
    assert_eq!(online.pushed(), 1);
}

#[test]
fn the_gate_is_refused_where_it_cannot_tell() {
    let cal = Arc::new(calibration(Matching::Multi));
    let err = Online::new(Arc::clone(&cal), online_params(Gate::Sequence, 4))
        .err()
        .unwrap();
    assert!(
        err.to_string().starts_with("gate sequence needs single matching"),
        "{err}"
    );
    assert!(
        cal.transfer(stream(&DEPLOYMENT, 2).view(), &params(Gate::Sequence))
            .is_err()
    );
    // |DB| = 7: +-3 rows cover 7 rows.
    let small = Calibration::new(
        Array2::from_shape_fn((7, 3), |(i, j)| f64::from(u8::from(i == j))).view(),
        &GroundTruth::new(Array2::from_shape_fn((7, 3), |(i, j)| i == j).view()).unwrap(),
        Matching::Single,
    )
    .unwrap();
    assert_eq!(
        small
            .check_gate(Gate::Sequence, &SequenceParams::default())
            .unwrap_err()
            .to_string(),
        "gate sequence cannot tell a line from chance with |DB| = 7: its widest tolerance, +-3 rows 5 steps \
         away (sequence tolerance 2 and drift 0.2), covers 7 rows; it needs |DB| >= 8"
    );
    // A window of 2 reaches +-2.4 rows: 5 rows, enough on 7.
    let narrow = SequenceParams {
        window: 2,
        ..SequenceParams::default()
    };
    small.check_gate(Gate::Sequence, &narrow).unwrap();
}

#[test]
fn the_protocols_sequence_methods_decide_by_the_definition() {
    // The calibration traverse (8 queries) then the deployment stream (15 queries, 3
    // segments of 5): one matrix. The consistency runs over the whole traverse, so the
    // first deployment queries look back at the calibration queries: query 0 (row 10)
    // has rows 9..5 before it, on its line (1); then as CONSISTENCY from query 5 on
    // (queries 1..=4 see rows of the traverse too: 1).
    let best: Vec<usize> = (2..10).chain(DEPLOYMENT).collect();
    let s = stream(&best, 6);
    // Ground truth: every best match right but the stop's last two (13 and 14 are wrong).
    let gt = GroundTruth::new(
        Array2::from_shape_fn((N_DB, best.len()), |(i, j)| {
            i == best[j] && !(j == 8 + 13 || j == 8 + 14)
        })
        .view(),
    )
    .unwrap();
    let protocol = Protocol {
        calibration: Split::Count(8),
        segment: Split::Count(5),
        k: 3,
        ..Protocol::default()
    };
    let methods = [
        Method::QuantileTransfer,
        Method::Sequence,
        Method::QuantileTransferSequence,
        Method::QuantileTransferMarginSequence,
    ];
    let e = evaluate(s.view(), &gt, &protocol, &methods).unwrap();
    let consistency: Vec<f64> = (0..15).map(|j| if j < 5 { 1.0 } else { CONSISTENCY[j] }).collect();
    let passes = |j: usize| consistency[j] >= 0.8 - 1e-12;
    let qt = e.method(Method::QuantileTransfer).unwrap();
    let sequence = e.method(Method::Sequence).unwrap();
    let gated = e.method(Method::QuantileTransferSequence).unwrap();
    for (g, segment) in sequence.segments.iter().zip(0..) {
        let queries = 5 * segment..5 * segment + 5;
        // The gate alone accepts each best match that passes: TP unless 13 or 14.
        let accepted: Vec<usize> = queries.clone().filter(|&j| passes(j)).collect();
        let fp = accepted.iter().filter(|&&j| j == 13 || j == 14).count();
        assert_eq!(
            (g.counts.tp, g.counts.fp),
            (accepted.len() - fp, fp),
            "segment {segment}"
        );
        assert_eq!(
            (g.threshold, g.gate, g.consistency_level),
            (f64::NEG_INFINITY, None, Some(0.8))
        );
        // With quantile transfer: also a score at or above the segment's threshold.
        let t = qt.segments[segment].threshold;
        let h = &gated.segments[segment];
        let kept: Vec<usize> = accepted.into_iter().filter(|&j| s[[best[8 + j], 8 + j]] >= t).collect();
        let fp = kept.iter().filter(|&&j| j == 13 || j == 14).count();
        assert_eq!((h.counts.tp, h.counts.fp, h.threshold), (kept.len() - fp, fp, t));
        assert_eq!(h.consistency_level, Some(0.8));
    }
    let both = e.method(Method::QuantileTransferMarginSequence).unwrap();
    assert!(
        both.segments
            .iter()
            .all(|g| g.gate.is_some() && g.consistency_level == Some(0.8))
    );
    // The sequence method has no finite threshold: no threshold MSE.
    assert_eq!(sequence.threshold_mse, None);
    // The consistency as a signal: every right decision (all but 13, 14) against the two
    // wrong ones (0.6 and 0.8): right 1 (10 of them) beat both, 0.8 (3: 4, 10, and the
    // calibration-looking 0..=3 are 1) ... computed from the definition here.
    let right: Vec<f64> = (0..15)
        .filter(|&j| j != 13 && j != 14)
        .map(|j| consistency[j])
        .collect();
    let wrong = [consistency[13], consistency[14]];
    let pairs: f64 = right
        .iter()
        .flat_map(|r| {
            wrong.iter().map(move |w| {
                if r > w {
                    1.0
                } else if r == w {
                    0.5
                } else {
                    0.0
                }
            })
        })
        .sum();
    let signals = e.confidence.as_ref().unwrap();
    assert_eq!(signals.consistency_auroc, Some(pairs / (right.len() * 2) as f64));
    // Multi matching refuses the sequence methods, naming the gate.
    let multi = Protocol {
        matching: Matching::Multi,
        ..protocol
    };
    let err = evaluate(s.view(), &gt, &multi, &[Method::Sequence]).unwrap_err();
    assert!(
        err.to_string().starts_with("gate sequence needs single matching"),
        "{err}"
    );
}

/// Every front end's path, the core's: `Online` with the gate (and on a calibration of
/// sequence length `L`) equals the batch path query by query on real data: its
/// consistency is the batch transfer's, its threshold the transfer of its window, its
/// accept the accept rule.
fn online_equals_the_batch<T: Score>(s: ArrayView2<'_, T>, gt: &GroundTruth, n_cal: usize, length: usize) {
    let (s_cal, s_val) = (s.slice(s![.., ..n_cal]), s.slice(s![.., n_cal..]));
    let gt_cal = gt_cal_of(gt, n_cal);
    let cal = Arc::new(Calibration::new_sequence(s_cal, &gt_cal, Matching::Single, length).unwrap());
    let matched = sequence_match(s_val, Sequence::causal(length)).unwrap();
    let p = online_params(Gate::Sequence, 28);
    let decisions = Online::new(Arc::clone(&cal), p).unwrap().push_many(s_val).unwrap();
    let batch = cal.transfer(s_val, &params(Gate::Sequence)).unwrap();
    let c = batch.query_consistencies.unwrap();
    let passing = decisions.iter().filter(|d| d.consistency.unwrap() >= 0.8).count();
    assert!(passing > 0, "some query passes on a traverse");
    // The window's threshold: the transfer of its matched columns on the calibration of
    // the matched calibration traverse (L = 1), no gate.
    let scores = cal.scores().unwrap();
    let plain = qtvpr::with_scores!(scores.view(), |m| Calibration::new(m, &gt_cal, Matching::Single)).unwrap();
    let one = Params {
        segment_size: None,
        ..params(Gate::None)
    };
    // The first 100 queries (each a transfer of its window).
    for (j, d) in decisions.iter().enumerate().take(100) {
        assert_eq!(d.consistency, Some(c[j]), "query {j}");
        let window = s![.., (j + 1).saturating_sub(28)..=j];
        let t = plain.transfer(matched.slice(window), &one).unwrap().segments[0].threshold;
        assert_eq!(d.threshold.to_bits(), t.to_bits(), "query {j}");
        assert_eq!(d.accept(), d.score >= t && c[j] >= 0.8 - 1e-12, "query {j}");
    }
    for (j, d) in decisions.iter().enumerate() {
        assert_eq!(d.consistency, Some(c[j]), "query {j}");
    }
}

#[test]
#[ignore = "needs ../shared/data vprbench-corridor: the gate and L = 11 online equal the batch path"]
fn online_with_the_gate_equals_the_batch_on_corridor() {
    let Some(dir) = data::shared("vprbench-corridor") else {
        return;
    };
    let s = qtvpr::npy::read_scores(&dir.join("S_AMOSNet.npy")).unwrap();
    let gt = qtvpr::npy::read_ground_truth(&dir.join("GT.npy"), None).unwrap();
    let s = s.view();
    let qtvpr::ScoresView::F64(s) = s else {
        panic!("AMOSNet is float64");
    };
    for length in [1, 11] {
        online_equals_the_batch(s, &gt, 11, length);
    }
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: the gate and L = 11 online equal the batch path"]
fn online_with_the_gate_equals_the_batch_on_nordland() {
    let Some((db, q)) = data::nordland(400) else {
        return;
    };
    let s = qtvpr::cosine_similarity(db.view(), q.view()).unwrap();
    let gt = GroundTruth::new(Array2::from_shape_fn(s.dim(), |(i, j)| i.abs_diff(j) <= 1).view()).unwrap();
    for length in [1, 11] {
        online_equals_the_batch(s.view(), &gt, 40, length);
    }
}
