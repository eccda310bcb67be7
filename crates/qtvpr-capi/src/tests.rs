//! The C functions called from Rust as C calls them: NULL pointers, wrong sizes and bad
//! values are errors with their documented codes, and a push gives exactly what
//! `qtvpr::Online` gives.

use std::ffi::{CStr, CString};
use std::path::Path;

use ndarray::{Array2, array};
use qtvpr::{Defaults, Gate, GroundTruth};

use super::*;
use crate::error::{last, qtvpr_status};

fn code(status: qtvpr_status) -> c_int {
    status as c_int
}

/// A sequence gate that |DB| = 4 can have: 2 previous queries, within half a row
/// (+-0 rows, 1 row of 4).
const SMALL_GATE: qtvpr::SequenceParams = qtvpr::SequenceParams {
    window: 2,
    level: 0.5,
    line: qtvpr::Line {
        speed: 1.0,
        tolerance: 0.5,
        drift: 0.0,
    },
};

/// 4 database images x 3 calibration queries; query j matches database image j.
fn calibration(matching: Matching, window: Option<usize>) -> Calibration {
    let s = array![[0.9, 0.2, 0.3], [0.1, 0.8, 0.2], [0.3, 0.4, 0.7], [0.2, 0.1, 0.1]];
    let gt = Array2::from_shape_fn((4, 3), |(i, j)| i == j);
    let gt = GroundTruth::new(gt.view()).unwrap();
    let defaults = Defaults {
        k: 2,
        precision: 1.0,
        window,
        gate: Gate::None,
        sequence_gate: SMALL_GATE,
    };
    Calibration::new(s.view(), &gt, matching)
        .unwrap()
        .with_defaults(defaults)
        .unwrap()
}

/// A C handle for `cal`, as qtvpr_calibration_load returns it.
fn handle(cal: Calibration) -> *mut qtvpr_calibration {
    Box::into_raw(Box::new(qtvpr_calibration { inner: Arc::new(cal) }))
}

/// Deployment queries (|DB| = 4), in arrival order.
const QUERIES: [[f64; 4]; 5] = [
    [0.8, 0.1, 0.2, 0.3],
    [0.2, 0.9, 0.1, 0.1],
    [0.3, 0.3, 0.6, 0.2],
    [0.5, 0.5, 0.1, 0.4],
    [0.1, 0.2, 0.2, 0.7],
];

fn no_decision() -> qtvpr_decision {
    qtvpr_decision {
        query: 99,
        quantile: -1.0,
        threshold: -1.0,
        best: 99,
        score: -1.0,
        accept: true,
        accepted: 99,
        query_quantile: -1.0,
        weight: -1.0,
        margin: -1.0,
        gate: -1.0,
        confidence: -1.0,
        confidence_lower95: -1.0,
        consistency: -1.0,
        consistency_level: -1.0,
    }
}

