//! The gates of a decision, composed once: a best match is kept when its score reaches
//! the threshold **and** every enabled gate passes.
//!
//! A gate is a second, scale-free check on each single-match decision, calibrated on
//! the calibration traverse (semantics §13, the margin gate, is the first). Each is one
//! small type in the file of its section: its *level*, found on the calibration, and
//! its `passes`, the check of one query's signal against that level
//! ([`QueryGate`]). [`Gates`] holds the gates a request enables, each with its level,
//! and is the one place the accept rule is written ([`Gates::threshold`],
//! [`Gates::keeps`]): the batch transfer, [`crate::Online`] and
//! [`crate::operations::evaluate()`] all take their gates from
//! [`Calibration::gates`](crate::Calibration) and decide through them.
//!
//! A gate plugs in beside the margin gate as its type here (a `passes` on
//! [`GateSignals`]), a field of [`Gates`] and of [`GateSignals`], and its name in the
//! request ([`Gate`]).

pub(crate) mod margin;
pub(crate) mod sequence;

use crate::error::Result;
use crate::input::params::Gate;
use crate::rules::decisions::Matching;
use margin::MarginGate;

/// What one query shows the gates: the signal each enabled gate reads (`None` for a
/// gate that is off, whose signal is not computed).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct GateSignals {
    /// The column's margin (semantics §13).
    pub(crate) margin: Option<f64>,
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
}

impl Gates {
    /// Each enabled gate.
    fn enabled(&self) -> impl Iterator<Item = &dyn QueryGate> {
        self.margin.iter().map(|g| g as &dyn QueryGate)
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
}

/// Check that decisions in `matching` mode over a database of `n_db` images can be
/// gated as `gate` asks: every gate it enables applies (the margin gate needs single
/// matching and |DB| >= 2). A front end checks a request with it before it calibrates;
/// [`Calibration::check_gate`](crate::Calibration::check_gate) checks it against a
/// calibration.
///
/// # Errors
/// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the gate.
pub fn check(gate: Gate, matching: Matching, n_db: usize) -> Result<()> {
    if gate == Gate::Margin {
        margin::check(matching, n_db)?;
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
        };
        let query = |m: f64| GateSignals { margin: Some(m) };
        // No gate: the score alone.
        assert!(none.keeps(0.5, 0.5, &GateSignals::default()));
        assert!(!none.keeps(0.4, 0.5, &GateSignals::default()));
        // The margin gate: both conditions, the margin inclusive as the score is.
        assert!(margin.keeps(0.5, 0.5, &query(2.0)));
        assert!(!margin.keeps(0.5, 0.5, &query(1.9)));
        assert!(!margin.keeps(0.4, 0.5, &query(3.0)));
        assert_eq!(margin.threshold(0.5, &query(1.0)), f64::INFINITY);
        assert_eq!(margin.margin_level(), Some(2.0));
    }
}
