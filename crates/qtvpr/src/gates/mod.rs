//! The gates of a decision, composed once: a best match is kept when its score reaches
//! the threshold **and** every enabled gate passes.
//!
//! A gate is a second check on each single-match decision (semantics §13, the margin
//! gate, calibrated on the calibration traverse; §15, the sequence gate, at a fixed
//! level). Each is one small type in the file of its section: its *level* and its
//! `passes`, the check of one query's signal against that level ([`QueryGate`]). [`Gates`] holds the gates a request enables, each with its level,
//! and is the one place the accept rule is written ([`Gates::threshold`],
//! [`Gates::keeps`]): the batch transfer, [`crate::Online`] and
//! [`crate::operations::evaluate()`] all take their gates from
//! [`Calibration::gates`](crate::Calibration) and decide through them.
//!
//! A gate plugs in as its type here (a `passes` on [`GateSignals`]), a field of
//! [`Gates`] and of [`GateSignals`], and its name in the request ([`Gate`], a set of
//! gates).

pub(crate) mod margin;
pub(crate) mod sequence;

use crate::error::Result;
use crate::input::params::{Gate, SequenceParams};
use crate::rules::decisions::Matching;
use margin::MarginGate;
use sequence::SequenceGate;

/// What one query shows the gates: the signal each enabled gate reads (`None` for a
/// gate that is off, whose signal is not computed).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct GateSignals {
    /// The column's margin (semantics §13).
    pub(crate) margin: Option<f64>,
    /// The query's consistency with the previous queries of its stream (semantics §15).
    pub(crate) consistency: Option<f64>,
}

/// One gate: its level, found on the calibration, and its check of one query.
pub(crate) trait QueryGate {
    /// The level a query's signal must reach (`+inf`: reject-all).
    fn level(&self) -> f64;
    /// Whether the query's signal reaches the level.
    fn passes(&self, query: &GateSignals) -> bool;
}

/// The gates a request enables, each with its level.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Gates {
    /// The margin gate (semantics §13).
    pub(crate) margin: Option<MarginGate>,
    /// The sequence gate (semantics §15).
    pub(crate) sequence: Option<SequenceGate>,
}

impl Gates {
    /// Each enabled gate.
    fn enabled(&self) -> impl Iterator<Item = &dyn QueryGate> {
        let margin = self.margin.iter().map(|g| g as &dyn QueryGate);
        margin.chain(self.sequence.iter().map(|g| g as &dyn QueryGate))
    }

    /// The gates of this set that `gate` names (each at its level here): a method of the
    /// protocol that decides through some of the gates found once for all.
    pub(crate) fn only(&self, gate: Gate) -> Gates {
        Gates {
            margin: self.margin.filter(|_| gate.margin()),
            sequence: self.sequence.filter(|_| gate.sequence()),
        }
    }

    /// Whether every enabled gate passes `query`.
    pub(crate) fn pass(&self, query: &GateSignals) -> bool {
        self.enabled().all(|g| g.passes(query))
    }

    /// The accept rule: the score a query's best match must reach, `threshold` when
    /// every enabled gate passes the query and `+inf` (nothing: scores are finite)
    /// when one does not.
    pub(crate) fn threshold(&self, threshold: f64, query: &GateSignals) -> f64 {
        if self.pass(query) { threshold } else { f64::INFINITY }
    }

    /// Whether a best match of score `score` is kept at `threshold`
    /// ([`Gates::threshold`]).
    pub(crate) fn keeps(&self, score: f64, threshold: f64, query: &GateSignals) -> bool {
        score >= self.threshold(threshold, query)
    }

    /// The margin gate's level `m*`, when it is on.
    pub(crate) fn margin_level(&self) -> Option<f64> {
        self.margin.map(|g| g.level())
    }

    /// The sequence gate's level, when it is on.
    pub(crate) fn consistency_level(&self) -> Option<f64> {
        self.sequence.map(|g| g.level())
    }
}

/// Check that decisions in `matching` mode over a database of `n_db` images can be
/// gated as `gate` asks, the sequence gate with `sequence`: every gate it enables
/// applies (both need single matching; the margin gate |DB| >= 2, the sequence gate a
/// database its widest tolerance does not cover). A front end checks a request with it
/// before it calibrates; [`Calibration::check_gate`](crate::Calibration::check_gate)
/// checks it against a calibration.
///
/// # Errors
/// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the gate.
pub fn check(gate: Gate, sequence: &SequenceParams, matching: Matching, n_db: usize) -> Result<()> {
    if gate.margin() {
        margin::check(matching, n_db)?;
    }
    if gate.sequence() {
        sequence.check(matching, n_db)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_best_match_is_kept_when_it_reaches_the_threshold_and_every_gate_passes() {
        let none = Gates::default();
        let margin = Gates {
            margin: Some(MarginGate { level: 2.0 }),
            sequence: None,
        };
        let query = |m: f64| GateSignals {
            margin: Some(m),
            consistency: None,
        };
        // No gate: the score alone.
        assert!(none.keeps(0.5, 0.5, &GateSignals::default()));
        assert!(!none.keeps(0.4, 0.5, &GateSignals::default()));
        // The margin gate: both conditions, the margin inclusive as the score is.
        assert!(margin.keeps(0.5, 0.5, &query(2.0)));
        assert!(!margin.keeps(0.5, 0.5, &query(1.9)));
        assert!(!margin.keeps(0.4, 0.5, &query(3.0)));
        assert_eq!(margin.threshold(0.5, &query(1.0)), f64::INFINITY);
        assert_eq!(margin.margin_level(), Some(2.0));
        // Both gates: the score, the margin and the consistency (0.8 at the default
        // level 0.8, inclusive; 0.6 is not enough).
        let both = Gates {
            sequence: Some(SequenceGate {
                params: SequenceParams::default(),
            }),
            ..margin
        };
        let query = |m: f64, c: f64| GateSignals {
            margin: Some(m),
            consistency: Some(c),
        };
        assert!(both.keeps(0.5, 0.5, &query(2.0, 0.8)));
        assert!(!both.keeps(0.5, 0.5, &query(2.0, 0.6)));
        assert!(!both.keeps(0.5, 0.5, &query(1.0, 1.0)));
        assert_eq!((both.margin_level(), both.consistency_level()), (Some(2.0), Some(0.8)));
        // A method's gates, of those found once.
        assert_eq!(both.only(Gate::Sequence).margin, None);
        assert!(both.only(Gate::Sequence).keeps(0.5, 0.5, &query(0.0, 1.0)));
        assert_eq!(both.only(Gate::None), none);
    }

    #[test]
    fn a_set_is_checked_gate_by_gate() {
        let p = SequenceParams::default();
        check(Gate::None, &p, Matching::Multi, 1).unwrap();
        assert!(
            check(Gate::Sequence, &p, Matching::Multi, 100)
                .unwrap_err()
                .to_string()
                .starts_with("gate sequence needs single matching")
        );
        // |DB| = 7 is too small for the sequence gate's +-3 rows, not for the margin gate.
        check(Gate::Margin, &p, Matching::Single, 7).unwrap();
        assert!(
            check(Gate::MarginSequence, &p, Matching::Single, 7)
                .unwrap_err()
                .to_string()
                .ends_with("it needs |DB| >= 8")
        );
        check(Gate::MarginSequence, &p, Matching::Single, 8).unwrap();
    }
}