#[test]
fn null_pointers_are_errors_with_their_code() {
    unsafe {
        assert!(qtvpr_calibration_load(ptr::null()).is_null());
        assert_eq!(last(), (1, Some("qtvpr_calibration_load: path is NULL".into())));
        assert_eq!(qtvpr_calibration_db_size(ptr::null()), 0);
        assert_eq!(last(), (1, Some("qtvpr_calibration_db_size: cal is NULL".into())));
        assert_eq!(qtvpr_calibration_matching(ptr::null()), 0);
        assert_eq!(last(), (1, Some("qtvpr_calibration_matching: cal is NULL".into())));
        assert!(qtvpr_online_new(ptr::null(), 0, 0.0, 0, 0).is_null());
        assert_eq!(last(), (1, Some("qtvpr_online_new: cal is NULL".into())));

        let cal = handle(calibration(Matching::Single, Some(2)));
        let o = qtvpr_online_new(cal, 0, 0.0, 0, 0);
        assert!(!o.is_null());
        assert_eq!(last(), (0, None));
        let scores = QUERIES[0];
        let mut d = no_decision();
        assert_eq!(qtvpr_online_push_f64(ptr::null_mut(), scores.as_ptr(), 4, &mut d), 1);
        assert_eq!(last(), (1, Some("qtvpr_online_push_f64: o is NULL".into())));
        assert_eq!(qtvpr_online_push_f64(o, ptr::null(), 4, &mut d), 1);
        assert_eq!(last(), (1, Some("qtvpr_online_push_f64: scores is NULL".into())));
        assert_eq!(qtvpr_online_push_f32(o, [0.5f32; 4].as_ptr(), 4, ptr::null_mut()), 1);
        assert_eq!(last(), (1, Some("qtvpr_online_push_f32: out is NULL".into())));
        assert_eq!(d, no_decision());
        assert_eq!(qtvpr_online_accepted(ptr::null(), ptr::null_mut(), 0), 0);
        assert_eq!(last(), (1, Some("qtvpr_online_accepted: o is NULL".into())));
        assert_eq!(qtvpr_online_accepted(o, ptr::null_mut(), 1), 0);
        assert_eq!(last(), (1, Some("qtvpr_online_accepted: out is NULL".into())));
        // Before the first push nothing is accepted, and a size query needs no buffer.
        assert_eq!(qtvpr_online_accepted(o, ptr::null_mut(), 0), 0);
        assert_eq!(last(), (0, None));

        qtvpr_online_free(ptr::null_mut());
        qtvpr_calibration_free(ptr::null_mut());
        assert_eq!(last(), (0, None));
        qtvpr_online_free(o);
        qtvpr_calibration_free(cal);
    }
}

#[test]
fn a_wrong_size_or_a_bad_score_is_an_error_and_changes_nothing() {
    unsafe {
        let cal = handle(calibration(Matching::Single, Some(2)));
        assert_eq!(qtvpr_calibration_db_size(cal), 4);
        let o = qtvpr_online_new(cal, 0, 0.0, 0, 0);
        let mut d = no_decision();
        let scores = QUERIES[0];
        assert_eq!(
            qtvpr_online_push_f64(o, scores.as_ptr(), 3, &mut d),
            code(QTVPR_ERR_SIZE)
        );
        let message = last().1.unwrap();
        assert!(
            message.starts_with("qtvpr_online_push_f64: deployment query 0 has 3 scores but the calibration has 4"),
            "{message}"
        );
        // A length far beyond the buffer is refused before any view of it is made.
        assert_eq!(qtvpr_online_push_f64(o, scores.as_ptr(), usize::MAX, &mut d), 2);
        assert_eq!(qtvpr_online_push_f64(o, scores.as_ptr(), 0, &mut d), 2);

        let nan = [0.1, f64::NAN, 0.2, 0.3];
        assert_eq!(qtvpr_online_push_f64(o, nan.as_ptr(), 4, &mut d), code(QTVPR_ERR_INPUT));
        let message = last().1.unwrap();
        assert!(
            message.starts_with("qtvpr_online_push_f64: ") && message.contains("NaN"),
            "{message}"
        );
        let inf = [0.1f32, 0.2, f32::INFINITY, 0.3];
        assert_eq!(qtvpr_online_push_f32(o, inf.as_ptr(), 4, &mut d), 3);
        assert!(last().1.unwrap().contains("inf"));

        // Scores one byte off their alignment: refused, never read.
        let buffer = [0.5f64; 5];
        let misaligned = buffer.as_ptr().cast::<u8>().add(1).cast::<f64>();
        assert_eq!(qtvpr_online_push_f64(o, misaligned, 4, &mut d), 3);
        assert!(last().1.unwrap().ends_with("is not aligned for double"));
        assert_eq!(d, no_decision());

        // None of this was pushed: the next query is query 0.
        assert_eq!(qtvpr_online_push_f64(o, scores.as_ptr(), 4, &mut d), 0);
        assert_eq!(last(), (0, None));
        assert_eq!(d.query, 0);
        qtvpr_online_free(o);
        qtvpr_calibration_free(cal);
    }
}

