//! A deployment set decided block by block, as a scheduler (`qtvpr.dask`) does:
//! `Calibration::transfer_at` of blocks of whole segments, concatenated, is the
//! transfer of the whole set, and `Online::resume` before each block gives the
//! decisions of the whole stream; errors name the queries of the whole set, and
//! `Calibration::check_transfer` refuses from the shape alone what the whole transfer
//! refuses before reading a score, with its messages.

use std::sync::Arc;

use ndarray::{Array2, s};
use qtvpr::{Calibration, GroundTruth, Matching, Online, OnlineParams, Params};

/// A deterministic matrix of scores in [0, 1) (a linear congruential generator).
fn scores(rows: usize, cols: usize, seed: u64) -> Array2<f64> {
    let mut x = seed;
    Array2::from_shape_fn((rows, cols), |_| {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    })
}

/// 6 database images, 8 calibration queries (query j matches image j mod 6).
fn calibration(matching: Matching) -> Arc<Calibration> {
    let s_cal = scores(6, 8, 1);
    let gt = GroundTruth::new(Array2::from_shape_fn((6, 8), |(i, j)| i == j % 6).view()).unwrap();
    Arc::new(Calibration::new(s_cal.view(), &gt, matching).unwrap())
}

#[test]
fn blocks_of_whole_segments_concatenate_to_the_whole_transfer() {
    let s_val = scores(6, 12, 2);
    for matching in [Matching::Single, Matching::Multi] {
        let cal = calibration(matching);
        let params = Params {
            k: 3,
            precision: 0.75,
            segment_size: Some(3),
            gate: qtvpr::Gate::None,
            sequence_gate: Default::default(),
        };
        let whole = cal.transfer(s_val.view(), &params).unwrap();
        // Blocks 0..6 and 6..12: two segments each; the last block's segments count
        // from query 6.
        let blocks: Vec<_> = [0..6, 6..12]
            .into_iter()
            .map(|r| {
                cal.transfer_at(s_val.slice(s![.., r.clone()]), &params, r.start)
                    .unwrap()
            })
            .collect();
        let segments: Vec<_> = blocks.iter().flat_map(|b| b.segments.clone()).collect();
        assert_eq!(segments, whole.segments);
        assert_eq!((segments[2].start, segments[2].end), (6, 9));
        let quantiles: Vec<f64> = blocks.iter().flat_map(|b| b.query_quantiles.clone()).collect();
        assert_eq!(quantiles, whole.query_quantiles);
        let neighbours: Vec<usize> = blocks
            .iter()
            .flat_map(|b| b.neighbours.iter().copied().collect::<Vec<_>>())
            .collect();
        assert_eq!(neighbours, whole.neighbours.iter().copied().collect::<Vec<_>>());
    }
    // A NaN at row 2 of deployment query 7 is named as query 7 by the block 6..12.
    let mut bad = s_val.clone();
    bad[(2, 7)] = f64::NAN;
    let cal = calibration(Matching::Single);
    let params = Params::default();
    let message = "deployment similarity contains NaN at row 2, column 7; scores must be finite";
    assert_eq!(cal.transfer(bad.view(), &params).unwrap_err().to_string(), message);
    let block = cal.transfer_at(bad.slice(s![.., 6..]), &params, 6).unwrap_err();
    assert_eq!(block.to_string(), message);
}

