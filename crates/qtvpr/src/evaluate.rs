//! semantics §8: the evaluation protocol of the paper's Table I.
//!
//! One similarity matrix with ground truth for every query is split in query order:
//! the first queries calibrate, the deployment set is cut into full segments of
//! consecutive queries (a shorter remainder is dropped), and every method of
//! [`Method`] gives each segment a threshold. Each segment's decisions at that
//! threshold are counted against the segment's own ground truth, which answers the
//! practical question: *would this threshold have kept me at the target precision on
//! this stretch of the traverse, and how much recall did it leave me?*
//!
//! Nothing here re-implements an earlier section: decisions and counts are
//! the per-column candidates of section 2, the oracle is the section-3 sweep, quantile transfer is
//! [`Calibration::transfer`] with one batch per segment (sections 4-6), and the
//! baselines are [`crate::baselines`] (section 7). Segments are independent, so each
//! method's thresholds and counts are computed for all segments in parallel.
//!
//! [`Protocol::deploy_fraction`] pins the deployment set to the last queries, so that
//! the calibration size can vary while the deployment set stays the same; [`ablation`]
//! runs the protocol once per `k` and calibration size on such a fixed deployment set
//! (the paper's Fig. 5).
//!
//! Every result derives `serde::Serialize` under the `serde` feature; the keys are
//! listed in [`crate::report`].

use std::ops::Range;
use std::sync::Arc;

use ndarray::{ArrayView2, s};
use rayon::prelude::*;

use crate::baselines::schubert;
use crate::best_threshold::subset_threshold;
use crate::decisions::{Candidates, Counts, Matching};
use crate::error::{Error, Result};
use crate::input::{GroundTruth, Score, check_gt_shape, validate_scores};
use crate::margin::{self, Gate};
use crate::names::Input;
use crate::online::Online;
use crate::params::{DEFAULT_K, DEFAULT_PRECISION, OnlineParams, Options, Params};
use crate::source::ScoreSource;
use crate::threads;
use crate::transfer::Calibration;

/// Tolerance of the "meets the target" test (semantics §8.3).
const EPS: f64 = 1e-12;

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
    pub const ALL: [Method; 8] = [
        Method::QuantileTransfer,
        Method::QuantileTransferOnline,
        Method::QuantileTransferMargin,
        Method::Margin,
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
            Method::Schubert => "schubert",
            Method::SchubertCalibrated => "schubert-calibrated",
            Method::CalibrationThreshold => "calibration-threshold",
            Method::Oracle => "oracle",
        }
    }
}

impl Method {
    /// Whether the method gates decisions on their margin (semantics §13), which needs
    /// single matching.
    pub fn is_gated(self) -> bool {
        matches!(self, Method::QuantileTransferMargin | Method::Margin)
    }

    /// Every method that applies to `matching`, in report order: what "all methods"
    /// means (the gated ones need single matching).
    pub fn all_for(matching: Matching) -> Vec<Method> {
        Method::ALL
            .into_iter()
            .filter(|m| matching == Matching::Single || !m.is_gated())
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
}

/// The share of the queries that calibrates when none is given: the paper's 10%.
pub const DEFAULT_CAL_FRACTION: f64 = 0.10;

/// The segment size as a share of the queries when none is given: the paper's 1%.
pub const DEFAULT_SEGMENT_FRACTION: f64 = 0.01;

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
    /// The number of calibration queries, the first ones, this split names among `n_q`
    /// queries: `floor(f n_q)` for a fraction `f`, `n` for a count. The same rule for
    /// [`Protocol::layout`] and for a front end that splits one matrix (or one set of
    /// query descriptors) into calibration and deployment queries.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a fraction outside (0, 1) or a count of 0;
    /// [`Error::Protocol`] when the result leaves no calibration query or no query
    /// after it (it must be between 1 and `n_q - 1`).
    pub fn calibration_size(self, n_q: usize) -> Result<usize> {
        let n_cal = match self {
            Split::Fraction(f) => (fraction("cal fraction", f)? * n_q as f64).floor() as usize,
            Split::Count(n) => count("cal queries", n)?,
        };
        if !(1..n_q).contains(&n_cal) {
            return Err(Error::Protocol(format!(
                "the calibration set must have between 1 and {} of the {n_q} queries, got {n_cal}",
                n_q.saturating_sub(1)
            )));
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
    ) -> Result<Self> {
        let d = Self::default();
        let protocol = Self {
            calibration: calibration.unwrap_or(d.calibration),
            deploy_fraction: deploy_fraction.or(d.deploy_fraction),
            segment: segment.unwrap_or(d.segment),
            k: k.unwrap_or(d.k),
            precision: precision.unwrap_or(d.precision),
            matching: matching.unwrap_or(d.matching),
        };
        protocol.validate()?;
        Ok(protocol)
    }

    /// Check the parameters that do not depend on the matrix: `k >= 1`, tau in (0, 1],
    /// fractions in (0, 1), counts >= 1.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        Params {
            k: self.k,
            precision: self.precision,
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
    /// ([`Error::Protocol`]).
    pub fn layout(&self, database_size: usize, queries: usize) -> Result<Layout> {
        self.validate()?;
        let n_q = queries;
        let n_cal = self.calibration.calibration_size(n_q)?;
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

/// One segment under one method (semantics §8.6).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SegmentResult {
    /// First query of the segment, counted from the first deployment query.
    pub start: usize,
    /// One past its last query.
    pub end: usize,
    /// The method's threshold (`inf` is reject-all).
    pub threshold: f64,
    /// The oracle's threshold of the segment (`inf` when no threshold meets the target).
    pub oracle_threshold: f64,
    /// A gated method's `m*` (semantics §13), the margin a best match needs besides its
    /// score; `None` (and left out of the JSON) for the other methods.
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "Option::is_none"))]
    pub gate: Option<f64>,
    /// TP, FP and positives at `threshold` (serialised with the figures derived from
    /// them: precision, recall and the precision's lower bound).
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub counts: Counts,
    /// Whether the precision is at least tau (less 1e-12).
    pub meets: bool,
}

