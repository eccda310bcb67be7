//! semantics §16: self-motion labels, ground truth for a calibration traverse from the
//! order of its own queries, for a robot without GNSS.
//!
//! A robot knows that its consecutive images are consecutive places. A calibration
//! query's best match is believed (a *pseudo-positive*) when the best matches of its
//! neighbours on the traverse, before and after it, lie on its line (the agreement of
//! semantics §15, [`Line`]), disbelieved (a *pseudo-negative*) when few of them do, and
//! left undecided (the query *abstains*) in between. The labels judge one entry per
//! column, the best match, so they serve single matching only; as ground truth they make
//! the pseudo-positive best match the column's one hard positive, a pseudo-negative
//! column one without a positive, and an abstaining best match a soft-only (ignored)
//! entry. The levels were chosen by measurement (`docs/self-motion-labels.md`).

use std::fmt;

use ndarray::{Array2, ArrayView2};

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::extensions::ground_truth::HardSoft;
#[cfg(feature = "npy")]
use crate::input::LabelRecord;
use crate::input::{GroundTruth, Score, validate_scores};
use crate::rules::agreement::Line;
use crate::rules::decisions::{Matching, best_match};

/// The rule a [`LabelRecord`] of self-motion labels names: `{"labels": "self-motion", ...}`.
pub const SELF_MOTION: &str = "self-motion";

/// Neighbours on each side when none is given.
pub const DEFAULT_NEIGHBOURS: usize = 5;
/// The share of agreeing neighbours that makes a pseudo-positive when none is given.
pub const DEFAULT_POSITIVE_LEVEL: f64 = 0.7;
/// The share at or below which a query is a pseudo-negative when none is given.
pub const DEFAULT_NEGATIVE_LEVEL: f64 = 0.3;

/// The slack of the levels (semantics §3's), so that `0.7 * 10` agreeing is 7.
const LEVEL_SLACK: f64 = 1e-12;

/// The parameters of self-motion labels (semantics §16).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct LabelParams {
    /// `N >= 1`: the neighbours on each side a best match is judged by.
    pub neighbours: usize,
    /// The share of agreeing neighbours at or above which a best match is a
    /// pseudo-positive.
    pub positive_level: f64,
    /// The share at or below which it is a pseudo-negative (`< positive_level`; in
    /// between, the query abstains).
    pub negative_level: f64,
    /// The agreement (`speed`, `tolerance`, `drift`), as the sequence gate's.
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub line: Line,
}

impl Default for LabelParams {
    fn default() -> Self {
        Self {
            neighbours: DEFAULT_NEIGHBOURS,
            positive_level: DEFAULT_POSITIVE_LEVEL,
            negative_level: DEFAULT_NEGATIVE_LEVEL,
            line: Line::default(),
        }
    }
}

impl LabelParams {
    /// The parameters given, each `None` its default (5 neighbours, levels 0.7 and 0.3,
    /// and the agreement's speed 1, tolerance 2 and drift 0.2), checked
    /// ([`LabelParams::validate`]): what every front end hands over as the user gave it.
    ///
    /// # Errors
    /// As [`LabelParams::validate`].
    pub fn resolve(
        neighbours: Option<usize>,
        positive_level: Option<f64>,
        negative_level: Option<f64>,
        speed: Option<f64>,
        tolerance: Option<f64>,
        drift: Option<f64>,
    ) -> Result<Self> {
        let (default, line) = (Self::default(), Line::default());
        let params = Self {
            neighbours: neighbours.unwrap_or(default.neighbours),
            positive_level: positive_level.unwrap_or(default.positive_level),
            negative_level: negative_level.unwrap_or(default.negative_level),
            line: Line {
                speed: speed.unwrap_or(line.speed),
                tolerance: tolerance.unwrap_or(line.tolerance),
                drift: drift.unwrap_or(line.drift),
            },
        };
        params.validate()?;
        Ok(params)
    }