#[test]
fn a_request_is_checked_from_its_shape_as_the_whole_transfer_checks_it() {
    let cal = calibration(Matching::Single);
    let ok = Params {
        k: 3,
        precision: 1.0,
        segment_size: Some(4),
        gate: qtvpr::Gate::None,
        sequence_gate: Default::default(),
    };
    assert_eq!(cal.check_transfer((6, 12), &ok), Ok(()));
    let cases = [
        ((6, 0), ok),
        ((0, 12), ok),
        ((5, 12), ok),
        (
            (6, 12),
            Params {
                segment_size: Some(13),
                ..ok
            },
        ),
        (
            (6, 12),
            Params {
                segment_size: Some(0),
                ..ok
            },
        ),
        ((6, 12), Params { k: 0, ..ok }),
        ((6, 0), Params { precision: 0.0, ..ok }),
    ];
    let messages = [
        "deployment similarity is empty (shape 6x0)",
        "deployment similarity is empty (shape 0x12)",
        "deployment similarity has 5 database images but calibration similarity has 6; \
         both must be scored against the same database",
        "segment size must be between 1 and the number of deployment queries (12), got 13",
        "segment size must be between 1 and the number of deployment queries (12), got 0",
        "k must be >= 1, got 0",
        "precision must be in (0, 1], got 0",
    ];
    for ((shape, params), message) in cases.into_iter().zip(messages) {
        let checked = cal.check_transfer(shape, &params).unwrap_err();
        assert_eq!(checked.to_string(), message);
        // The whole transfer of a matrix of that shape refuses it the same way.
        let whole = cal.transfer(Array2::<f64>::zeros(shape).view(), &params).unwrap_err();
        assert_eq!(checked, whole);
    }
}

#[test]
fn a_resumed_state_decides_as_the_whole_stream() {
    let s_val = scores(6, 12, 3);
    for matching in [Matching::Single, Matching::Multi] {
        let cal = calibration(matching);
        // A warm-up of 3: queries 0 and 1 are reject-all.
        let p = OnlineParams {
            k: 3,
            precision: 0.75,
            window: 4,
            min_window: 3,
            gate: qtvpr::Gate::None,
            sequence_gate: Default::default(),
        };
        let whole = Online::new(Arc::clone(&cal), p)
            .unwrap()
            .push_many(s_val.view())
            .unwrap();
        // From query 1 (one query before it: min(1, window - 1)) and from query 5 (the
        // window - 1 = 3 queries 2..5 before it).
        for (first, before) in [(1, 0..1), (5, 2..5), (0, 0..0)] {
            let mut online = Online::new(Arc::clone(&cal), p).unwrap();
            online.resume(first, s_val.slice(s![.., before])).unwrap();
            assert_eq!(online.pushed(), first);
            let got = online.push_many(s_val.slice(s![.., first..])).unwrap();
            assert_eq!(got, whole[first..], "from query {first}");
        }
        assert_eq!((whole[1].quantile, whole[1].accepted), (1.0, 0));
    }
}

#[test]
fn resume_errors() {
    let cal = calibration(Matching::Single);
    let p = OnlineParams {
        k: 3,
        precision: 1.0,
        window: 4,
        min_window: 1,
        gate: qtvpr::Gate::None,
        sequence_gate: Default::default(),
    };
    let s_val = scores(6, 12, 4);
    let mut online = Online::new(Arc::clone(&cal), p).unwrap();
    assert_eq!(
        online.resume(5, s_val.slice(s![.., 0..2])).unwrap_err().to_string(),
        "resume at query 5 with a window of 4 takes the 3 queries before it, got 2"
    );
    online.push(s_val.column(0)).unwrap();
    assert_eq!(
        online.resume(5, s_val.slice(s![.., 2..5])).unwrap_err().to_string(),
        "resume needs a fresh state, but 1 queries were pushed"
    );
    // A NaN in query 3 of the stream (the second column before query 5) is named so,
    // and the state is fresh again.
    let mut bad = s_val.clone();
    bad[(4, 3)] = f64::INFINITY;
    let mut online = Online::new(cal, p).unwrap();
    assert_eq!(
        online.resume(5, bad.slice(s![.., 2..5])).unwrap_err().to_string(),
        "deployment similarity contains inf at row 4, column 3; scores must be finite"
    );
    assert_eq!((online.pushed(), online.threshold()), (0, None));
    online.resume(5, s_val.slice(s![.., 2..5])).unwrap();
    assert_eq!(online.push(s_val.column(5)).unwrap().query, 5);
}