/// A method's results over every full segment (semantics §8).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MethodResult {
    /// Which method (serialised as the key of this result).
    #[cfg_attr(feature = "serde", serde(skip))]
    pub method: Method,
    /// %Segs: 100 x segments that meet / segments counted; `None` when none is counted.
    pub pct_segs: Option<f64>,
    /// AvgR@tauP: the mean over counted segments of their recall if they meet, else 0;
    /// `None` when none is counted.
    pub avg_recall: Option<f64>,
    /// Segments with at least one positive.
    pub segments_counted: usize,
    /// Segments without positives, left out of both figures.
    pub segments_skipped: usize,
    /// Mean squared difference from the oracle's threshold over the counted segments
    /// where both are finite; `None` when there is no such segment.
    pub threshold_mse: Option<f64>,
    /// [`MethodResult::pooled`], serialised as `pooled_tp`, ..., `pooled_precision_lower95`.
    #[cfg_attr(
        feature = "serde",
        serde(flatten, serialize_with = "crate::report::serialize::pooled")
    )]
    pooled: Counts,
    /// Every full segment, in order.
    pub segments: Vec<SegmentResult>,
}

impl MethodResult {
    /// TP, FP and positives summed over every full segment (skipped ones included): the
    /// method's operating point on the whole deployment set.
    pub fn pooled(&self) -> Counts {
        self.pooled
    }
}

/// One point of a precision-recall curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrPoint {
    /// Accept scores `>=` this.
    pub threshold: f64,
    /// Precision there.
    pub precision: f64,
    /// Recall there.
    pub recall: f64,
}

/// The result of [`evaluate`].
#[derive(Debug, Clone)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Evaluation {
    /// The protocol's parameters and how they split the queries (serialised as `params`).
    #[cfg_attr(feature = "serde", serde(rename = "params"))]
    pub layout: Layout,
    /// R@1 of the deployment set's full segments: the fraction of its queries with at
    /// least one hard match whose best match (the first maximum of the column) is a hard
    /// match. It counts best matches whatever the matching mode; a best match that is
    /// soft but not hard is a miss. `None` when no such query has a hard match.
    ///
    /// VPR-Bench's "recall at 100% precision" divides by the queries whose best match is
    /// correct instead of the queries with a match: with single matching at tau = 1 it
    /// is the recall reported here divided by `recall_at_1`.
    pub recall_at_1: Option<f64>,
    /// One result per method asked for, in the order asked (duplicates removed);
    /// serialised as an object keyed by method name.
    #[cfg_attr(feature = "serde", serde(serialize_with = "crate::report::serialize::methods"))]
    pub methods: Vec<MethodResult>,
    /// The candidates of the full segments' queries, for the precision-recall curve.
    #[cfg_attr(feature = "serde", serde(skip))]
    deployment: Candidates,
}

impl Evaluation {
    /// The result of `method`, if it was asked for.
    pub fn method(&self, method: Method) -> Option<&MethodResult> {
        self.methods.iter().find(|m| m.method == method)
    }

    /// The precision-recall curve of the deployment set (every full segment pooled,
    /// one threshold for all), from the highest threshold down, evaluated at the end of
    /// each group of equal scores as in semantics §3.
    ///
    /// To keep a plot light, a point is kept only when precision or recall has moved
    /// by at least `1 / resolution` since the last kept point (the first and last
    /// points are always kept); `resolution = usize::MAX` keeps every point.
    pub fn precision_recall_curve(&self, resolution: usize) -> Vec<PrPoint> {
        let c = &self.deployment;
        let mut all: Vec<(f64, bool)> = (0..c.ncols())
            .flat_map(|j| {
                let (s, ok) = c.column(j);
                s.iter().copied().zip(ok.iter().copied())
            })
            .collect();
        threads::install(|| all.par_sort_unstable_by(|a, b| b.0.total_cmp(&a.0)));
        let positives = c.positives(0..c.ncols());
        let step = 1.0 / resolution as f64;
        let mut curve: Vec<PrPoint> = Vec::new();
        let (mut tp, mut fp) = (0usize, 0usize);
        for (i, &(score, correct)) in all.iter().enumerate() {
            if correct {
                tp += 1;
            } else {
                fp += 1;
            }
            let last = i + 1 == all.len();
            if !last && all[i + 1].0 == score {
                continue;
            }
            let counts = Counts { tp, fp, positives };
            let p = PrPoint {
                threshold: score,
                precision: counts.precision(),
                recall: counts.recall(),
            };
            let keep = curve.last().is_none_or(|q| {
                last || (p.precision - q.precision).abs() >= step || (p.recall - q.recall).abs() >= step
            });
            if keep {
                curve.push(p);
            }
        }
        curve
    }
}

/// Run the protocol on the similarity `scores` (|DB| x |Q|: a matrix, or descriptors,
/// whose similarity is computed in memory, as the protocol reads all of it) with ground
/// truth `gt` for every query.
///
/// `methods` are evaluated in the order given (a repeated method once); the oracle
/// threshold of every segment is computed whether or not [`Method::Oracle`] is asked
/// for, since every method reports it. `protocol` is the [`Protocol`] (`&protocol`),
/// with an optional progress callback ([`Options::progress`]) called as
/// `progress(done, total)` after each method: `done` of the `total` distinct methods
/// are evaluated.
///
/// # Errors
/// Invalid parameters or split ([`Protocol::layout`]), empty or non-finite scores, a
/// range of descriptor queries that is empty or beyond |Q|, or ground truth of
/// another shape.
pub fn evaluate<'s, 'd: 's, 'p>(
    scores: impl Into<ScoreSource<'s, 'd>>,
    gt: &GroundTruth,
    protocol: impl Into<Options<'p, Protocol>>,
    methods: &[Method],
) -> Result<Evaluation> {
    let options = protocol.into();
    options.params.validate()?;
    scores
        .into()
        .with_matrix(None, |s| with_scores!(s, |s| evaluate_matrix(s, gt, &options, methods)))
}

