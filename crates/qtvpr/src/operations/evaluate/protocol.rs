//! semantics §8.1: the protocol's parameters, the methods it compares, and how it
//! splits the queries of a matrix ([`Layout`]).

use crate::error::{Error, Result};
use crate::input::params::{DEFAULT_K, DEFAULT_PRECISION, Gate, Params, SequenceOverrides, SequenceParams};
use crate::rules::decisions::Matching;

/// A way of choosing each segment's threshold (semantics §4-§7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Method {
    /// Quantile transfer (sections 4-6), each segment its own batch.
    QuantileTransfer,
    /// Online quantile transfer (section 11): every deployment query decided at the
    /// threshold of its causal window of one segment size.
    QuantileTransferOnline,
    /// Quantile transfer with the margin gate (section 13): a best match is accepted
    /// at the segment's quantile-transfer threshold when its margin is at least the
    /// calibration's `m*` too. Single matching only.
    QuantileTransferMargin,
    /// The margin gate alone (section 13): threshold `-inf`, a best match accepted when
    /// its margin is at least `m*`. Single matching only.
    Margin,
    /// Quantile transfer with the sequence gate (section 15): a best match is accepted
    /// at the segment's quantile-transfer threshold when its consistency with the
    /// previous queries' reaches the gate's level too. Single matching only.
    QuantileTransferSequence,
    /// Quantile transfer with both gates (sections 13 and 15). Single matching only.
    QuantileTransferMarginSequence,
    /// The sequence gate alone (section 15): threshold `-inf`, a best match accepted
    /// when its consistency reaches the level. Single matching only.
    Sequence,
    /// Schubert et al.'s threshold fitted to each segment's raw scores.
    Schubert,
    /// Schubert et al.'s threshold fitted once to the calibration scores.
    SchubertCalibrated,
    /// The section-3 threshold of the calibration set, kept fixed.
    CalibrationThreshold,
    /// The section-3 threshold of each segment under its own ground truth (an upper
    /// bound, not deployable).
    Oracle,
}

impl Method {
    /// Every method, in report order.
    pub const ALL: [Method; 11] = [
        Method::QuantileTransfer,
        Method::QuantileTransferOnline,
        Method::QuantileTransferMargin,
        Method::Margin,
        Method::QuantileTransferSequence,
        Method::QuantileTransferMarginSequence,
        Method::Sequence,
        Method::Schubert,
        Method::SchubertCalibrated,
        Method::CalibrationThreshold,
        Method::Oracle,
    ];

    /// The name used on the command line, in JSON and in Python.
    pub fn as_str(self) -> &'static str {
        match self {
            Method::QuantileTransfer => "quantile-transfer",
            Method::QuantileTransferOnline => "quantile-transfer-online",
            Method::QuantileTransferMargin => "quantile-transfer-margin",
            Method::Margin => "margin",
            Method::QuantileTransferSequence => "quantile-transfer-sequence",
            Method::QuantileTransferMarginSequence => "quantile-transfer-margin-sequence",
            Method::Sequence => "sequence",
            Method::Schubert => "schubert",
            Method::SchubertCalibrated => "schubert-calibrated",
            Method::CalibrationThreshold => "calibration-threshold",
            Method::Oracle => "oracle",
        }
    }

    /// What the method is, in one line: the legend of a results table (the README's).
    pub fn caption(self) -> &'static str {
        match self {
            Method::QuantileTransfer => "quantile transfer, one threshold per segment of deployment queries",
            Method::QuantileTransferOnline => "quantile transfer on a causal window of the last queries (online)",
            Method::QuantileTransferMargin => "quantile transfer, a match also kept only if its margin clears m*",
            Method::Margin => "the margin gate alone: the best match kept when its margin clears m*",
            Method::QuantileTransferSequence => {
                "quantile transfer, a match also kept only if the previous queries' matches agree with it"
            }
            Method::QuantileTransferMarginSequence => {
                "quantile transfer with both gates: the margin clears m* and the previous matches agree"
            }
            Method::Sequence => "the sequence gate alone: the best match kept when the previous queries' agree",
            Method::Schubert => "Schubert et al.'s threshold, fitted to each segment's raw scores",
            Method::SchubertCalibrated => "Schubert et al.'s threshold, fitted once to the calibration scores",
            Method::CalibrationThreshold => "the calibration's own best threshold, kept fixed (tuned once, offline)",
            Method::Oracle => "each segment's best threshold under its own ground truth: the bound, not deployable",
        }
    }
}