#[test]
fn zero_takes_the_files_value_and_a_bad_parameter_is_an_error() {
    unsafe {
        let cal = handle(calibration(Matching::Single, Some(2)));
        let o = qtvpr_online_new(cal, 0, 0.0, 0, 0);
        let params = OnlineParams {
            k: 2,
            precision: 1.0,
            window: 2,
            min_window: 1,
            gate: Gate::None,
            sequence_gate: SMALL_GATE,
        };
        assert_eq!(*(*o).inner.params(), params);
        qtvpr_online_free(o);
        let o = qtvpr_online_new(cal, 1, 0.5, 3, 2);
        let params = OnlineParams {
            k: 1,
            precision: 0.5,
            window: 3,
            min_window: 2,
            gate: Gate::None,
            sequence_gate: SMALL_GATE,
        };
        assert_eq!(*(*o).inner.params(), params);
        qtvpr_online_free(o);

        assert!(qtvpr_online_new(cal, 0, 1.5, 0, 0).is_null());
        assert_eq!(
            last(),
            (4, Some("qtvpr_online_new: precision must be in (0, 1], got 1.5".into()))
        );
        assert!(qtvpr_online_new(cal, 0, f64::NAN, 0, 0).is_null());
        assert_eq!(last().0, 4);
        assert!(qtvpr_online_new(cal, 0, 0.0, 2, 3).is_null());
        assert_eq!(
            last(),
            (
                4,
                Some("qtvpr_online_new: min window must be between 1 and the window (2), got 3".into())
            )
        );
        qtvpr_calibration_free(cal);

        let cal = handle(calibration(Matching::Single, None));
        assert!(qtvpr_online_new(cal, 0, 0.0, 0, 0).is_null());
        assert_eq!(
            last(),
            (
                4,
                Some("qtvpr_online_new: window is not given and the calibration sets none".into())
            )
        );
        let o = qtvpr_online_new(cal, 0, 0.0, 2, 0);
        assert!(!o.is_null());
        qtvpr_online_free(o);
        qtvpr_calibration_free(cal);
    }
}