/// [`evaluate`] of a matrix.
fn evaluate_matrix<T: Score>(
    s: ArrayView2<'_, T>,
    gt: &GroundTruth,
    options: &Options<'_, Protocol>,
    methods: &[Method],
) -> Result<Evaluation> {
    let protocol = &options.params;
    validate_scores(Input::Similarity, s)?;
    check_gt_shape(gt, Input::Similarity, s.dim())?;
    let layout = protocol.layout(s.nrows(), s.ncols())?;
    let mut unique: Vec<Method> = Vec::with_capacity(methods.len());
    for &m in methods {
        if !unique.contains(&m) {
            unique.push(m);
        }
    }

    let (tau, size) = (protocol.precision, layout.segment_size);
    let cal = s![.., ..layout.calibration_queries];
    let dep = s![
        ..,
        layout.deployment_start..layout.deployment_start + layout.segments * size
    ];
    let (s_cal, gt_cal) = (s.slice(cal), gt.view().slice_move(cal));
    let (s_dep, gt_dep) = (s.slice(dep), gt.view().slice_move(dep));
    let ranges: Vec<Range<usize>> = (0..layout.segments).map(|i| i * size..(i + 1) * size).collect();

    let deployment = Candidates::new(s_dep, gt_dep, protocol.matching);
    // R@1 is the recall of single-match decisions with nothing rejected.
    let all = 0..deployment.ncols();
    let best_matches = match protocol.matching {
        Matching::Single => deployment.counts(all, f64::NEG_INFINITY),
        Matching::Multi => Candidates::new(s_dep, gt_dep, Matching::Single).counts(all, f64::NEG_INFINITY),
    };
    let recall_at_1 = (best_matches.positives > 0).then(|| best_matches.recall());
    let oracle: Vec<f64> = threads::install(|| {
        ranges
            .par_iter()
            .map(|r| subset_threshold(&deployment, &r.clone().collect::<Vec<_>>(), tau))
            .collect()
    });
    let gated = unique.iter().any(|m| m.is_gated());
    if gated {
        margin::check(protocol.matching, s.nrows())?;
    }
    let needs_calibration = unique.iter().any(|m| {
        m.is_gated()
            || matches!(
                m,
                Method::QuantileTransfer | Method::QuantileTransferOnline | Method::CalibrationThreshold
            )
    });
    let calibration = needs_calibration
        .then(|| Calibration::with_labels(s_cal, gt_cal, protocol.matching).map(Arc::new))
        .transpose()?;
    // The gate's margins (of scores validated above) and m*, and the quantile-transfer
    // thresholds: each found once for the methods that share them.
    let gate = if gated {
        let cal = calibration.as_ref().expect("built for the gate");
        Some((margin::of_columns(s_dep), cal.gate(tau)?))
    } else {
        None
    };
    let transferred = if unique
        .iter()
        .any(|m| matches!(m, Method::QuantileTransfer | Method::QuantileTransferMargin))
    {
        let params = Params {
            k: protocol.k,
            precision: tau,
            segment_size: Some(size),
            gate: Gate::None,
        };
        let cal = calibration.as_ref().expect("built for quantile transfer");
        let segments = cal.transfer(s_dep, &params)?.segments;
        Some(segments.iter().map(|g| g.threshold).collect::<Vec<f64>>())
    } else {
        None
    };

    let mut results = Vec::with_capacity(unique.len());
    for &method in &unique {
        // Every method but the online one gives each segment one threshold.
        let scored = |thresholds: &[f64]| {
            let gate = gate.as_ref().filter(|_| method.is_gated());
            score(method, &deployment, &ranges, thresholds, &oracle, tau, gate)
        };
        let result = match method {
            Method::QuantileTransfer | Method::QuantileTransferMargin => {
                scored(transferred.as_deref().expect("transferred for quantile transfer"))
            }
            Method::Margin => scored(&vec![f64::NEG_INFINITY; ranges.len()]),
            Method::Schubert => scored(&threads::install(|| {
                ranges
                    .par_iter()
                    .map(|r| schubert(s_dep.slice(s![.., r.clone()])))
                    .collect::<Vec<f64>>()
            })),
            Method::SchubertCalibrated => scored(&vec![schubert(s_cal); ranges.len()]),
            Method::CalibrationThreshold => {
                let cal = calibration.as_ref().expect("built for the calibration threshold");
                scored(&vec![cal.threshold(tau)?; ranges.len()])
            }
            Method::Oracle => scored(&oracle),
            // Decided query by query: its segments are counted as it goes.
            Method::QuantileTransferOnline => {
                let cal = calibration.as_ref().expect("built for online quantile transfer");
                summarise(
                    method,
                    online_segments(cal, s_dep, &deployment, &ranges, &oracle, protocol)?,
                )
            }
        };
        results.push(result);
        options.report(results.len(), unique.len());
    }
    Ok(Evaluation {
        layout,
        recall_at_1,
        methods: results,
        deployment,
    })
}

/// The deployment set of an [`ablation`] whose base protocol leaves it open: the last
/// half of the queries.
pub const ABLATION_DEPLOY_FRACTION: f64 = 0.5;

/// The result of [`ablation`].
#[derive(Debug, Clone)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Ablation {
    /// One evaluation per setting: calibration sizes in the outer loop, `k` in the inner
    /// one, each in the order given (serialised as `ablation`).
    #[cfg_attr(feature = "serde", serde(rename = "ablation"))]
    pub runs: Vec<Evaluation>,
}