impl Method {
    /// The gates the method decides through: the margin gate (semantics §13), the
    /// sequence gate (§15), both, or [`Gate::None`].
    pub fn gate(self) -> Gate {
        match self {
            Method::QuantileTransferMargin | Method::Margin => Gate::Margin,
            Method::QuantileTransferSequence | Method::Sequence => Gate::Sequence,
            Method::QuantileTransferMarginSequence => Gate::MarginSequence,
            _ => Gate::None,
        }
    }

    /// Whether the method gates decisions (semantics §13, §15), which needs single
    /// matching.
    pub fn is_gated(self) -> bool {
        self.gate().is_on()
    }

    /// Whether the method thresholds each segment by quantile transfer (with or
    /// without gates).
    pub(crate) fn transfers(self) -> bool {
        matches!(
            self,
            Method::QuantileTransfer
                | Method::QuantileTransferMargin
                | Method::QuantileTransferSequence
                | Method::QuantileTransferMarginSequence
        )
    }

    /// Every method that applies to `matching`, in report order: what "all methods"
    /// means (the gated ones need single matching).
    pub fn all_for(matching: Matching) -> Vec<Method> {
        Method::ALL
            .into_iter()
            .filter(|m| matching == Matching::Single || !m.is_gated())
            .collect()
    }

    /// Every method that applies to `matching` on a database of `n_db` images with the
    /// sequence gate's parameters `sequence`: [`Method::all_for`] less the sequence
    /// gate's methods on a database its widest tolerance covers (semantics §15: there
    /// the gate cannot tell, and a user who did not name it is not refused for it). What
    /// "all methods" means once the input is read; a method asked for by name that does
    /// not apply is an error instead, as the margin gate's are on |DB| < 2.
    pub fn all_applying(matching: Matching, n_db: usize, sequence: &SequenceParams) -> Vec<Method> {
        let tells = sequence.check(matching, n_db).is_ok();
        Method::all_for(matching)
            .into_iter()
            .filter(|m| tells || !m.gate().sequence())
            .collect()
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Method::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| Error::UnknownMethod {
                name: s.to_string(),
                expected: Method::ALL.map(Method::as_str).to_vec(),
            })
    }
}

/// A number of queries, given as a fraction of |Q| or as a count.
///
/// Serialised as `{"fraction": f}` or `{"count": n}`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize), serde(rename_all = "snake_case"))]
pub enum Split {
    /// A fraction of all |Q| queries, in (0, 1).
    Fraction(f64),
    /// A number of queries, at least 1.
    Count(usize),
}

/// The protocol's parameters (semantics §8.1); [`Default`] is the paper's.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Protocol {
    /// Calibration queries, the first ones: `floor(f |Q|)` for a fraction `f`.
    /// Default: 10%.
    pub calibration: Split,
    /// `None` (default): the deployment set is every query after the calibration set.
    /// `Some(f)`: it is the last `floor(f |Q|)` queries, whatever the calibration size;
    /// queries between the two sets are unused, and the sets may not overlap.
    pub deploy_fraction: Option<f64>,
    /// Segment size: `ceil(f |Q|)` for a fraction `f` (of all |Q| queries, not of the
    /// deployment set). Default: 1%.
    pub segment: Split,
    /// Calibration queries sampled per deployment query by quantile transfer.
    pub k: usize,
    /// Precision target tau in (0, 1].
    pub precision: f64,
    /// Single- or multi-match decisions.
    pub matching: Matching,
    /// The sequence gate's parameters (semantics §15): of the sequence methods, and of
    /// the consistency reported as a signal.
    pub sequence_gate: SequenceParams,
}

/// The share of the queries that calibrates when none is given: the paper's 10%.
pub const DEFAULT_CAL_FRACTION: f64 = 0.10;

/// The segment size as a share of the queries when none is given: the paper's 1%.
pub const DEFAULT_SEGMENT_FRACTION: f64 = 0.01;

/// The deployment set of an [`ablation`](super::ablation()) whose base protocol leaves
/// it open: the last half of the queries.
pub const ABLATION_DEPLOY_FRACTION: f64 = 0.5;

impl Default for Protocol {
    /// The paper's protocol: the first 10% of the queries calibrate, segments of 1% of
    /// them, `k` = [`DEFAULT_K`], 100% precision, single matching.
    fn default() -> Self {
        Self {
            calibration: Split::Fraction(DEFAULT_CAL_FRACTION),
            deploy_fraction: None,
            segment: Split::Fraction(DEFAULT_SEGMENT_FRACTION),
            k: DEFAULT_K,
            precision: DEFAULT_PRECISION,
            matching: Matching::Single,
            sequence_gate: SequenceParams::default(),
        }
    }
}