/// `qtvpr_online_new_with` and its options: initialised, every parameter the file's;
/// each member given overrides the file's; a struct not initialised, a gate or a
/// sequence length that does not fit, are errors naming what is wrong.
#[test]
fn options_take_the_files_values_and_each_member_given() {
    unsafe {
        // The file's sequence gate, on: SMALL_GATE (the defaults' +-3 rows would cover
        // |DB| = 4).
        let cal = calibration(Matching::Single, Some(3));
        let file_gate = SMALL_GATE;
        let defaults = Defaults {
            gate: Gate::Sequence,
            sequence_gate: file_gate,
            ..*cal.defaults()
        };
        let cal = cal.with_defaults(defaults).unwrap();
        let cal = handle(cal);
        assert_eq!(qtvpr_calibration_sequence(cal), 1);
        let mut opts = std::mem::MaybeUninit::<qtvpr_online_options>::uninit();
        qtvpr_online_options_init(opts.as_mut_ptr());
        let mut opts = opts.assume_init();
        assert_eq!(opts.size, std::mem::size_of::<qtvpr_online_options>());
        assert!(opts.gate.is_null() && opts.sequence_level.is_nan() && opts.precision == 0.0);
        // Initialised: the file's, as NULL options are.
        for o in [
            qtvpr_online_new_with(cal, &opts),
            qtvpr_online_new_with(cal, ptr::null()),
        ] {
            let p = *(*o).inner.params();
            assert_eq!(
                (p.k, p.window, p.gate, p.sequence_gate),
                (2, 3, Gate::Sequence, file_gate)
            );
            qtvpr_online_free(o);
        }
        // Each member given overrides the file's; the others stay the file's.
        let both = CString::new("sequence,margin").unwrap();
        opts.gate = both.as_ptr();
        opts.sequence_level = 1.0;
        opts.sequence_speed = -1.0;
        opts.min_window = 2;
        opts.sequence = 1;
        let o = qtvpr_online_new_with(cal, &opts);
        let p = *(*o).inner.params();
        assert_eq!((p.gate, p.min_window), (Gate::MarginSequence, 2));
        assert_eq!(
            p.sequence_gate,
            qtvpr::SequenceParams {
                level: 1.0,
                line: qtvpr::Line {
                    speed: -1.0,
                    ..file_gate.line
                },
                ..file_gate
            }
        );
        // A push carries the consistency (the first query of a stream: 0 of 2) and its
        // level.
        let mut d = no_decision();
        assert_eq!(qtvpr_online_push_f64(o, QUERIES[0].as_ptr(), 4, &mut d), 0);
        assert_eq!((d.consistency, d.consistency_level, d.accept), (0.0, 1.0, false));
        qtvpr_online_free(o);
        // Errors, each named.
        let mut bad = opts;
        bad.size = 8;
        assert!(qtvpr_online_new_with(cal, &bad).is_null());
        let (code, message) = last();
        assert_eq!(code, 4);
        assert!(message.unwrap().starts_with(
            "qtvpr_online_new_with: opts was not initialised by qtvpr_online_options_init: its size is 8"
        ));
        let mut bad = opts;
        bad.sequence = 11;
        assert!(qtvpr_online_new_with(cal, &bad).is_null());
        assert_eq!(
            last(),
            (
                4,
                Some(
                    "qtvpr_online_new_with: sequence 11 is not the calibration's sequence length 1: the length \
                     belongs to the calibration, whose scores were matched over it (calibrate with that length \
                     instead)"
                        .into()
                )
            )
        );
        // A tolerance of 2 rows covers 5 rows: |DB| = 4 cannot tell.
        let mut bad = opts;
        bad.sequence_tolerance = 2.0;
        assert!(qtvpr_online_new_with(cal, &bad).is_null());
        assert_eq!(
            last(),
            (
                4,
                Some(
                    "qtvpr_online_new_with: gate sequence cannot tell a line from chance with |DB| = 4: its \
                     widest tolerance, +-2 rows 2 steps away (sequence tolerance 2 and drift 0), covers 5 rows; it \
                     needs |DB| >= 6"
                        .into()
                )
            )
        );
        let twice = CString::new("margin,margin").unwrap();
        let mut bad = opts;
        bad.gate = twice.as_ptr();
        assert!(qtvpr_online_new_with(cal, &bad).is_null());
        assert_eq!(
            last(),
            (
                4,
                Some("qtvpr_online_new_with: gate names margin twice in \"margin,margin\"".into())
            )
        );
        let mut bad = opts;
        bad.sequence_tolerance = -1.0;
        assert!(qtvpr_online_new_with(cal, &bad).is_null());
        assert_eq!(
            last(),
            (
                4,
                Some("qtvpr_online_new_with: sequence tolerance must be finite and >= 0, got -1".into())
            )
        );
        assert!(qtvpr_online_new_with(ptr::null(), &opts).is_null());
        assert_eq!(last(), (1, Some("qtvpr_online_new_with: cal is NULL".into())));
        // A NULL opts to init is a no-op.
        qtvpr_online_options_init(ptr::null_mut());
        assert_eq!(qtvpr_calibration_sequence(ptr::null()), 0);
        qtvpr_calibration_free(cal);
    }
}