/// Run the protocol once per combination of `ks` and `calibration` sizes (the paper's
/// Fig. 5: %Segs and AvgR@tauP against `k` and against the calibration size).
///
/// Every run is `base` with its `k` and calibration replaced; an empty list keeps
/// `base`'s value. So that the figures of different settings are comparable, every run
/// deploys on the same queries: the last `floor(f |Q|)` with `f = base.deploy_fraction`,
/// or [`ABLATION_DEPLOY_FRACTION`] (the last 50%) when that is `None`. The calibration
/// set is always the first queries, and may not reach into the deployment set.
///
/// `base` may carry a progress callback ([`Options::progress`]), called as
/// `progress(done, total)` after each method of each run: `done` of the `total` method
/// evaluations of the whole ablation are finished.
///
/// # Errors
/// As [`evaluate`]; every setting is checked ([`Protocol::layout`]) before the first
/// one runs.
pub fn ablation<'s, 'd: 's, 'p>(
    scores: impl Into<ScoreSource<'s, 'd>>,
    gt: &GroundTruth,
    base: impl Into<Options<'p, Protocol>>,
    ks: &[usize],
    calibration: &[Split],
    methods: &[Method],
) -> Result<Ablation> {
    let options = base.into();
    let base = &options.params;
    let ks = if ks.is_empty() {
        std::slice::from_ref(&base.k)
    } else {
        ks
    };
    let calibration = if calibration.is_empty() {
        std::slice::from_ref(&base.calibration)
    } else {
        calibration
    };
    let deploy_fraction = Some(base.deploy_fraction.unwrap_or(ABLATION_DEPLOY_FRACTION));
    let protocols: Vec<Protocol> = calibration
        .iter()
        .flat_map(|&calibration| {
            ks.iter().map(move |&k| Protocol {
                calibration,
                deploy_fraction,
                k,
                ..*base
            })
        })
        .collect();
    let source = scores.into();
    let (n_db, n_q) = source.dim();
    for p in &protocols {
        p.layout(n_db, n_q)?;
    }
    let n = protocols.len();
    // Descriptors are turned into their similarity once, for every run.
    let runs = source.with_matrix(None, |s| {
        protocols
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let progress = |done, total| options.report(i * total + done, n * total);
                evaluate(s, gt, Options::new(*p).progress(&progress), methods)
            })
            .collect::<Result<_>>()
    })?;
    Ok(Ablation { runs })
}

/// Count every segment at its threshold and summarise (semantics §8). With a `gate`
/// (every deployment query's margin, and `m*`), a query whose margin is below `m*`
/// accepts nothing (semantics §13).
fn score(
    method: Method,
    deployment: &Candidates,
    ranges: &[Range<usize>],
    thresholds: &[f64],
    oracle: &[f64],
    tau: f64,
    gate: Option<&(Vec<f64>, f64)>,
) -> MethodResult {
    let segments: Vec<SegmentResult> = threads::install(|| {
        (ranges, thresholds, oracle)
            .into_par_iter()
            .map(|(r, &threshold, &oracle_threshold)| {
                let counts = match gate {
                    None => deployment.counts(r.clone(), threshold),
                    // Scores are finite: no score is at or above +inf.
                    Some((margins, m_star)) => r
                        .clone()
                        .map(|j| {
                            let t = if margins[j] >= *m_star {
                                threshold
                            } else {
                                f64::INFINITY
                            };
                            deployment.counts(j..j + 1, t)
                        })
                        .sum(),
                };
                SegmentResult {
                    start: r.start,
                    end: r.end,
                    threshold,
                    oracle_threshold,
                    gate: gate.map(|g| g.1),
                    counts,
                    meets: counts.precision() >= tau - EPS,
                }
            })
            .collect()
    });
    summarise(method, segments)
}

/// Online quantile transfer in the protocol (semantics §11): one window of the
/// segment size over the deployment queries (not reset at segment boundaries); every
/// query decided at its own threshold; a segment's counts are the sums over its
/// queries, and its threshold that of its last query.
fn online_segments<T: Score>(
    cal: &Arc<Calibration>,
    s_dep: ArrayView2<'_, T>,
    deployment: &Candidates,
    ranges: &[Range<usize>],
    oracle: &[f64],
    protocol: &Protocol,
) -> Result<Vec<SegmentResult>> {
    let params = OnlineParams {
        k: protocol.k,
        precision: protocol.precision,
        window: ranges[0].len(),
        min_window: 1,
        gate: Gate::None,
    };
    let decisions = Online::new(Arc::clone(cal), params)?.push_many(s_dep)?;
    let segments = ranges
        .iter()
        .zip(oracle)
        .map(|(r, &oracle_threshold)| {
            let counts = r
                .clone()
                .map(|j| deployment.counts(j..j + 1, decisions[j].threshold))
                .sum();
            SegmentResult {
                start: r.start,
                end: r.end,
                threshold: decisions[r.end - 1].threshold,
                oracle_threshold,
                gate: None,
                counts,
                meets: counts.precision() >= protocol.precision - EPS,
            }
        })
        .collect();
    Ok(segments)
}