/// The protocol applied to a |DB| x |Q| matrix: its parameters and where it puts the
/// queries (the `params` of the JSON output).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Layout {
    /// The parameters.
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub protocol: Protocol,
    /// |DB|.
    pub database_size: usize,
    /// |Q|.
    pub queries: usize,
    /// Columns `0..calibration_queries` calibrate.
    pub calibration_queries: usize,
    /// Column of the first deployment query; segment bounds count from here.
    pub deployment_start: usize,
    /// |Qdeploy|, the full segments and the dropped remainder together.
    pub deployment_queries: usize,
    /// Queries per segment.
    pub segment_size: usize,
    /// Number of full segments.
    pub segments: usize,
}

fn fraction(name: &'static str, f: f64) -> Result<f64> {
    if !(f > 0.0 && f < 1.0) {
        return Err(Error::param(name, format!("must be in (0, 1), got {f}")));
    }
    Ok(f)
}

fn count(name: &'static str, n: usize) -> Result<usize> {
    if n < 1 {
        return Err(Error::param(name, format!("must be >= 1, got {n}")));
    }
    Ok(n)
}

impl Split {
    /// Check the split's own parameter, before the number of queries is known (a front
    /// end checks it before reading any file): a fraction in (0, 1), a count of at
    /// least 1.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a fraction outside (0, 1) or a count of 0.
    pub fn validate(self) -> Result<()> {
        match self {
            Split::Fraction(f) => fraction("cal fraction", f).map(drop),
            Split::Count(n) => count("cal queries", n).map(drop),
        }
    }

    /// The number of calibration queries, the first ones, this split names among `n_q`
    /// queries: `floor(f n_q)` for a fraction `f`, `n` for a count. The same rule for
    /// [`Protocol::layout`] and for a front end that splits one matrix (or one set of
    /// query descriptors) into calibration and deployment queries.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a fraction outside (0, 1) or a count of 0;
    /// [`Error::CalibrationSize`] when the result leaves no calibration query or no
    /// query after it (it must be between 1 and `n_q - 1`).
    pub fn calibration_size(self, n_q: usize) -> Result<usize> {
        self.calibration_size_of(None, n_q)
    }

    /// [`Split::calibration_size`] of a matrix of `database` images (when known), which
    /// an error carries so that a front end can say when the count fits |DB| instead
    /// ([`crate::input::orientation::hint`]).
    ///
    /// # Errors
    /// As [`Split::calibration_size`].
    pub(crate) fn calibration_size_of(self, database: Option<usize>, n_q: usize) -> Result<usize> {
        let n_cal = match self {
            Split::Fraction(f) => (fraction("cal fraction", f)? * n_q as f64).floor() as usize,
            Split::Count(n) => count("cal queries", n)?,
        };
        if !(1..n_q).contains(&n_cal) {
            return Err(Error::CalibrationSize {
                calibration: n_cal,
                queries: n_q,
                database,
            });
        }
        Ok(n_cal)
    }
}

impl Protocol {
    /// The protocol of the values a user gave, [`Protocol::default`]'s for those left
    /// out (`None`), checked: what every front end asks for, so that none decides a
    /// default. A segment or a calibration set given as a count replaces the default
    /// fraction.
    ///
    /// # Errors
    /// As [`Protocol::validate`].
    pub fn resolve(
        k: Option<usize>,
        precision: Option<f64>,
        matching: Option<Matching>,
        calibration: Option<Split>,
        segment: Option<Split>,
        deploy_fraction: Option<f64>,
        sequence_gate: SequenceOverrides,
    ) -> Result<Self> {
        let d = Self::default();
        let protocol = Self {
            calibration: calibration.unwrap_or(d.calibration),
            deploy_fraction: deploy_fraction.or(d.deploy_fraction),
            segment: segment.unwrap_or(d.segment),
            k: k.unwrap_or(d.k),
            precision: precision.unwrap_or(d.precision),
            matching: matching.unwrap_or(d.matching),
            sequence_gate: d.sequence_gate.overridden(sequence_gate),
        };
        protocol.validate()?;
        Ok(protocol)
    }