/// The C pushes, f32 and f64 mixed, give what `qtvpr::Online` gives, in both matchings;
/// the calibration is freed first (the state keeps its own reference).
#[test]
fn pushes_are_the_rust_online_decisions() {
    for (matching, gate) in [
        (Matching::Single, Gate::None),
        (Matching::Multi, Gate::None),
        (Matching::Single, Gate::Margin),
        (Matching::Single, Gate::MarginSequence),
    ] {
        let mut rust = Online::new(
            Arc::new(calibration(matching, Some(3))),
            OnlineParams {
                k: 2,
                precision: 1.0,
                window: 3,
                min_window: 2,
                gate,
                sequence_gate: SMALL_GATE,
            },
        )
        .unwrap();
        unsafe {
            let cal = handle(calibration(matching, Some(3)));
            let expected = match matching {
                Matching::Single => qtvpr_matching::QTVPR_SINGLE,
                Matching::Multi => qtvpr_matching::QTVPR_MULTI,
            };
            assert_eq!(qtvpr_calibration_matching(cal), expected as c_int);
            let name = CString::new(gate.as_str()).unwrap();
            let o = qtvpr_online_new_gate(cal, 0, 0.0, 0, 2, name.as_ptr());
            qtvpr_calibration_free(cal);
            for (j, column) in QUERIES.iter().enumerate() {
                let mut d = no_decision();
                let want = if j % 2 == 0 {
                    assert_eq!(qtvpr_online_push_f64(o, column.as_ptr(), 4, &mut d), 0);
                    rust.push(ArrayView1::from(column)).unwrap()
                } else {
                    let column = column.map(|v| v as f32);
                    assert_eq!(qtvpr_online_push_f32(o, column.as_ptr(), 4, &mut d), 0);
                    rust.push(ArrayView1::from(&column)).unwrap()
                };
                assert_eq!(d.query, j);
                assert_record(&d, &want);
                if j == 0 {
                    // Warm-up (min_window 2): query 0 rejects all, at quantile 1 and
                    // the next double above its window's highest score, 0.8.
                    assert_eq!((d.quantile, d.threshold, d.accepted), (1.0, 0.8f64.next_up(), 0));
                }
                assert_eq!(d.quantile.to_bits(), want.quantile.to_bits());
                assert_eq!(d.threshold.to_bits(), want.threshold.to_bits());
                assert_eq!(d.query_quantile.to_bits(), want.query_quantile.to_bits());
                assert_eq!(d.weight.to_bits(), want.weight.to_bits());
                assert_eq!(
                    (d.best, d.score.to_bits(), d.accepted, d.accept),
                    (want.best, want.score.to_bits(), want.accepted, want.accept())
                );
                // The gate's fields, NaN without it.
                let bits = |x: Option<f64>| x.unwrap_or(f64::NAN).to_bits();
                assert_eq!(
                    (d.margin.to_bits(), d.gate.to_bits()),
                    (bits(want.margin), bits(want.gate))
                );
                assert_eq!(d.margin.is_nan(), !gate.margin());
                assert_eq!(
                    (d.consistency.to_bits(), d.consistency_level.to_bits()),
                    (bits(want.consistency), bits(want.consistency_level))
                );
                assert_eq!(d.consistency_level.is_nan(), !gate.sequence());
                // The confidence, whatever the gate (NaN in multi matching).
                assert_eq!(
                    (d.confidence.to_bits(), d.confidence_lower95.to_bits()),
                    (want.confidence.to_bits(), want.confidence_lower95.to_bits())
                );
                // The accepted indices, in full and cut to a buffer of 1.
                let all = rust.accepted();
                let mut out = [usize::MAX; 4];
                assert_eq!(qtvpr_online_accepted(o, out.as_mut_ptr(), 4), all.len());
                assert_eq!(&out[..all.len()], all);
                let mut one = [usize::MAX; 2];
                assert_eq!(qtvpr_online_accepted(o, one.as_mut_ptr(), 1), all.len());
                assert_eq!(one[0], all.first().copied().unwrap_or(usize::MAX));
                assert_eq!(one[1], usize::MAX);
            }
            qtvpr_online_free(o);
        }
    }
}

#[test]
fn loading_names_the_file_and_tells_missing_from_corrupt() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| CString::new(dir.path().join(name).to_str().unwrap()).unwrap();
    let cal = calibration(Matching::Multi, Some(2));
    cal.save(&dir.path().join("cal.npz"), cal.defaults()).unwrap();
    std::fs::write(dir.path().join("corrupt.npz"), b"not a zip archive").unwrap();
    unsafe {
        let loaded = qtvpr_calibration_load(path("cal.npz").as_ptr());
        assert!(!loaded.is_null());
        assert_eq!(last(), (0, None));
        assert_eq!(qtvpr_calibration_db_size(loaded), 4);
        assert_eq!(qtvpr_calibration_matching(loaded), qtvpr_matching::QTVPR_MULTI as c_int);
        assert_eq!((*loaded).inner.defaults(), cal.defaults());
        qtvpr_calibration_free(loaded);

        let missing = path("missing.npz");
        assert!(qtvpr_calibration_load(missing.as_ptr()).is_null());
        let (code, message) = last();
        let message = message.unwrap();
        assert_eq!(code, 5);
        let expected = format!("qtvpr_calibration_load: cannot read {}", missing.to_str().unwrap());
        assert!(message.starts_with(&expected), "{message}");

        let corrupt = path("corrupt.npz");
        assert!(qtvpr_calibration_load(corrupt.as_ptr()).is_null());
        let (code, message) = last();
        assert_eq!(code, 6);
        assert!(message.unwrap().contains(corrupt.to_str().unwrap()));
    }
    assert!(Path::new(&dir.path().join("cal.npz")).exists());
}