    /// Check `neighbours >= 1`, `0 <= negative_level < positive_level <= 1` and the line
    /// ([`Line::validate`]).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        if self.neighbours < 1 {
            return Err(Error::param(
                "neighbours",
                format!("must be >= 1, got {}", self.neighbours),
            ));
        }
        let (negative, positive) = (self.negative_level, self.positive_level);
        if !(positive > 0.0 && positive <= 1.0) {
            return Err(Error::param(
                "positive level",
                format!("must be in (0, 1], got {positive}"),
            ));
        }
        if !(negative >= 0.0 && negative < positive) {
            return Err(Error::param(
                "negative level",
                format!("must be at least 0 and below the positive level ({positive}), got {negative}"),
            ));
        }
        self.line.validate()
    }
}

/// What the self-motion labels say of one calibration query's best match.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SelfMotionLabel {
    /// Its neighbours agree with it: taken as right.
    Positive,
    /// Few of them do: taken as wrong.
    Negative,
    /// In between: neither (no decision).
    Abstain,
}

impl SelfMotionLabel {
    /// Its name in output: `positive`, `negative` or `abstain`.
    pub fn as_str(self) -> &'static str {
        match self {
            SelfMotionLabel::Positive => "positive",
            SelfMotionLabel::Negative => "negative",
            SelfMotionLabel::Abstain => "abstain",
        }
    }
}

/// The self-motion labels of a calibration traverse.
#[derive(Debug, Clone, PartialEq)]
pub struct SelfMotionLabels {
    /// The parameters they were found with.
    pub params: LabelParams,
    /// |DB|.
    pub db_size: usize,
    /// Each calibration query's best match (semantics §2: the first maximum).
    pub best: Vec<usize>,
    /// Each query's share of agreeing neighbours, `f_q`.
    pub agreement: Vec<f64>,
    /// Each query's label.
    pub labels: Vec<SelfMotionLabel>,
}

/// How many calibration queries each label has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct LabelCounts {
    /// Pseudo-positives.
    pub positive: usize,
    /// Pseudo-negatives.
    pub negative: usize,
    /// Queries that abstain.
    pub abstain: usize,
}

impl SelfMotionLabels {
    /// How many queries have `label`.
    pub fn count(&self, label: SelfMotionLabel) -> usize {
        self.labels.iter().filter(|&&l| l == label).count()
    }

    /// How many queries have each label.
    pub fn counts(&self) -> LabelCounts {
        LabelCounts {
            positive: self.count(SelfMotionLabel::Positive),
            negative: self.count(SelfMotionLabel::Negative),
            abstain: self.count(SelfMotionLabel::Abstain),
        }
    }

    /// The record of these labels (semantics §16): the rule, its parameters and the
    /// counts, one JSON object, e.g. `{"labels": "self-motion", "neighbours": 5,
    /// "positive_level": 0.7, "negative_level": 0.3, "speed": 1.0, "tolerance": 2.0,
    /// "drift": 0.2, "queries": 11, "positive": 9, "negative": 0, "abstain": 2}`: what a
    /// ground-truth `.npz` holds in its `labels` member, a calibration file in `meta`'s
    /// `"labels"`, and `qtvpr-cli ground-truth --from-sequence --format json` prints.
    #[cfg(feature = "npy")]
    pub fn record(&self) -> LabelRecord {
        /// The record's keys, in this order (a struct: `serde_json::json!` sorts them).
        #[derive(serde::Serialize)]
        struct Record {
            labels: &'static str,
            neighbours: usize,
            positive_level: f64,
            negative_level: f64,
            speed: f64,
            tolerance: f64,
            drift: f64,
            queries: usize,
            positive: usize,
            negative: usize,
            abstain: usize,
        }
        let (p, counts) = (&self.params, self.counts());
        let record = Record {
            labels: SELF_MOTION,
            neighbours: p.neighbours,
            positive_level: p.positive_level,
            negative_level: p.negative_level,
            speed: p.line.speed,
            tolerance: p.line.tolerance,
            drift: p.line.drift,
            queries: self.labels.len(),
            positive: counts.positive,
            negative: counts.negative,
            abstain: counts.abstain,
        };
        LabelRecord::new(serde_json::to_string(&record).expect("a record serialises"))
    }