    /// Every protocol an ablation of this one runs (the paper's Fig. 5), checked: one
    /// per calibration size of `calibration` (the outer loop) and `k` of `ks` (the
    /// inner one), each in the order given, an empty list keeping this protocol's
    /// value; every one deploys on the last `floor(f |Q|)` queries, `f` this protocol's
    /// `deploy_fraction` or [`ABLATION_DEPLOY_FRACTION`] (the last 50%) when it has
    /// none. What [`ablation`](super::ablation()) runs, and what a front end checks
    /// before it reads a file.
    ///
    /// # Errors
    /// [`Protocol::validate`] of any of them.
    pub fn ablation(&self, ks: &[usize], calibration: &[Split]) -> Result<Vec<Protocol>> {
        let ks = if ks.is_empty() {
            std::slice::from_ref(&self.k)
        } else {
            ks
        };
        let calibration = if calibration.is_empty() {
            std::slice::from_ref(&self.calibration)
        } else {
            calibration
        };
        let deploy_fraction = Some(self.deploy_fraction.unwrap_or(ABLATION_DEPLOY_FRACTION));
        let protocols: Vec<Protocol> = calibration
            .iter()
            .flat_map(|&calibration| {
                ks.iter().map(move |&k| Protocol {
                    calibration,
                    deploy_fraction,
                    k,
                    ..*self
                })
            })
            .collect();
        for p in &protocols {
            p.validate()?;
        }
        Ok(protocols)
    }