#[test]
fn the_version_is_the_crates_and_leaves_the_last_error() {
    unsafe {
        assert_eq!(qtvpr_calibration_db_size(ptr::null()), 0);
        let version = CStr::from_ptr(qtvpr_version()).to_str().unwrap();
        assert_eq!(version, env!("CARGO_PKG_VERSION"));
        assert_eq!(last().0, 1);
    }
}

/// `d` is the core's record `want`, field for field (`qtvpr::Decision::RECORD`): every
/// field is a member of the C struct with the record's value (NaN where the record has
/// none, `null` once serialised, as the record's own JSON has it), and there is no other
/// member.
fn assert_record(d: &qtvpr_decision, want: &qtvpr::Decision) {
    use qtvpr::Value;
    let c = serde_json::to_value(d).unwrap();
    let mut fields: Vec<&str> = qtvpr::Decision::RECORD.iter().map(|f| f.name).collect();
    fields.sort_unstable();
    let members: Vec<&str> = c.as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(members, fields, "the members of qtvpr_decision");
    for field in &qtvpr::Decision::RECORD {
        let value = match field.value(want) {
            None => serde_json::Value::Null,
            Some(Value::Count(n)) => n.into(),
            // A NaN is null, as serde_json writes the C member's NaN.
            Some(Value::Real(x)) => x.into(),
            Some(Value::Flag(b)) => b.into(),
        };
        assert_eq!(c[field.name], value, "qtvpr_decision.{}", field.name);
    }
}

/// The header's `qtvpr_decision` has a member of the C type of its kind for every field
/// of the core's record, and no other (in the ABI's own order).
#[test]
fn the_header_struct_is_the_record() {
    let header = include_str!("../../../include/qtvpr.h");
    // `typedef struct { ... } qtvpr_decision;`: the last struct before that name.
    let body = header.split("} qtvpr_decision;").next().unwrap();
    let body = body.rsplit("typedef struct {").next().unwrap();
    let mut members: Vec<(String, String)> = body
        .lines()
        .map(str::trim)
        .filter(|l| l.ends_with(';') && !l.starts_with('*'))
        .map(|l| {
            let (ty, name) = l.trim_end_matches(';').rsplit_once(' ').unwrap();
            (name.to_string(), ty.to_string())
        })
        .collect();
    members.sort();
    let mut want: Vec<(String, String)> = qtvpr::Decision::RECORD
        .iter()
        .map(|f| {
            let ty = match f.kind {
                qtvpr::Kind::Count => "size_t",
                qtvpr::Kind::Real => "double",
                qtvpr::Kind::Flag => "bool",
            };
            (f.name.to_string(), ty.to_string())
        })
        .collect();
    want.sort();
    assert_eq!(members, want);
}

#[test]
fn more_threads_than_the_cap_is_a_parameter_error() {
    // 2^40 = 1099511627776 threads: refused before one starts (it used to start up to
    // 65,535 of them, one by one).
    assert_eq!(qtvpr_set_threads(1 << 40), code(qtvpr_status::QTVPR_ERR_PARAM));
    let message = "qtvpr_set_threads: threads must be at most 1024, got 1099511627776";
    assert_eq!(last(), (code(qtvpr_status::QTVPR_ERR_PARAM), Some(message.into())));
}