    /// The labels as the core's ground truth (as [`SelfMotionLabels::ground_truth`]:
    /// a pseudo-positive's best match true, an abstaining query's ignored), carrying
    /// their [`record`](SelfMotionLabels::record), so that a calibration on them says so.
    #[cfg(feature = "npy")]
    pub fn truth(&self) -> GroundTruth {
        let HardSoft { hard, soft } = self.ground_truth();
        let soft = soft.expect("self-motion labels have a soft ground truth");
        GroundTruth::new(hard.view())
            .and_then(|gt| gt.with_soft(soft.view()))
            .expect("two non-empty bool matrices of one shape")
            .with_record(Some(self.record()))
    }

    /// The labels as ground truth, |DB| x |Qcal|: a pseudo-positive's best match is the
    /// column's one hard positive, a pseudo-negative's column has none, an abstaining
    /// query's best match is soft only (an ignored entry: no decision). The soft matrix
    /// holds the hard one's entries too, as VPR_Tutorial's `GTsoft` does.
    pub fn ground_truth(&self) -> HardSoft {
        let shape = (self.db_size, self.labels.len());
        let (mut hard, mut soft) = (Array2::from_elem(shape, false), Array2::from_elem(shape, false));
        for (q, (&b, &label)) in self.best.iter().zip(&self.labels).enumerate() {
            hard[[b, q]] = label == SelfMotionLabel::Positive;
            soft[[b, q]] = label != SelfMotionLabel::Negative;
        }
        HardSoft { hard, soft: Some(soft) }
    }
}

/// One line for a person: `self-motion labels of 11 calibration queries: 9 positive, 0
/// negative, 2 abstained`.
impl fmt::Display for SelfMotionLabels {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = self.counts();
        write!(
            f,
            "self-motion labels of {} calibration queries: {} positive, {} negative, {} abstained",
            self.labels.len(),
            c.positive,
            c.negative,
            c.abstain
        )
    }
}

/// Check a record read from a file (a ground truth's `labels` member, a calibration's
/// `meta.labels`): a JSON object that names the self-motion rule. Its other keys are kept
/// as they are. `Err` says what is wrong, for the caller to name the file and member.
#[cfg(feature = "npy")]
pub(crate) fn check_record(value: serde_json::Value) -> std::result::Result<LabelRecord, String> {
    match value.get("labels") {
        _ if !value.is_object() => Err(format!("is not a JSON object but {value}")),
        Some(serde_json::Value::String(rule)) if rule == SELF_MOTION => Ok(LabelRecord::new(value.to_string())),
        Some(rule) => Err(format!("names the rule {rule}; qtvpr knows \"{SELF_MOTION}\"")),
        None => Err(format!(
            "names no rule: it has no \"labels\" key (\"labels\": \"{SELF_MOTION}\")"
        )),
    }
}

/// Self-motion labels judge one entry per column, the best match: a calibration on them
/// is single matching (semantics §16).
///
/// # Errors
/// [`Error::InvalidParameter`] naming `matching` when `gt` carries a record and
/// `matching` is multi.
pub(crate) fn check_matching(gt: &GroundTruth, matching: Matching) -> Result<()> {
    match (gt.record(), matching) {
        (Some(_), Matching::Multi) => Err(Error::param(
            "matching",
            "multi does not apply to self-motion labels (semantics §16), which judge one entry per column, the best \
             match: in multi matching the right neighbours of a right match would count as wrong; use single matching",
        )),
        _ => Ok(()),
    }
}

