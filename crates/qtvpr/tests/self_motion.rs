//! semantics §16, self-motion labels, through the public API: a database that is not a
//! sequence labels nothing positive; the labels' record travels from a ground-truth
//! `.npz` to the calibration file and back; a bad record, or multi matching on such
//! labels, is refused. (The rule's own cases, a stop, a reverse traverse, a wrong match,
//! are the unit tests of `signals/self_motion.rs`.)
#![cfg(feature = "npy")]

use ndarray::Array2;
use qtvpr::npy::{NpyArray, read_ground_truth, write_ground_truth, write_npz};
use qtvpr::{Calibration, Defaults, LabelParams, Matching, SelfMotionLabel, Truth, self_motion_labels};

/// A |DB| x |Q| matrix whose column j's best match is row `best[j]`.
fn matrix(n_db: usize, best: &[usize]) -> Array2<f64> {
    Array2::from_shape_fn((n_db, best.len()), |(i, j)| if i == best[j] { 1.0 } else { 0.0 })
}

/// The stop of the unit tests: rows 100..=110, row 110 for 19 more queries, 111..=120.
fn stop() -> Array2<f64> {
    let best: Vec<usize> = (100..=110).chain([110; 19]).chain(111..=120).collect();
    matrix(200, &best)
}

#[test]
fn a_database_that_is_not_a_sequence_labels_nothing_positive() {
    // A forward traverse (query q at row 100 + q) over a database whose rows were shuffled
    // by r -> 7 r mod 200: consecutive queries' best matches lie 7 rows apart (or 193 back
    // across the wrap), so a neighbour d away is 6 |d| (or more) from its prediction q + d,
    // beyond 2 + 0.2 |d| for every d >= 1: no neighbour agrees, f = 0, all 40 negative.
    let best: Vec<usize> = (0..40).map(|q| 7 * (100 + q) % 200).collect();
    let err = self_motion_labels(matrix(200, &best).view(), &LabelParams::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("self-motion labels found no pseudo-positive: no calibration query's best match agrees with 70% of its neighbours (40 queries: 40 negative, 0 abstained)"),
        "{err}"
    );
    // Told the spacing (7 rows per query), the same traverse is a line again on each side
    // of the wrap (between queries 14, row 198, and 15, row 5): queries 0..=9 and 20..=39
    // see none of it among their neighbours, all of which agree: positive.
    let seven = LabelParams::resolve(None, None, None, Some(7.0), None, None).unwrap();
    let labels = self_motion_labels(matrix(200, &best).view(), &seven).unwrap();
    let away: Vec<_> = labels.labels[..10].iter().chain(&labels.labels[20..]).collect();
    assert!(
        away.iter().all(|&&l| l == SelfMotionLabel::Positive),
        "{:?}",
        labels.labels
    );
}

#[test]
fn the_record_travels_from_the_ground_truth_file_to_the_calibration_file() {
    let dir = tempfile::tempdir().unwrap();
    let (gt_path, cal_path) = (dir.path().join("gt.npz"), dir.path().join("cal.npz"));
    let s = stop();
    let labels = self_motion_labels(s.view(), &LabelParams::default()).unwrap();
    let hs = labels.ground_truth();
    let record = labels.record();
    write_ground_truth(
        &gt_path,
        hs.hard.view(),
        hs.soft.as_ref().map(|m| m.view()),
        Some(&record),
    )
    .unwrap();

    let gt = read_ground_truth(&gt_path, None).unwrap();
    let json = |r: &qtvpr::LabelRecord| serde_json::from_str::<serde_json::Value>(r.json()).unwrap();
    assert_eq!(json(gt.record().unwrap()), json(&record));
    // Query 20 stands inside the stop (f = 4 / 10): its best match, row 110, is ignored.
    assert_eq!(gt.view()[[110, 20]], Truth::Ignored);
    assert_eq!(gt.view(), labels.truth().view());

    let cal = Calibration::new(s.view(), &gt, Matching::Single).unwrap();
    assert_eq!(cal.labels().map(json), Some(json(&record)));
    cal.save(&cal_path, &Defaults::default()).unwrap();
    let back = Calibration::load(&cal_path).unwrap();
    assert_eq!(back.labels().map(json), Some(json(&record)));
    assert_eq!(json(back.labels().unwrap())["abstain"], 14);

    // Multi matching on such labels is refused, on the ground truth as read.
    let Err(err) = Calibration::new(s.view(), &gt, Matching::Multi) else {
        panic!("multi matching on self-motion labels was accepted");
    };
    let err = err.to_string();
    assert!(err.contains("multi does not apply to self-motion labels"), "{err}");
    // The same labels without their record (a .npy) are ordinary ground truth.
    let plain = qtvpr::GroundTruth::from_truth(gt.view().to_owned());
    assert!(
        Calibration::new(s.view(), &plain, Matching::Single)
            .unwrap()
            .labels()
            .is_none()
    );
}

#[test]
fn a_labels_member_that_is_not_a_record_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let hard = Array2::from_shape_fn((3, 2), |(i, j)| i == j);
    for (text, why) in [
        ("not json", "is not JSON"),
        ("[1]", "is not a JSON object but [1]"),
        (
            r#"{"labels": "gnss"}"#,
            r#"names the rule "gnss"; qtvpr knows "self-motion""#,
        ),
    ] {
        let path = dir.path().join("gt.npz");
        write_npz(
            &path,
            &[("GThard", NpyArray::Bool(hard.view())), ("labels", NpyArray::Str(text))],
        )
        .unwrap();
        let err = read_ground_truth(&path, None).unwrap_err().to_string();
        assert!(err.contains("labels") && err.contains(why), "{text}: {err}");
    }
    // A ground-truth archive without the member is VPR_Tutorial's: no record.
    let path = dir.path().join("plain.npz");
    write_ground_truth(&path, hard.view(), None, None).unwrap();
    assert!(read_ground_truth(&path, None).unwrap().record().is_none());
}
