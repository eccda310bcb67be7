//! The decision record of semantics §11, and the one list of its fields that every
//! front end lays it out from.
//!
//! [`Decision::RECORD`] names each field once, in the record's order, with its kind, the
//! gate that brings it (the margin gate's `margin` and `gate`, semantics §13; the
//! sequence gate's `consistency` and `consistency_level`, §15) and how to read it. The JSON of a record ([`serde::Serialize`]), the CSV of `qtvpr-cli
//! stream` ([`Decision::fields`], [`Decision::values`]), Python's `OnlineDecision` and
//! `OnlineDecisions` (their attributes, and `qtvpr.dask`'s columns), the C struct and
//! the ROS message are all held to this list, each by a test of its front end. So a
//! field is added here (a field of [`Decision`], a row of [`Decision::RECORD`]), in
//! the C struct and in the ROS message, and a front end that misses it fails its test.

use std::fmt;

use crate::input::params::Gate;

/// The decision of one deployment query: the record of semantics §11, the same values
/// in every front end (the CLI's `stream` line, Python, C, ROS) and in both matching
/// modes. Its fields, in order, are [`Decision::RECORD`].
#[derive(Debug, Clone, Copy)]
pub struct Decision {
    /// Its index in arrival order, from 0.
    pub query: usize,
    /// Its own quantile `q_j` (of its subset threshold among its calibration neighbours).
    pub query_quantile: f64,
    /// Its weight `w_j` (the mean correlation of its neighbours, clipped at 0).
    pub weight: f64,
    /// The window's quantile: the lower weighted median of the window's `q` (1 in warm-up).
    pub quantile: f64,
    /// `theta_j`, that quantile of the window's scores: accept `score >= threshold`.
    pub threshold: f64,
    /// `b_j`, the database index of the column's highest score (the first one): the
    /// matcher's own choice, in both matching modes.
    pub best: usize,
    /// `S[b_j, j]`, its score.
    pub score: f64,
    /// The number of accepted database entries: 0 or 1 in single matching (the best
    /// match, when `score >= threshold` and every enabled gate passes), every entry
    /// `>= threshold` in multi matching.
    pub accepted: usize,
    /// With the margin gate (semantics §13): the column's margin.
    pub margin: Option<f64>,
    /// With the margin gate: `m*`, the margin the best match needs.
    pub gate: Option<f64>,
    /// With the sequence gate (semantics §15): the query's consistency, the share of the
    /// previous queries of its stream whose best matches agree with its own.
    pub consistency: Option<f64>,
    /// With the sequence gate: its level, the consistency the best match needs.
    pub consistency_level: Option<f64>,
    /// semantics §14: the probability that the best match is right, the calibration's
    /// hit rate at the column's PA-score, whatever the gate; NaN in multi matching, with
    /// fewer than 2 database images, or when the calibration has no decision.
    pub confidence: f64,
    /// The one-sided 95% Clopper-Pearson lower bound on `confidence` (NaN where it is).
    pub confidence_lower95: f64,
}

/// What a field of the record holds: how a table of decisions stores it (Python's
/// int64, float64 and bool arrays; C's `size_t`, `double` and `bool`; ROS's `uint64`,
/// `float64` and `bool`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// An index or a count.
    Count,
    /// A real number, NaN where the record has none to give.
    Real,
    /// A truth value.
    Flag,
}

impl Kind {
    /// Its name in Python's `OnlineDecision.RECORD`: `count`, `real` or `flag`.
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Count => "count",
            Kind::Real => "real",
            Kind::Flag => "flag",
        }
    }
}

/// The value of one field of a record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// An index or a count.
    Count(usize),
    /// A real number (NaN: none, JSON's `null`).
    Real(f64),
    /// A truth value.
    Flag(bool),
}

/// Written as a CSV cell: the number, `NaN` for none, `true` or `false`.
impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Count(n) => write!(f, "{n}"),
            Value::Real(x) => write!(f, "{x}"),
            Value::Flag(b) => write!(f, "{b}"),
        }
    }
}

/// A NaN is `None` (JSON's `null`) in every serialiser, not only serde_json.
#[cfg(feature = "serde")]
impl serde::Serialize for Value {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match *self {
            Value::Count(n) => serializer.serialize_u64(n as u64),
            Value::Real(x) if x.is_nan() => serializer.serialize_none(),
            Value::Real(x) => serializer.serialize_f64(x),
            Value::Flag(b) => serializer.serialize_bool(b),
        }
    }
}

/// One field of the decision record.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// Its name: the JSON key, the CSV column, the Python attribute, the C member and
    /// the ROS field.
    pub name: &'static str,
    /// Its name in a table of decisions, one value per query: the attribute of
    /// Python's `OnlineDecisions`, a column of `qtvpr.dask.online`.
    pub column: &'static str,
    /// What it holds.
    pub kind: Kind,
    /// The gate that brings it: [`Gate::None`] for a field of every record, else one
    /// gate ([`Gate::Margin`] or [`Gate::Sequence`]).
    pub gate: Gate,
    /// Its value in a record: `None` in a record decided without its gate.
    get: fn(&Decision) -> Option<Value>,
}