/// The self-motion labels (semantics §16) of a calibration traverse `s_cal` (|DB| x
/// |Qcal|, its columns in the order the queries were taken).
///
/// # Errors
/// Invalid `params` ([`LabelParams::validate`]); empty or non-finite scores; fewer than
/// `neighbours + 1` queries; a database too small for the tolerance
/// ([`Line`]: `2 floor(a + b N) + 1 >= |DB|`); and no pseudo-positive at all (a
/// calibration on such labels would reject every query), each
/// [`Error::InvalidParameter`] saying why.
pub fn self_motion_labels<T: Score>(s_cal: ArrayView2<'_, T>, params: &LabelParams) -> Result<SelfMotionLabels> {
    params.validate()?;
    validate_scores(Input::CalSimilarity, s_cal)?;
    let (n_db, n_cal) = s_cal.dim();
    let n = params.neighbours;
    if n_cal <= n {
        return Err(Error::param(
            "self-motion labels",
            format!(
                "need at least {} calibration queries in the order they were taken (each best match is judged \
                 by its {n} neighbours on each side), got {n_cal}",
                n + 1
            ),
        ));
    }
    params.line.check_database("self-motion labels", n, n_db)?;
    let best: Vec<usize> = s_cal.columns().into_iter().map(best_match).collect();
    let (agreement, labels): (Vec<f64>, Vec<SelfMotionLabel>) = (0..n_cal)
        .map(|q| {
            let reach = n as isize;
            let neighbours: Vec<(isize, usize)> = (-reach..=reach)
                .filter(|&d| d != 0)
                .filter_map(|d| Some((d, *best.get(q.checked_add_signed(d)?)?)))
                .collect();
            let f = params.line.agreeing(best[q], neighbours.iter().copied()) as f64 / neighbours.len() as f64;
            let label = if f >= params.positive_level - LEVEL_SLACK {
                SelfMotionLabel::Positive
            } else if f <= params.negative_level + LEVEL_SLACK {
                SelfMotionLabel::Negative
            } else {
                SelfMotionLabel::Abstain
            };
            (f, label)
        })
        .unzip();
    let labels = SelfMotionLabels {
        params: *params,
        db_size: n_db,
        best,
        agreement,
        labels,
    };
    if labels.count(SelfMotionLabel::Positive) == 0 {
        return Err(Error::param(
            "self-motion labels",
            format!(
                "found no pseudo-positive: no calibration query's best match agrees with {}% of its neighbours \
                 ({n_cal} queries: {} negative, {} abstained); the calibration traverse does not follow the \
                 database's route (it is not a sequence, runs backwards: sequence speed -1, or at another \
                 spacing: sequence speed), or its matcher is rarely right",
                params.positive_level * 100.0,
                labels.count(SelfMotionLabel::Negative),
                labels.count(SelfMotionLabel::Abstain),
            ),
        ));
    }
    Ok(labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A |DB| x |Q| matrix whose column j's best match is row `best[j]`.
    fn matrix(n_db: usize, best: &[usize]) -> Array2<f64> {
        Array2::from_shape_fn((n_db, best.len()), |(i, j)| if i == best[j] { 1.0 } else { 0.0 })
    }

    fn labels_of(n_db: usize, best: &[usize], params: &LabelParams) -> Result<SelfMotionLabels> {
        self_motion_labels(matrix(n_db, best).view(), params)
    }

    /// `+` positive, `-` negative, `?` abstain.
    fn signs(labels: &SelfMotionLabels) -> String {
        let sign = |l: &SelfMotionLabel| match l {
            SelfMotionLabel::Positive => '+',
            SelfMotionLabel::Negative => '-',
            SelfMotionLabel::Abstain => '?',
        };
        labels.labels.iter().map(sign).collect()
    }

    #[test]
    fn a_forward_traverse_is_all_positive_and_its_ground_truth_is_its_best_matches() {
        // b_q = 100 + q: every neighbour on the line. Query 0 has 5 neighbours (after it),
        // query 3 has 3 + 5 = 8: all agree, f = 1.
        let best: Vec<usize> = (100..112).collect();
        let l = labels_of(200, &best, &LabelParams::default()).unwrap();
        assert_eq!(signs(&l), "+".repeat(12));
        assert_eq!(l.agreement, [1.0; 12]);
        let gt = l.ground_truth();
        assert_eq!(gt.hard.iter().filter(|&&t| t).count(), 12);
        assert!(gt.hard[[103, 3]] && !gt.hard[[104, 3]]);
        assert_eq!(gt.soft.unwrap(), gt.hard);
    }

    #[test]
    fn a_stop_abstains_and_a_wrong_match_is_negative() {
        // 100..=110 (queries 0..=10), row 110 for queries 11..=29 (the robot stands
        // still), then 111..=120. Deep in the stop (e.g. query 20), of its 10 neighbours
        // (all at 110) only d = +-1, +-2 lie within 2 + 0.2 |d| of 110 + d: f = 0.4,
        // between the levels: abstain.
        let best: Vec<usize> = (100..=110).chain([110; 19]).chain(111..=120).collect();
        let l = labels_of(200, &best, &LabelParams::default()).unwrap();
        assert_eq!(l.agreement[20], 0.4);
        assert_eq!(l.labels[20], SelfMotionLabel::Abstain);
        assert_eq!(l.count(SelfMotionLabel::Negative), 0);
        // One wrong match in a forward traverse: none of its neighbours agree (0:
        // negative), and each neighbour loses one of its 10 (0.9: still positive).
        let mut best: Vec<usize> = (100..120).collect();
        best[10] = 50;
        let l = labels_of(200, &best, &LabelParams::default()).unwrap();
        assert_eq!(l.labels[10], SelfMotionLabel::Negative);
        assert_eq!(l.agreement[9], 0.9);
        assert_eq!(l.count(SelfMotionLabel::Positive), 19);
        // The ground truth: no positive in column 10, one soft-only entry nowhere.
        let gt = l.ground_truth();
        assert!(!gt.hard.column(10).iter().any(|&t| t));
        assert!(!gt.soft.unwrap().column(10).iter().any(|&t| t));
    }

    #[test]
    fn an_abstaining_best_match_is_soft_only() {
        let best: Vec<usize> = (100..=110).chain([110; 19]).chain(111..=120).collect();
        let l = labels_of(200, &best, &LabelParams::default()).unwrap();
        let (gt, q) = (l.ground_truth(), 20);
        assert!(!gt.hard[[110, q]] && gt.soft.unwrap()[[110, q]]);
    }

    #[test]
    fn a_reverse_traverse_has_no_positive_unless_its_speed_is_minus_one() {
        // b_q = 139 - q: at v = 1 a neighbour d away lies 2 |d| from the prediction, so
        // only d = +-1 agree (2 <= 2.2): f <= 2 / 5 for the ends, 2 / 10 inside.
        let best: Vec<usize> = (0..40).map(|q| 139 - q).collect();
        let err = labels_of(200, &best, &LabelParams::default()).unwrap_err().to_string();
        assert!(err.starts_with("self-motion labels found no pseudo-positive"), "{err}");
        let back = LabelParams {
            line: Line {
                speed: -1.0,
                ..Line::default()
            },
            ..LabelParams::default()
        };
        assert_eq!(signs(&labels_of(200, &best, &back).unwrap()), "+".repeat(40));
    }

    #[test]
    #[cfg(feature = "npy")]
    fn the_record_says_the_rule_its_parameters_and_the_counts() {
        // The wrong match of the test above: query 10 negative, the other 19 positive
        // (each has at most one wrong neighbour of its 9 or 10: f >= 8 / 9), none abstains.
        let mut best: Vec<usize> = (100..120).collect();
        best[10] = 50;
        let l = labels_of(200, &best, &LabelParams::default()).unwrap();
        assert_eq!(
            l.counts(),
            LabelCounts {
                positive: 19,
                negative: 1,
                abstain: 0
            }
        );
        assert_eq!(
            l.to_string(),
            "self-motion labels of 20 calibration queries: 19 positive, 1 negative, 0 abstained"
        );
        assert_eq!(
            l.record().json(),
            r#"{"labels":"self-motion","neighbours":5,"positive_level":0.7,"negative_level":0.3,"speed":1.0,"#
                .to_owned()
                + r#""tolerance":2.0,"drift":0.2,"queries":20,"positive":19,"negative":1,"abstain":0}"#
        );
        // A record read back is checked, and kept as it is.
        let record = check_record(serde_json::from_str(l.record().json()).unwrap()).unwrap();
        assert_eq!(
            serde_json::from_str::<serde_json::Value>(record.json()).unwrap(),
            serde_json::from_str::<serde_json::Value>(l.record().json()).unwrap()
        );
    }

    #[test]
    #[cfg(feature = "npy")]
    fn a_record_must_be_an_object_naming_the_rule() {
        let check = |text: &str| check_record(serde_json::from_str(text).unwrap()).map(|r| r.json().to_owned());
        assert_eq!(
            check(r#"{"labels": "self-motion", "note": 1}"#).unwrap(),
            r#"{"labels":"self-motion","note":1}"#
        );
        assert_eq!(check("[1]").unwrap_err(), "is not a JSON object but [1]");
        assert_eq!(
            check(r#"{"labels": "gnss"}"#).unwrap_err(),
            r#"names the rule "gnss"; qtvpr knows "self-motion""#
        );
        assert_eq!(
            check(r#"{"neighbours": 5}"#).unwrap_err(),
            r#"names no rule: it has no "labels" key ("labels": "self-motion")"#
        );
    }

    #[test]
    #[cfg(feature = "npy")]
    fn as_the_cores_ground_truth_an_abstaining_match_is_ignored_and_the_record_rides_along() {
        use crate::input::Truth;
        // The stop of `a_stop_abstains_and_a_wrong_match_is_negative`: query 20 abstains at
        // row 110; query 0 (f = 1) is positive at row 100.
        let best: Vec<usize> = (100..=110).chain([110; 19]).chain(111..=120).collect();
        let l = labels_of(200, &best, &LabelParams::default()).unwrap();
        let truth = l.truth();
        assert_eq!(truth.view()[[110, 20]], Truth::Ignored);
        assert_eq!(truth.view()[[100, 0]], Truth::True);
        // One entry per column is not false: 40 in all.
        assert_eq!(truth.view().iter().filter(|&&t| t != Truth::False).count(), 40);
        assert_eq!(truth.record(), Some(&l.record()));
        // The same entries as the hard and soft matrices.
        let HardSoft { hard, soft } = l.ground_truth();
        let again = GroundTruth::new(hard.view())
            .unwrap()
            .with_soft(soft.unwrap().view())
            .unwrap();
        assert_eq!(again.view(), truth.view());
    }

    #[test]
    fn parameters_not_given_are_the_defaults() {
        assert_eq!(
            LabelParams::resolve(None, None, None, None, None, None).unwrap(),
            LabelParams::default()
        );
        let back = LabelParams::resolve(Some(3), None, Some(0.2), Some(-1.0), None, None).unwrap();
        assert_eq!((back.neighbours, back.negative_level, back.line.speed), (3, 0.2, -1.0));
        let err = |r: Result<LabelParams>| r.unwrap_err().to_string();
        assert_eq!(
            err(LabelParams::resolve(Some(0), None, None, None, None, None)),
            "neighbours must be >= 1, got 0"
        );
        assert_eq!(
            err(LabelParams::resolve(None, Some(1.5), None, None, None, None)),
            "positive level must be in (0, 1], got 1.5"
        );
        assert_eq!(
            err(LabelParams::resolve(None, None, None, None, Some(-1.0), None)),
            "sequence tolerance must be finite and >= 0, got -1"
        );
    }

    #[test]
    fn too_few_queries_a_small_database_and_bad_levels_are_errors() {
        let p = LabelParams::default();
        let err = |n_db: usize, best: &[usize], p: &LabelParams| labels_of(n_db, best, p).unwrap_err().to_string();
        assert_eq!(
            err(200, &[100, 101, 102, 103, 104], &p),
            "self-motion labels need at least 6 calibration queries in the order they were taken (each best \
             match is judged by its 5 neighbours on each side), got 5"
        );
        // Six queries: each has exactly 5 neighbours, all on the line.
        assert_eq!(
            signs(&labels_of(200, &(100..106).collect::<Vec<_>>(), &p).unwrap()),
            "++++++"
        );
        assert!(err(7, &[0, 1, 2, 3, 4, 5], &p).ends_with("it needs |DB| >= 8"));
        let bad = LabelParams {
            negative_level: 0.7,
            ..p
        };
        assert_eq!(
            err(200, &[0; 6], &bad),
            "negative level must be at least 0 and below the positive level (0.7), got 0.7"
        );
    }
}