    /// Check the parameters that do not depend on the matrix: `k >= 1`, tau in (0, 1],
    /// fractions in (0, 1), counts >= 1, the sequence gate's parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        Params {
            k: self.k,
            precision: self.precision,
            sequence_gate: self.sequence_gate,
            ..Params::default()
        }
        .validate()?;
        match self.calibration {
            Split::Fraction(f) => fraction("cal fraction", f).map(drop)?,
            Split::Count(n) => count("cal queries", n).map(drop)?,
        }
        if let Some(f) = self.deploy_fraction {
            fraction("deploy fraction", f)?;
        }
        match self.segment {
            Split::Fraction(f) => fraction("segment fraction", f).map(drop),
            Split::Count(n) => count("segment size", n).map(drop),
        }
    }

    /// Split the `queries` columns of a matrix with `database_size` rows as the
    /// protocol says.
    ///
    /// # Errors
    /// Invalid parameters ([`Protocol::validate`]), or a split that leaves no
    /// calibration query, no deployment query, overlapping sets or no full segment
    /// ([`Error::CalibrationSize`], [`Error::Protocol`]).
    pub fn layout(&self, database_size: usize, queries: usize) -> Result<Layout> {
        self.validate()?;
        let n_q = queries;
        let n_cal = self.calibration.calibration_size_of(Some(database_size), n_q)?;
        let n_dep = match self.deploy_fraction {
            None => n_q - n_cal,
            Some(f) => {
                let n_dep = (f * n_q as f64).floor() as usize;
                if n_dep < 1 {
                    return Err(Error::Protocol(format!(
                        "the deployment set has no query: floor({f} * {n_q}) = 0"
                    )));
                }
                if n_cal + n_dep > n_q {
                    return Err(Error::Protocol(format!(
                        "the calibration set ({n_cal} queries) and the deployment set ({n_dep} queries) \
                         overlap: together they exceed the {n_q} queries"
                    )));
                }
                n_dep
            }
        };
        let size = match self.segment {
            Split::Fraction(f) => (f * n_q as f64).ceil() as usize,
            Split::Count(n) => n,
        };
        if size > n_dep {
            return Err(Error::Protocol(format!(
                "segment size {size} is larger than the {n_dep} deployment queries"
            )));
        }
        Ok(Layout {
            protocol: *self,
            database_size,
            queries: n_q,
            calibration_queries: n_cal,
            deployment_start: n_q - n_dep,
            deployment_queries: n_dep,
            segment_size: size,
            segments: n_dep / size,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::operations::evaluate::evaluate;
    use crate::operations::evaluate::tests::{protocol, tiny};

    #[test]
    fn a_protocol_resolves_what_is_left_out_to_the_defaults() {
        let none = Protocol::resolve(None, None, None, None, None, None, SequenceOverrides::default()).unwrap();
        assert_eq!(none, Protocol::default());
        assert_eq!(
            (none.calibration, none.segment, none.k, none.precision),
            (Split::Fraction(0.10), Split::Fraction(0.01), 10, 1.0)
        );
        let given = Protocol::resolve(
            Some(3),
            Some(0.9),
            Some(Matching::Multi),
            Some(Split::Count(20)),
            Some(Split::Count(7)),
            Some(0.5),
            SequenceOverrides {
                window: Some(3),
                ..SequenceOverrides::default()
            },
        )
        .unwrap();
        assert_eq!(
            given,
            Protocol {
                calibration: Split::Count(20),
                deploy_fraction: Some(0.5),
                segment: Split::Count(7),
                k: 3,
                precision: 0.9,
                matching: Matching::Multi,
                sequence_gate: SequenceParams {
                    window: 3,
                    ..SequenceParams::default()
                },
            }
        );
        let err = Protocol::resolve(Some(0), None, None, None, None, None, SequenceOverrides::default()).unwrap_err();
        assert_eq!(err.to_string(), "k must be >= 1, got 0");
    }

    #[test]
    fn deploy_fraction_pins_the_last_queries() {
        // |Q| = 10, 50% deploy: the last 5 (columns 5..10); 20% calibrates (columns 0, 1);
        // columns 2..5 are unused. Segment size ceil(0.2 * 10) = 2: 2 full segments.
        let p = Protocol {
            calibration: Split::Fraction(0.2),
            deploy_fraction: Some(0.5),
            segment: Split::Fraction(0.2),
            ..Protocol::default()
        };
        let l = p.layout(4, 10).unwrap();
        assert_eq!(
            (
                l.calibration_queries,
                l.deployment_start,
                l.deployment_queries,
                l.segments
            ),
            (2, 5, 5, 2)
        );
        // 60% + 50% of 10 overlap.
        let p = Protocol {
            calibration: Split::Fraction(0.6),
            ..p
        };
        assert_eq!(
            p.layout(4, 10).unwrap_err().to_string(),
            "the calibration set (6 queries) and the deployment set (5 queries) overlap: \
             together they exceed the 10 queries"
        );
    }

    #[test]
    fn bad_protocols() {
        let msg = |p: Protocol, n: usize| p.layout(3, n).unwrap_err().to_string();
        let d = Protocol::default();
        // floor(0.1 * 7) = 0 calibration queries.
        assert_eq!(
            msg(d, 7),
            "the calibration set must have between 1 and 6 of the 7 queries, got 0"
        );
        let p = |calibration, segment| Protocol {
            calibration,
            segment,
            ..d
        };
        assert_eq!(
            msg(p(Split::Fraction(1.5), Split::Count(1)), 7),
            "cal fraction must be in (0, 1), got 1.5"
        );
        assert_eq!(
            msg(p(Split::Count(0), Split::Count(1)), 7),
            "cal queries must be >= 1, got 0"
        );
        assert_eq!(
            msg(p(Split::Count(2), Split::Count(6)), 7),
            "segment size 6 is larger than the 5 deployment queries"
        );
        assert_eq!(
            msg(p(Split::Count(2), Split::Fraction(0.0)), 7),
            "segment fraction must be in (0, 1), got 0"
        );
        assert_eq!(
            msg(p(Split::Count(7), Split::Count(1)), 7),
            "the calibration set must have between 1 and 6 of the 7 queries, got 7"
        );
        assert_eq!(
            "magic".parse::<Method>().unwrap_err().to_string(),
            "unknown method 'magic'; expected one of quantile-transfer, quantile-transfer-online, \
             quantile-transfer-margin, margin, quantile-transfer-sequence, quantile-transfer-margin-sequence, \
             sequence, schubert, schubert-calibrated, calibration-threshold, oracle"
        );
        assert_eq!(
            "quantile-transfer-margin-sequence".parse::<Method>().unwrap().gate(),
            Gate::MarginSequence
        );
        // The gated methods are single matching's only.
        assert_eq!(Method::all_for(Matching::Single).len(), 11);
        // On |DB| = 7 the default sequence gate (+-3 rows, 7 rows) cannot tell: all but
        // its three methods; on |DB| = 8 all 11.
        let p = SequenceParams::default();
        let small = Method::all_applying(Matching::Single, 7, &p);
        assert_eq!(small.len(), 8);
        assert!(small.iter().all(|m| !m.gate().sequence()));
        assert_eq!(
            Method::all_applying(Matching::Single, 8, &p),
            Method::all_for(Matching::Single)
        );
        assert_eq!(
            Method::all_applying(Matching::Multi, 100, &p),
            Method::all_for(Matching::Multi)
        );
        assert_eq!(
            Method::all_for(Matching::Multi),
            [
                Method::QuantileTransfer,
                Method::QuantileTransferOnline,
                Method::Schubert,
                Method::SchubertCalibrated,
                Method::CalibrationThreshold,
                Method::Oracle
            ]
        );
        assert_eq!(
            "schubert-calibrated".parse::<Method>().unwrap(),
            Method::SchubertCalibrated
        );
        let (s, gt) = tiny();
        let err = evaluate(s.view(), &gt, &Protocol { k: 0, ..protocol() }, &Method::ALL).unwrap_err();
        assert_eq!(err.to_string(), "k must be >= 1, got 0");
    }
}