impl Field {
    /// Whether a record decided with the gates `gate` has this field: its gate is one
    /// of them (or it is a field of every record).
    pub fn in_record(&self, gate: Gate) -> bool {
        gate.includes(self.gate)
    }

    /// Its value in `decision`: `None` when the record was decided without its gate.
    pub fn value(&self, decision: &Decision) -> Option<Value> {
        (self.get)(decision)
    }
}

/// A field of every record.
const fn always(name: &'static str, column: &'static str, kind: Kind, get: fn(&Decision) -> Option<Value>) -> Field {
    Field {
        name,
        column,
        kind,
        gate: Gate::None,
        get,
    }
}

/// The names of the fields of [`Decision::RECORD`] that `gate` brings, in order, `N`
/// of them (a count that does not match fails to compile).
const fn names<const N: usize>(gate: Gate) -> [&'static str; N] {
    let mut out = [""; N];
    let (mut i, mut n) = (0, 0);
    while i < Decision::RECORD.len() {
        if Decision::RECORD[i].gate as u8 == gate as u8 {
            assert!(n < N, "more fields of the gate than N");
            out[n] = Decision::RECORD[i].name;
            n += 1;
        }
        i += 1;
    }
    assert!(n == N, "fewer fields of the gate than N");
    out
}

impl Decision {
    /// The record's fields, in order (semantics §11, §13, §14 and §15): what it
    /// serialises to, the columns of a table of decisions, and what every front end lays
    /// out.
    pub const RECORD: [Field; 15] = [
        always("query", "queries", Kind::Count, |d| Some(Value::Count(d.query))),
        always("query_quantile", "query_quantiles", Kind::Real, |d| {
            Some(Value::Real(d.query_quantile))
        }),
        always("weight", "weights", Kind::Real, |d| Some(Value::Real(d.weight))),
        always("quantile", "quantiles", Kind::Real, |d| Some(Value::Real(d.quantile))),
        always("threshold", "thresholds", Kind::Real, |d| {
            Some(Value::Real(d.threshold))
        }),
        always("best", "best", Kind::Count, |d| Some(Value::Count(d.best))),
        always("score", "score", Kind::Real, |d| Some(Value::Real(d.score))),
        always("accepted", "accepted", Kind::Count, |d| Some(Value::Count(d.accepted))),
        always("accept", "accept", Kind::Flag, |d| Some(Value::Flag(d.accept()))),
        always("confidence", "confidences", Kind::Real, |d| {
            Some(Value::Real(d.confidence))
        }),
        always("confidence_lower95", "confidences_lower95", Kind::Real, |d| {
            Some(Value::Real(d.confidence_lower95))
        }),
        Field {
            name: "margin",
            column: "margins",
            kind: Kind::Real,
            gate: Gate::Margin,
            get: |d| d.margin.map(Value::Real),
        },
        Field {
            name: "gate",
            column: "gates",
            kind: Kind::Real,
            gate: Gate::Margin,
            get: |d| d.gate.map(Value::Real),
        },
        Field {
            name: "consistency",
            column: "consistencies",
            kind: Kind::Real,
            gate: Gate::Sequence,
            get: |d| d.consistency.map(Value::Real),
        },
        Field {
            name: "consistency_level",
            column: "consistency_levels",
            kind: Kind::Real,
            gate: Gate::Sequence,
            get: |d| d.consistency_level.map(Value::Real),
        },
    ];