/// %Segs, AvgR@tauP and the threshold MSE of a method's segments (semantics §8-§8).
fn summarise(method: Method, segments: Vec<SegmentResult>) -> MethodResult {
    let counted: Vec<&SegmentResult> = segments.iter().filter(|g| g.counts.positives > 0).collect();
    let n = counted.len();
    let (pct_segs, avg_recall) = if n == 0 {
        (None, None)
    } else {
        let meet = counted.iter().filter(|g| g.meets).count();
        let recall: f64 = counted
            .iter()
            .map(|g| if g.meets { g.counts.recall() } else { 0.0 })
            .sum();
        (Some(100.0 * meet as f64 / n as f64), Some(recall / n as f64))
    };
    let squares: Vec<f64> = counted
        .iter()
        .filter(|g| g.threshold.is_finite() && g.oracle_threshold.is_finite())
        .map(|g| (g.threshold - g.oracle_threshold).powi(2))
        .collect();
    let threshold_mse = (!squares.is_empty()).then(|| squares.iter().sum::<f64>() / squares.len() as f64);
    let pooled = segments.iter().map(|g| g.counts).sum();
    MethodResult {
        method,
        pct_segs,
        avg_recall,
        segments_counted: n,
        segments_skipped: segments.len() - n,
        threshold_mse,
        pooled,
        segments,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::baselines::SCHUBERT_Z;
    use ndarray::{Array2, array};

    /// |DB| = 3, |Q| = 7 (the reference's TINY case): calibration c0, c1, then
    /// deployment d0..d4.
    ///
    /// ```text
    ///        c0   c1    d0   d1   d2   d3   d4
    /// db0   0.9  0.2   0.7  0.1  0.5  0.2  0.3
    /// db1   0.1  0.95  0.3  0.6  0.4  0.9  0.3
    /// db2   0.3  0.4   0.2  0.5  0.3  0.1  0.3
    /// ```
    /// GT: c0 -> db0, c1 -> db2, d0 -> db0, d1 -> db2; d2..d4 have no match.
    fn tiny() -> (Array2<f64>, GroundTruth) {
        let s = array![
            [0.9, 0.2, 0.7, 0.1, 0.5, 0.2, 0.3],
            [0.1, 0.95, 0.3, 0.6, 0.4, 0.9, 0.3],
            [0.3, 0.4, 0.2, 0.5, 0.3, 0.1, 0.3],
        ];
        let gt =
            GroundTruth::new(array![[1u8, 0, 1, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 0], [0, 1, 0, 1, 0, 0, 0],].view())
                .unwrap();
        (s, gt)
    }

    /// tau = 0.5, two calibration queries, segments of two: (0, 2) = d0 d1 and
    /// (2, 4) = d2 d3; d4 is the dropped remainder.
    fn protocol() -> Protocol {
        Protocol {
            calibration: Split::Count(2),
            segment: Split::Count(2),
            precision: 0.5,
            ..Protocol::default()
        }
    }

    fn run(methods: &[Method]) -> Evaluation {
        let (s, gt) = tiny();
        evaluate(s.view(), &gt, &protocol(), methods).unwrap()
    }

    #[test]
    fn progress_after_each_distinct_method() {
        // Schubert, the oracle and Schubert again: two distinct methods, so 1 then 2 of 2;
        // the results are those of `evaluate`.
        let (s, gt) = tiny();
        let methods = [Method::Schubert, Method::Oracle, Method::Schubert];
        let calls = std::cell::RefCell::new(vec![]);
        let record = |d, t| calls.borrow_mut().push((d, t));
        let e = evaluate(s.view(), &gt, Options::new(protocol()).progress(&record), &methods).unwrap();
        assert_eq!(calls.take(), [(1, 2), (2, 2)]);
        assert_eq!(e.methods, run(&methods).methods);
        // Rejected input (tau = 0): no call.
        let bad = Protocol {
            precision: 0.0,
            ..protocol()
        };
        assert!(evaluate(s.view(), &gt, Options::new(bad).progress(&record), &methods).is_err());
        assert_eq!(calls.take(), []);
    }

    #[test]
    fn a_protocol_resolves_what_is_left_out_to_the_defaults() {
        let none = Protocol::resolve(None, None, None, None, None, None).unwrap();
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
            }
        );
        let err = Protocol::resolve(Some(0), None, None, None, None, None).unwrap_err();
        assert_eq!(err.to_string(), "k must be >= 1, got 0");
    }

    #[test]
    fn layout_of_the_tiny_case() {
        let e = run(&[Method::Oracle]);
        assert_eq!(
            e.layout,
            Layout {
                protocol: protocol(),
                database_size: 3,
                queries: 7,
                calibration_queries: 2,
                deployment_start: 2,
                deployment_queries: 5,
                segment_size: 2,
                segments: 2
            }
        );
    }

    #[test]
    fn oracle_and_a_skipped_segment() {
        // Segment 0 (single): d0's best match 0.7 (db0, correct), d1's 0.6 (db1, wrong);
        // positives 2. Sweep at tau 0.5: 0.7 (1, 0) valid; 0.6 (1, 1): 1 >= 0.5 * 2 valid;
        // TP* = 1, first reached at 0.7 -> oracle 0.7: TP 1, FP 0, recall 1/2, meets.
        // Segment 1: d2, d3 have no match -> positives 0 -> skipped; oracle inf.
        // %Segs = 100 * 1/1 = 100; AvgR = 0.5 / 1; MSE over segment 0 = 0.
        let e = run(&[Method::Oracle]);
        let o = &e.methods[0];
        assert_eq!((o.segments_counted, o.segments_skipped), (1, 1));
        assert_eq!(
            (o.pct_segs, o.avg_recall, o.threshold_mse),
            (Some(100.0), Some(0.5), Some(0.0))
        );
        let g = o.segments[0];
        assert_eq!((g.start, g.end, g.threshold, g.oracle_threshold), (0, 2, 0.7, 0.7));
        assert_eq!((g.counts.tp, g.counts.fp, g.counts.positives, g.meets), (1, 0, 2, true));
        assert_eq!(o.segments[1].oracle_threshold, f64::INFINITY);
        assert_eq!(o.segments[1].counts.positives, 0);
    }

    #[test]
    fn calibration_threshold_is_reused_for_every_segment() {
        // Calibration (single): c0 best 0.9 (db0, correct), c1 best 0.95 (db1, wrong).
        // Sweep: 0.95 (0, 1) TP 0 invalid; 0.9 (1, 1): 1 >= 0.5 * 2 valid -> t = 0.9.
        // Segment 0 at 0.9 accepts nothing: precision 1 (meets), recall 0.
        // Segment 1 accepts d3's 0.9 (inclusive, wrong): FP 1, precision 0 -- but skipped.
        // %Segs 100, AvgR 0; MSE over segment 0: (0.9 - 0.7)^2 = 0.04.
        let e = run(&[Method::CalibrationThreshold]);
        let c = &e.methods[0];
        assert_eq!(
            c.segments.iter().map(|g| g.threshold).collect::<Vec<_>>(),
            vec![0.9, 0.9]
        );
        assert_eq!((c.segments[0].counts.tp, c.segments[0].counts.fp), (0, 0));
        assert_eq!((c.segments[1].counts.fp, c.segments[1].meets), (1, false));
        assert_eq!((c.pct_segs, c.avg_recall), (Some(100.0), Some(0.0)));
        assert!((c.threshold_mse.unwrap() - 0.04).abs() < 1e-15);
    }

    #[test]
    fn quantile_transfer_per_segment() {
        // k = 10 clips to 2: every deployment query's subset is {c0, c1}, threshold 0.9 (as
        // above). Sample (0.1, 0.2, 0.3, 0.4, 0.9, 0.95): c(<= 0.9) = 5 -> q = 4/5 for all.
        // Segment 0 scores ascending (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): h = 5 * 0.8 = 4 -> 0.6;
        // it accepts 0.7 (T) and 0.6 (F): precision 1/2 >= 0.5 meets, recall 1/2.
        // Segment 1 ascending (0.1, 0.2, 0.3, 0.4, 0.5, 0.9): h = 4 -> 0.5.
        // %Segs 100, AvgR 0.5 / 1, MSE (0.6 - 0.7)^2 = 0.01.
        let e = run(&[Method::QuantileTransfer]);
        let q = &e.methods[0];
        let t: Vec<f64> = q.segments.iter().map(|g| g.threshold).collect();
        assert!((t[0] - 0.6).abs() < 1e-15 && (t[1] - 0.5).abs() < 1e-15, "{t:?}");
        assert_eq!((q.segments[0].counts.tp, q.segments[0].counts.fp), (1, 1));
        assert_eq!((q.pct_segs, q.avg_recall), (Some(100.0), Some(0.5)));
        assert!((q.threshold_mse.unwrap() - 0.01).abs() < 1e-15);
    }

    #[test]
    fn quantile_transfer_online_per_query() {
        // Every query's subset is {c0, c1} (k clipped to 2): q = 4/5, as above. Window 2,
        // over the deployment queries only:
        // d0: {d0} ascending (0.2, 0.3, 0.7): h = 2 * 0.8 = 1.6 -> 0.3 + 0.6 * 0.4 = 0.54;
        //     its best 0.7 (T) is accepted.
        // d1: {d0, d1} (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): h = 4 -> 0.6; best 0.6 (F) accepted.
        // Segment 0: TP 1, FP 1, positives 2: precision 1/2 meets, recall 1/2; its
        //     threshold is d1's, 0.6.
        // d2: {d1, d2} (0.1, 0.3, 0.4, 0.5, 0.5, 0.6) -> 0.5: best 0.5 (F) accepted.
        // d3: {d2, d3} (0.1, 0.2, 0.3, 0.4, 0.5, 0.9) -> 0.5: best 0.9 (F) accepted.
        // Segment 1: FP 2, no positives: skipped. %Segs 100, AvgR 0.5, MSE (0.6 - 0.7)^2.
        let e = run(&[Method::QuantileTransferOnline]);
        let o = &e.methods[0];
        assert_eq!(o.method.as_str(), "quantile-transfer-online");
        let t: Vec<f64> = o.segments.iter().map(|g| g.threshold).collect();
        assert!((t[0] - 0.6).abs() < 1e-15 && (t[1] - 0.5).abs() < 1e-15, "{t:?}");
        let c: Vec<(usize, usize, usize)> = o
            .segments
            .iter()
            .map(|g| (g.counts.tp, g.counts.fp, g.counts.positives))
            .collect();
        assert_eq!(c, vec![(1, 1, 2), (0, 2, 0)]);
        assert_eq!((o.pct_segs, o.avg_recall), (Some(100.0), Some(0.5)));
        assert_eq!((o.segments_counted, o.segments_skipped), (1, 1));
        assert!((o.threshold_mse.unwrap() - 0.01).abs() < 1e-15);
    }

    #[test]
    fn quantile_transfer_online_is_online_over_the_deployment_queries() {
        // A fixed LCG matrix of 8 x 50: 5 calibration queries, segments of 6 from column 8
        // (columns 5..8 unused, deploy fraction 0.84): 7 full segments, 42 queries.
        let mut x = 7u64;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 100) as f64 / 100.0
        };
        let s = Array2::from_shape_fn((8, 50), |_| next());
        let gt = GroundTruth::new(Array2::from_shape_fn((8, 50), |(i, j)| i == j % 8).view()).unwrap();
        for matching in [Matching::Single, Matching::Multi] {
            let p = Protocol {
                calibration: Split::Count(5),
                deploy_fraction: Some(0.84),
                segment: Split::Count(6),
                k: 3,
                precision: 0.9,
                matching,
            };
            let e = evaluate(s.view(), &gt, &p, &[Method::QuantileTransferOnline]).unwrap();
            assert_eq!((e.layout.deployment_start, e.layout.segments), (8, 7));
            let cal = Calibration::new(
                s.slice(s![.., ..5]),
                &GroundTruth::from_truth(gt.view().slice(s![.., ..5]).to_owned()),
                matching,
            )
            .unwrap();
            let params = OnlineParams {
                k: 3,
                precision: 0.9,
                window: 6,
                min_window: 1,
                gate: Gate::None,
            };
            let decisions = Online::new(Arc::new(cal), params)
                .unwrap()
                .push_many(s.slice(s![.., 8..50]))
                .unwrap();
            for (g, segment) in e.methods[0].segments.iter().zip(0..) {
                let queries = &decisions[6 * segment..6 * (segment + 1)];
                assert_eq!(g.threshold.to_bits(), queries[5].threshold.to_bits());
                // Counts by hand from the decisions and the ground truth.
                let (mut tp, mut fp, mut positives) = (0, 0, 0);
                for d in queries {
                    let col = 8 + d.query;
                    positives += 1; // every column has its match, row j % 8
                    match matching {
                        Matching::Single => {
                            if d.accept() {
                                if d.best == col % 8 { tp += 1 } else { fp += 1 }
                            }
                        }
                        Matching::Multi => {
                            let hit = usize::from(s[[col % 8, col]] >= d.threshold);
                            tp += hit;
                            fp += d.accepted - hit;
                        }
                    }
                }
                assert_eq!(
                    (g.counts.tp, g.counts.fp, g.counts.positives),
                    (tp, fp, positives),
                    "{matching:?} {segment}"
                );
            }
        }
    }

    #[test]
    fn schubert_per_segment_and_calibrated() {
        // Segment 0 scores (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): mu = (0.3 + 0.5) / 2 = 0.4;
        // |S - mu| = (0.3, 0.2, 0.1, 0.1, 0.2, 0.3) -> median (0.2 + 0.2) / 2 = 0.2;
        // t = 0.4 + (0.2 / 0.675) * z = 1.808... accepts nothing: meets, recall 0.
        // Calibration (0.1, 0.2, 0.3, 0.4, 0.9, 0.95): mu = (0.3 + 0.4) / 2 = 0.35;
        // |S - mu| sorted (0.05, 0.05, 0.15, 0.25, 0.55, 0.6) -> median 0.2;
        // t = 0.35 + (0.2 / 0.675) * z for both segments.
        let e = run(&[Method::Schubert, Method::SchubertCalibrated]);
        let (sch, cal) = (&e.methods[0], &e.methods[1]);
        let near = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(near(sch.segments[0].threshold, 0.4 + 0.2 / 0.675 * SCHUBERT_Z));
        assert_eq!((sch.pct_segs, sch.avg_recall), (Some(100.0), Some(0.0)));
        for g in &cal.segments {
            assert!(near(g.threshold, 0.35 + 0.2 / 0.675 * SCHUBERT_Z));
        }
    }

    #[test]
    fn no_counted_segment_gives_no_figures() {
        // Columns c0, c1, d2, d3 only: the one segment (d2, d3) has no positives.
        let (s, gt) = tiny();
        let cols = [0, 1, 4, 5];
        let s = s.select(ndarray::Axis(1), &cols);
        let gt = GroundTruth::from_truth(gt.view().select(ndarray::Axis(1), &cols));
        let e = evaluate(s.view(), &gt, &protocol(), &[Method::Oracle, Method::Schubert]).unwrap();
        for m in &e.methods {
            assert_eq!((m.segments_counted, m.segments_skipped), (0, 1));
            assert_eq!((m.pct_segs, m.avg_recall, m.threshold_mse), (None, None, None));
        }
    }

    #[test]
    fn pct_segs_avg_recall_and_mse_by_hand() {
        // |DB| = 2, |Q| = 5: c0, then four deployment queries in segments of one, tau = 1,
        // with a fixed threshold 0.5 (calibration-threshold: c0's best match 0.8 is correct,
        // so t = 0.8; the arithmetic below uses that).
        //        c0   d0   d1   d2   d3
        // db0   0.8  0.9  0.7  0.85 0.1
        // db1   0.1  0.2  0.3  0.9  0.2
        // GT:   db0  db0  db0  db0  none
        // d0: best 0.9 (db0, T) accepted -> TP 1, meets, recall 1; oracle 0.9.
        // d1: best 0.7 (T) < 0.8 -> nothing accepted, meets, recall 0; oracle 0.7.
        // d2: best 0.9 (db1, F) accepted -> FP 1, fails; oracle inf (no valid group).
        // d3: no positive -> skipped.
        // Counted 3, meet 2 -> %Segs 66.67; AvgR (1 + 0 + 0) / 3; MSE over d0, d1 (d2's
        // oracle is inf): ((0.8 - 0.9)^2 + (0.8 - 0.7)^2) / 2 = 0.01.
        let s = array![[0.8, 0.9, 0.7, 0.85, 0.1], [0.1, 0.2, 0.3, 0.9, 0.2]];
        let gt = GroundTruth::new(array![[1u8, 1, 1, 1, 0], [0, 0, 0, 0, 0]].view()).unwrap();
        let p = Protocol {
            calibration: Split::Count(1),
            segment: Split::Count(1),
            ..Protocol::default()
        };
        let e = evaluate(s.view(), &gt, &p, &[Method::CalibrationThreshold]).unwrap();
        let c = &e.methods[0];
        assert_eq!((c.segments_counted, c.segments_skipped), (3, 1));
        assert_eq!(c.pct_segs, Some(100.0 * 2.0 / 3.0));
        assert_eq!(c.avg_recall, Some(1.0 / 3.0));
        assert!((c.threshold_mse.unwrap() - 0.01).abs() < 1e-15);
        let pooled = c.pooled();
        assert_eq!((pooled.tp, pooled.fp, pooled.positives), (1, 1, 3));
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
             quantile-transfer-margin, margin, schubert, schubert-calibrated, calibration-threshold, oracle"
        );
        assert_eq!(
            "schubert-calibrated".parse::<Method>().unwrap(),
            Method::SchubertCalibrated
        );
        let (s, gt) = tiny();
        let err = evaluate(s.view(), &gt, &Protocol { k: 0, ..protocol() }, &Method::ALL).unwrap_err();
        assert_eq!(err.to_string(), "k must be >= 1, got 0");
    }

    #[test]
    fn precision_recall_curve_of_the_deployment_set() {
        // Full segments d0..d3 (single): best matches 0.7 T, 0.6 F, 0.5 F, 0.9 F; 2 positives.
        // Descending: 0.9 F (P 0, R 0), 0.7 T (P 1/2, R 1/2), 0.6 F (1/3, 1/2), 0.5 F (1/4, 1/2).
        let e = run(&[Method::Oracle]);
        let curve = e.precision_recall_curve(usize::MAX);
        let got: Vec<(f64, f64, f64)> = curve.iter().map(|p| (p.threshold, p.precision, p.recall)).collect();
        assert_eq!(
            got,
            vec![
                (0.9, 0.0, 0.0),
                (0.7, 0.5, 0.5),
                (0.6, 1.0 / 3.0, 0.5),
                (0.5, 0.25, 0.5)
            ]
        );
        // At a resolution of 2 (steps of 0.5), 0.6 moves precision by 1/6 only: dropped;
        // the last point is always kept.
        let thin: Vec<f64> = e.precision_recall_curve(2).iter().map(|p| p.threshold).collect();
        assert_eq!(thin, vec![0.9, 0.7, 0.5]);
    }

    #[test]
    fn recall_at_1_counts_best_matches_in_both_modes() {
        // Full segments d0..d3: best matches d0 0.7 (db0, hard), d1 0.6 (db1, wrong),
        // d2 0.5 (db0, no match), d3 0.9 (db1, no match). Queries with a hard match: d0, d1
        // -> R@1 = 1 / 2, in multi mode too (it is about best matches).
        for matching in [Matching::Single, Matching::Multi] {
            let (s, gt) = tiny();
            let p = Protocol { matching, ..protocol() };
            let e = evaluate(s.view(), &gt, &p, &[Method::Oracle]).unwrap();
            assert_eq!(e.recall_at_1, Some(0.5), "{matching:?}");
        }
        // Columns c0, c1, d2, d3: the deployment queries have no hard match -> None.
        let (s, gt) = tiny();
        let cols = [0, 1, 4, 5];
        let s = s.select(ndarray::Axis(1), &cols);
        let gt = GroundTruth::from_truth(gt.view().select(ndarray::Axis(1), &cols));
        let e = evaluate(s.view(), &gt, &protocol(), &[Method::Oracle]).unwrap();
        assert_eq!(e.recall_at_1, None);
    }

    #[test]
    fn pooled_counts_and_their_lower_bound() {
        // Oracle: segment 0 TP 1, FP 0, positives 2; segment 1 (d2 0.5, d3 0.9 wrong, no
        // positives) at inf accepts nothing. Pooled: TP 1, FP 0, positives 2; precision 1,
        // recall 1/2, lower bound 0.05^(1/1) = 0.05.
        let e = run(&[Method::Oracle]);
        let p = e.methods[0].pooled();
        assert_eq!((p.tp, p.fp, p.positives), (1, 0, 2));
        assert!((p.precision_lower95().unwrap() - 0.05).abs() < 1e-12);
        // Nothing accepted in segment 1: no bound there.
        assert_eq!(e.methods[0].segments[1].counts.precision_lower95(), None);
    }

    /// The k and calibration-size ablation: one run per setting on the last half.
    #[test]
    fn ablation_runs_every_setting_on_one_deployment_set() {
        // |Q| = 7: the last floor(0.5 * 7) = 3 queries (columns 4..7 = d2, d3, d4) deploy
        // in segments of one; calibration 1 or 2 first queries; k 1 or 5.
        let (s, gt) = tiny();
        let base = Protocol {
            segment: Split::Count(1),
            precision: 0.5,
            ..Protocol::default()
        };
        let a = ablation(
            s.view(),
            &gt,
            &base,
            &[1, 5],
            &[Split::Count(1), Split::Count(2)],
            &[Method::QuantileTransfer, Method::Oracle],
        )
        .unwrap();
        let settings: Vec<(usize, Split)> = a
            .runs
            .iter()
            .map(|r| (r.layout.protocol.k, r.layout.protocol.calibration))
            .collect();
        assert_eq!(
            settings,
            vec![
                (1, Split::Count(1)),
                (5, Split::Count(1)),
                (1, Split::Count(2)),
                (5, Split::Count(2))
            ]
        );
        for r in &a.runs {
            let l = r.layout;
            assert_eq!(l.protocol.deploy_fraction, Some(ABLATION_DEPLOY_FRACTION));
            assert_eq!((l.deployment_start, l.deployment_queries, l.segments), (4, 3, 3));
            // Each run is the protocol with that setting.
            let one = evaluate(s.view(), &gt, &l.protocol, &[Method::QuantileTransfer, Method::Oracle]).unwrap();
            assert_eq!(r.methods, one.methods);
        }
        // An empty list keeps the base value; a deploy fraction given is kept.
        let a = ablation(
            s.view(),
            &gt,
            &Protocol {
                calibration: Split::Count(2),
                deploy_fraction: Some(0.6),
                ..base
            },
            &[3],
            &[],
            &[Method::Oracle],
        )
        .unwrap();
        assert_eq!(a.runs.len(), 1);
        let p = a.runs[0].layout.protocol;
        assert_eq!((p.k, p.calibration, p.deploy_fraction), (3, Split::Count(2), Some(0.6)));
        // A bad setting fails before any run: 5 calibration queries reach into the last 3.
        let err = ablation(
            s.view(),
            &gt,
            &base,
            &[1],
            &[Split::Count(1), Split::Count(5)],
            &[Method::Oracle],
        );
        assert_eq!(
            err.unwrap_err().to_string(),
            "the calibration set (5 queries) and the deployment set (3 queries) overlap: \
             together they exceed the 7 queries"
        );
    }

    #[cfg(feature = "serde")]
    #[test]
    fn serialised_keys() {
        let e = run(&[Method::Oracle, Method::Schubert]);
        let v = serde_json::to_value(crate::report::Report {
            dataset: Some("tiny"),
            result: &e,
        })
        .unwrap();
        let keys = |v: &serde_json::Value| {
            let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
            k.sort();
            k
        };
        assert_eq!(keys(&v), ["dataset", "methods", "params", "recall_at_1"]);
        assert_eq!(
            keys(&v["params"]),
            [
                "calibration",
                "calibration_queries",
                "database_size",
                "deploy_fraction",
                "deployment_queries",
                "deployment_start",
                "k",
                "matching",
                "precision",
                "queries",
                "segment",
                "segment_size",
                "segments"
            ]
        );
        assert_eq!(v["params"]["calibration"], serde_json::json!({"count": 2}));
        assert_eq!(v["params"]["matching"], "single");
        assert_eq!(v["params"]["database_size"], 3);
        assert_eq!(keys(&v["methods"]), ["oracle", "schubert"]);
        let oracle = &v["methods"]["oracle"];
        assert_eq!(
            keys(oracle),
            [
                "avg_recall",
                "pct_segs",
                "pooled_fp",
                "pooled_positives",
                "pooled_precision",
                "pooled_precision_lower95",
                "pooled_recall",
                "pooled_tp",
                "segments",
                "segments_counted",
                "segments_skipped",
                "threshold_mse"
            ]
        );
        assert!((oracle["pooled_precision_lower95"].as_f64().unwrap() - 0.05).abs() < 1e-12);
        let seg = &oracle["segments"][1];
        assert_eq!(
            keys(seg),
            [
                "end",
                "fp",
                "meets",
                "oracle_threshold",
                "positives",
                "precision",
                "precision_lower95",
                "recall",
                "start",
                "threshold",
                "tp"
            ]
        );
        // Reject-all is null in JSON; so is a bound over nothing accepted.
        assert_eq!(
            (seg["threshold"].is_null(), seg["precision_lower95"].is_null()),
            (true, true)
        );
        assert_eq!(v["recall_at_1"], 0.5);
        let (s, gt) = tiny();
        let a = ablation(s.view(), &gt, &protocol(), &[1, 2], &[], &[Method::Oracle]).unwrap();
        let v = serde_json::to_value(crate::report::Report {
            dataset: None,
            result: &a,
        })
        .unwrap();
        assert_eq!(keys(&v), ["ablation", "dataset"]);
        assert_eq!(keys(&v["ablation"][1]), ["methods", "params", "recall_at_1"]);
        assert_eq!(v["ablation"][1]["params"]["k"], 2);
    }

    #[test]
    fn repeated_methods_are_reported_once() {
        let e = run(&[Method::Oracle, Method::Schubert, Method::Oracle]);
        let names: Vec<&str> = e.methods.iter().map(|m| m.method.as_str()).collect();
        assert_eq!(names, vec!["oracle", "schubert"]);
    }
}