    /// The names of the fields every record has, in order.
    pub const FIELDS: [&'static str; 11] = names(Gate::None);

    /// The fields a record decided with the margin gate has besides
    /// [`Decision::FIELDS`] (semantics §13).
    pub const GATE_FIELDS: [&'static str; 2] = names(Gate::Margin);

    /// The fields a record decided with the sequence gate has besides
    /// [`Decision::FIELDS`] (semantics §15), after the margin gate's when both are on.
    pub const SEQUENCE_FIELDS: [&'static str; 2] = names(Gate::Sequence);

    /// Every field of a record decided with the gates `gate`, in order: the columns of a
    /// table of such records.
    pub fn fields(gate: Gate) -> Vec<&'static str> {
        Self::RECORD
            .iter()
            .filter(|f| f.in_record(gate))
            .map(|f| f.name)
            .collect()
    }

    /// This record's fields and their values, in order (a gate's fields only when it
    /// was decided with that gate).
    pub fn values(&self) -> impl Iterator<Item = (&'static Field, Value)> + '_ {
        Self::RECORD.iter().filter_map(|f| Some((f, f.value(self)?)))
    }

    /// Whether anything is accepted (`accepted > 0`): in single matching, whether the
    /// best match is kept; in multi matching, whether any entry is.
    pub fn accept(&self) -> bool {
        self.accepted > 0
    }
}

/// Every field equal, a NaN equal to a NaN (it stands for "none", as JSON's `null`
/// does), so that the records of multi matching compare as values.
impl PartialEq for Decision {
    fn eq(&self, other: &Self) -> bool {
        let same = |a: Value, b: Value| match (a, b) {
            (Value::Real(a), Value::Real(b)) => a == b || (a.is_nan() && b.is_nan()),
            (a, b) => a == b,
        };
        let (a, b): (Vec<_>, Vec<_>) = (self.values().collect(), other.values().collect());
        a.len() == b.len()
            && a.iter()
                .zip(&b)
                .all(|((f, x), (g, y))| f.name == g.name && same(*x, *y))
    }
}

/// The fields of [`Decision::values`], in order, keyed by name.
#[cfg(feature = "serde")]
impl serde::Serialize for Decision {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let values: Vec<_> = self.values().collect();
        let mut s = serializer.serialize_struct("Decision", values.len())?;
        for (field, value) in values {
            s.serialize_field(field.name, &value)?;
        }
        s.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decision(gated: bool) -> Decision {
        Decision {
            consistency: None,
            consistency_level: None,
            ..margin_gated(gated)
        }
    }

    /// A record with both gates.
    fn both() -> Decision {
        Decision {
            consistency: Some(0.6),
            consistency_level: Some(0.8),
            ..margin_gated(true)
        }
    }

    fn margin_gated(gated: bool) -> Decision {
        Decision {
            query: 3,
            query_quantile: 0.25,
            weight: 0.5,
            quantile: 0.75,
            threshold: 0.5,
            best: 2,
            score: 0.625,
            accepted: 1,
            margin: gated.then_some(2.5),
            gate: gated.then_some(1.5),
            consistency: None,
            consistency_level: None,
            confidence: f64::NAN,
            confidence_lower95: 0.125,
        }
    }

    #[test]
    fn the_record_is_its_list_of_fields() {
        assert_eq!(
            Decision::FIELDS,
            [
                "query",
                "query_quantile",
                "weight",
                "quantile",
                "threshold",
                "best",
                "score",
                "accepted",
                "accept",
                "confidence",
                "confidence_lower95"
            ]
        );
        assert_eq!(Decision::GATE_FIELDS, ["margin", "gate"]);
        assert_eq!(Decision::SEQUENCE_FIELDS, ["consistency", "consistency_level"]);
        assert_eq!(Decision::fields(Gate::None), Decision::FIELDS);
        assert_eq!(
            Decision::fields(Gate::Margin),
            [&Decision::FIELDS[..], &Decision::GATE_FIELDS[..]].concat()
        );
        assert_eq!(
            Decision::fields(Gate::Sequence),
            [&Decision::FIELDS[..], &Decision::SEQUENCE_FIELDS[..]].concat()
        );
        assert_eq!(
            Decision::fields(Gate::MarginSequence),
            [
                &Decision::FIELDS[..],
                &Decision::GATE_FIELDS[..],
                &Decision::SEQUENCE_FIELDS[..]
            ]
            .concat()
        );
        let sequence_only = Decision {
            margin: None,
            gate: None,
            ..both()
        };
        let names = |d: &Decision| d.values().map(|(f, _)| f.name).collect::<Vec<_>>();
        assert_eq!(names(&decision(false)), Decision::fields(Gate::None));
        assert_eq!(names(&decision(true)), Decision::fields(Gate::Margin));
        assert_eq!(names(&sequence_only), Decision::fields(Gate::Sequence));
        assert_eq!(names(&both()), Decision::fields(Gate::MarginSequence));
        // CSV cells: the numbers, NaN, true.
        let cells: Vec<String> = decision(true).values().map(|(_, v)| v.to_string()).collect();
        assert_eq!(cells.join(","), "3,0.25,0.5,0.75,0.5,2,0.625,1,true,NaN,0.125,2.5,1.5");
        let cells: Vec<String> = both().values().map(|(_, v)| v.to_string()).collect();
        assert_eq!(
            cells.join(","),
            "3,0.25,0.5,0.75,0.5,2,0.625,1,true,NaN,0.125,2.5,1.5,0.6,0.8"
        );
    }

    #[test]
    fn records_compare_as_values() {
        assert_eq!(decision(true), decision(true));
        assert_ne!(decision(true), decision(false));
        assert_ne!(both(), decision(true));
        assert_ne!(
            decision(false),
            Decision {
                best: 1,
                ..decision(false)
            }
        );
    }

    #[cfg(feature = "serde")]
    #[test]
    fn json_follows_the_list_and_a_nan_is_null() {
        assert_eq!(
            serde_json::to_string(&decision(true)).unwrap(),
            r#"{"query":3,"query_quantile":0.25,"weight":0.5,"quantile":0.75,"threshold":0.5,"best":2,"score":0.625,"accepted":1,"accept":true,"confidence":null,"confidence_lower95":0.125,"margin":2.5,"gate":1.5}"#
        );
        assert!(
            serde_json::to_string(&both())
                .unwrap()
                .ends_with(r#""margin":2.5,"gate":1.5,"consistency":0.6,"consistency_level":0.8}"#)
        );
    }
}
