//! semantics §9: the machine-readable results, one schema for `qtvpr-cli ... --format
//! json` and the dicts of the Python binding.
//!
//! With the `serde` feature, the result types derive `serde::Serialize`, and both
//! front ends serialise those same values: the CLI with `serde_json`, the binding with
//! `pythonize`. The keys are therefore identical by construction; only the encoding of
//! a reject-all threshold differs: `null` in JSON (which has no infinity), `math.inf`
//! in Python. Figures that are undefined (no segment counted, nothing accepted) are
//! `null` / `None` in both.
//!
//! # `evaluate` (and `qtvpr.evaluate`)
//!
//! One run of the evaluation protocol ([`Evaluation`] inside a `Report`, the wrapper
//! this module defines with the `serde` feature):
//!
//! - `dataset`: what the run was made on: the similarity file's path, the embedded
//!   data's name, or `None` in Python when the matrix was passed as an array.
//! - `orientation` (a similarity matrix the caller gave, not descriptors or the
//!   embedded data; [`Orientation`]): `db` and `queries` (|DB| and |Q| as computed on),
//!   `query_major` (read transposed), and with ground truth read from a file (or given
//!   as an array) `evidence`: `labelled_queries`, `queries_without_positive`,
//!   `db_without_positive` (hard positives) and `verdict` (`"consistent"`,
//!   `"cannot-tell"` or `"contradicts"`: every database image has a positive and at
//!   least 5% of the queries have none, so the transposed layout is the likelier).
//! - `params` ([`Layout`], with its [`Protocol`] flattened in):
//!   - the parameters: `k`, `precision` (tau), `matching` (`"single"` or `"multi"`),
//!     `calibration` and `segment` as asked for (`{"fraction": f}` of all |Q| queries or
//!     `{"count": n}`), `deploy_fraction` (`null`: every query after the calibration
//!     set);
//!   - how they split this matrix: `database_size` (|DB|), `queries` (|Q|),
//!     `calibration_queries` (columns `0..calibration_queries` calibrate),
//!     `deployment_start` (the column of deployment query 0), `deployment_queries`
//!     (|Qdeploy|, including the dropped remainder), `segment_size`, `segments` (the
//!     number of full segments).
//! - `recall_at_1`: R@1 of the deployment set (its full segments): the queries whose
//!   best match (the first maximum of the column) is a hard match, divided by the
//!   queries with at least one hard match. It is computed from best matches whatever
//!   `matching` is; a query whose best match is soft-only counts as a miss. `null` when
//!   no deployment query has a hard match.
//! - `methods`: one object per method asked for, keyed by its name
//!   (`"quantile-transfer"`, `"quantile-transfer-sequence"`, `"schubert"`, ...:
//!   [`Method`]), in the order asked ([`MethodResult`]):
//!   - `pct_segs`: %Segs, 100 x segments that meet the target / segments counted;
//!   - `avg_recall`: AvgR@tauP, the mean over counted segments of their recall if they
//!     meet the target, else 0;
//!   - `segments_counted` (segments with at least one positive) and
//!     `segments_skipped` (without: left out of both figures, which are `null` when no
//!     segment is counted);
//!   - `threshold_mse`: the mean squared difference from the oracle's threshold over
//!     the counted segments where both are finite (`null` if none);
//!   - `pooled_tp`, `pooled_fp`, `pooled_accepted` (TP + FP: the matches the method
//!     accepted), `pooled_positives`: the counts summed over every full segment
//!     (skipped ones included), the method's operating point on the whole deployment
//!     set, and from them `pooled_precision` (`null` when nothing was accepted: a
//!     %Segs of 100 then rests on no decision), `pooled_recall` and
//!     `pooled_precision_lower95` (as for a segment, below);
//!   - `segments`: every full segment in order ([`SegmentResult`]): `start`, `end`
//!     (deployment-query indices, end exclusive: deployment query i is column
//!     `deployment_start + i`), `threshold` (the method's; reject-all is `null` /
//!     `inf`; the `margin` method's is always `-inf`, also `null` in JSON: it accepts
//!     every score and its gate decides, as the `sequence` method's), `oracle_threshold`,
//!     `gate` (the methods with the margin gate only, semantics §13: `m*`; reject-all
//!     is `null` / `inf`), `consistency_level` (the methods with the sequence gate
//!     only, semantics §15: its level), `tp`, `fp`, `accepted`, `positives`,
//!     `precision` (`null` when nothing is accepted), `recall` (0 without positives),
//!     `precision_lower95` and `meets` (precision >= tau - 1e-12, or nothing accepted:
//!     the paper's convention, semantics §8.3).
//! - `confidence` (single matching with |DB| >= 2 only, semantics §14): `{"signals":
//!   {"score": {"auroc"}, "margin": {"auroc"}, "pa_score": {"auroc"}, "consistency":
//!   {"auroc"}, "confidence": {"auroc", "brier", "ece", "bins"}}}` over the full
//!   segments' decisions ([`Signals`]; the consistency is semantics §15's, `null` on a
//!   database too small for the sequence gate's parameters); `bins` is the
//!   reliability summary the ECE is computed from, the non-empty ones of 10 equal-width
//!   bins of [0, 1], each `{"lower", "upper", "n", "mean_confidence", "hit_rate"}`
//!   ([`ReliabilityBin`]), `null` with the ECE.
//!
//! `precision_lower95` is the one-sided 95% Clopper-Pearson lower bound on the
//! precision, the 0.05 quantile of Beta(TP, FP + 1) ([`Counts::precision_lower95`]): 0
//! when TP = 0, `null` when nothing is accepted. A segment of 2 decisions at "100%
//! precision" has a bound of 0.22; 28 correct decisions without a false positive, 0.90.
//!
//! # An ablation (`evaluate --k 1,3,5 ...`, `qtvpr.ablation`)
//!
//! `dataset` as above, and `ablation`: a list with one object per setting
//! ([`Ablation`]), each with the `params`, `recall_at_1`, `methods` (and `confidence`)
//! of one run. Every
//! run shares the deployment set (see [`ablation`](crate::operations::evaluate::ablation)).
//!
//! # `threshold`
//!
//! One transfer ([`ThresholdReport`]): `method` (`"quantile-transfer"`), `params`
//! ([`Params`] with the segment size resolved, and `matching`), `segments` ([`Segment`]:
//! `start`, `end`, `quantile`, `threshold`; reject-all is `null`), with the margin gate
//! `gate` (`m*`, semantics §13), with the sequence gate `consistency_level` and
//! `query_consistencies` (each deployment query's, semantics §15),
//! `calibration_queries`, `deployment_queries`,
//! `database_size` and, for a similarity matrix (`--val` or `--similarity`),
//! `orientation` as above: `queries` are its columns, `evidence` that of the ground
//! truth given (the calibration queries', or every query's for a split).
//!
//! # `qtvpr.counts` and `Calibration.defaults`
//!
//! [`Counts`] at one threshold: `tp`, `fp`, `accepted`, `positives`, `precision`
//! (`null` when nothing is accepted), `recall` and `precision_lower95`, the keys of a
//! segment of `evaluate`. A calibration's [`Defaults`]: `k`, `precision`, `window`
//! (`None` when the file sets none), `gate` and `sequence_gate` (`window`, `level`,
//! `speed`, `tolerance`, `drift`), the `params` of its file.
//!
//! [`Evaluation`]: crate::operations::evaluate::Evaluation
//! [`Layout`]: crate::operations::evaluate::Layout
//! [`Protocol`]: crate::operations::evaluate::Protocol
//! [`MethodResult`]: crate::operations::evaluate::MethodResult
//! [`Method`]: crate::operations::evaluate::Method
//! [`SegmentResult`]: crate::operations::evaluate::SegmentResult
//! [`Ablation`]: crate::operations::evaluate::Ablation
//! [`Signals`]: crate::signals::confidence::Signals
//! [`ReliabilityBin`]: crate::signals::confidence::ReliabilityBin
//! [`Counts::precision_lower95`]: crate::rules::decisions::Counts::precision_lower95
//! [`Params`]: crate::input::params::Params
//! [`Segment`]: crate::operations::transfer::Segment
//! [`Counts`]: crate::rules::decisions::Counts
//! [`Defaults`]: crate::input::params::Defaults
//! [`Orientation`]: crate::input::orientation::Orientation

#[cfg(feature = "serde")]
pub use serialize::{Report, ThresholdParams, ThresholdReport};

#[cfg(feature = "serde")]
pub(crate) mod serialize {
    use serde::Serialize;

    use crate::input::orientation::Orientation;
    use crate::input::params::Params;
    use crate::operations::calibration::Calibration;
    use crate::operations::evaluate::Method;
    use crate::operations::transfer::{Segment, Transfer};
    use crate::rules::decisions::Matching;

    /// A result with the name of what it was computed on: the document `qtvpr-cli
    /// evaluate` prints and the dict `qtvpr.evaluate` / `qtvpr.ablation` return.
    #[derive(Debug, Clone, Copy, Serialize)]
    pub struct Report<'a, T> {
        /// The similarity file's path or the dataset's name; `None` when unknown.
        pub dataset: Option<&'a str>,
        /// How a similarity matrix given by the caller was read, and what its ground
        /// truth says of that; `None` (left out) for descriptors and embedded data.
        #[serde(skip_serializing_if = "Option::is_none")]
        pub orientation: Option<Orientation>,
        /// The [`Evaluation`](crate::operations::evaluate::Evaluation) or
        /// [`Ablation`](crate::operations::evaluate::Ablation), its keys beside `dataset`.
        #[serde(flatten)]
        pub result: &'a T,
    }

    /// The document of `qtvpr-cli threshold`: one transfer, its parameters and the
    /// sizes of its inputs.
    #[derive(Debug, Clone, Copy, Serialize)]
    pub struct ThresholdReport<'a> {
        /// `"quantile-transfer"`.
        pub method: &'static str,
        /// The parameters of the transfer.
        pub params: ThresholdParams,
        /// Its segments.
        pub segments: &'a [Segment],
        /// With the margin gate (semantics §13): `m*`; left out without it.
        #[serde(skip_serializing_if = "Option::is_none")]
        pub gate: Option<f64>,
        /// With the sequence gate (semantics §15): its level; left out without it.
        #[serde(skip_serializing_if = "Option::is_none")]
        pub consistency_level: Option<f64>,
        /// With the sequence gate: every deployment query's consistency; left out
        /// without it.
        #[serde(skip_serializing_if = "Option::is_none")]
        pub query_consistencies: Option<&'a [f64]>,
        /// |Qcal|.
        pub calibration_queries: usize,
        /// |Qval|, the queries thresholded.
        pub deployment_queries: usize,
        /// |DB|.
        pub database_size: usize,
        /// How the thresholded similarity matrix was read, with the evidence of the
        /// ground truth given; `None` (left out) for descriptors. Set by the caller.
        #[serde(skip_serializing_if = "Option::is_none")]
        pub orientation: Option<Orientation>,
    }

    /// The `params` of a [`ThresholdReport`]: the transfer's [`Params`], its segment
    /// size resolved (every deployment query when it had none), and the matching mode.
    #[derive(Debug, Clone, Copy, Serialize)]
    pub struct ThresholdParams {
        /// `k`, `precision`, `segment_size` and `gate`.
        #[serde(flatten)]
        pub params: Params,
        /// The calibration's matching mode.
        pub matching: Matching,
    }

    impl<'a> ThresholdReport<'a> {
        /// The document of `transfer`, the result of `cal.transfer(..., params)`.
        pub fn new(cal: &Calibration, params: &Params, transfer: &'a Transfer) -> Self {
            let deployment_queries = transfer.query_quantiles.len();
            Self {
                method: Method::QuantileTransfer.as_str(),
                params: ThresholdParams {
                    params: Params {
                        segment_size: Some(params.segment_size.unwrap_or(deployment_queries)),
                        ..*params
                    },
                    matching: cal.matching(),
                },
                segments: &transfer.segments,
                gate: transfer.gate,
                consistency_level: transfer.consistency_level,
                query_consistencies: transfer.query_consistencies.as_deref(),
                calibration_queries: cal.len(),
                deployment_queries,
                database_size: cal.db_size(),
                orientation: None,
            }
        }
    }
}

#[cfg(all(test, feature = "serde"))]
mod tests {
    use ndarray::array;
    use serde_json::json;

    use super::ThresholdReport;
    use crate::input::GroundTruth;
    use crate::input::params::{Defaults, Params};
    use crate::operations::calibration::Calibration;
    use crate::rules::decisions::{Counts, Matching};

    #[test]
    fn the_threshold_document() {
        // The transfer.rs example: with k = 1 and segments of one query the quantiles
        // are 0.5 and 1 and the thresholds 4 and the next f64 above 5.
        let s_cal = array![[3.0, 1.0], [1.0, 4.0], [2.0, 1.0]];
        let gt = GroundTruth::new(array![[1u8, 1], [0, 1], [1, 0]].view()).unwrap();
        let cal = Calibration::new(s_cal.view(), &gt, Matching::Multi).unwrap();
        let s_val = array![[2.0, 2.0], [6.0, 5.0], [4.0, 2.0]];
        let params = Params {
            k: 1,
            segment_size: Some(1),
            ..Params::default()
        };
        let transfer = cal.transfer(s_val.view(), &params).unwrap();
        assert_eq!(
            serde_json::to_value(ThresholdReport::new(&cal, &params, &transfer)).unwrap(),
            json!({
                "method": "quantile-transfer",
                // No sequence gate: none of its parameters.
                "params": {"k": 1, "precision": 1.0, "segment_size": 1, "gate": "none", "matching": "multi"},
                "segments": [
                    {"start": 0, "end": 1, "quantile": 0.5, "threshold": 4.0},
                    {"start": 1, "end": 2, "quantile": 1.0, "threshold": 5f64.next_up()},
                ],
                "calibration_queries": 2,
                "deployment_queries": 2,
                "database_size": 3,
            })
        );
        // No segment size: one segment of both deployment queries.
        let params = Params {
            k: 1,
            ..Params::default()
        };
        let transfer = cal.transfer(s_val.view(), &params).unwrap();
        let document = serde_json::to_value(ThresholdReport::new(&cal, &params, &transfer)).unwrap();
        assert_eq!(document["params"]["segment_size"], 2);
    }

    #[test]
    fn counts_and_defaults() {
        // 3 of 4 accepted are correct, of 5 positives: precision 0.75, recall 0.6.
        let c = Counts {
            tp: 3,
            fp: 1,
            positives: 5,
        };
        let text = serde_json::to_string(&c).unwrap();
        assert!(
            text.starts_with(
                r#"{"tp":3,"fp":1,"accepted":4,"positives":5,"precision":0.75,"recall":0.6,"precision_lower95":0."#
            ),
            "{text}"
        );
        // Nothing accepted: no precision, no bound.
        let none = Counts {
            tp: 0,
            fp: 0,
            positives: 5,
        };
        assert_eq!(
            serde_json::to_value(none).unwrap(),
            json!({"tp": 0, "fp": 0, "accepted": 0, "positives": 5, "precision": null, "recall": 0.0,
                   "precision_lower95": null})
        );
        assert_eq!(
            serde_json::to_value(Defaults::default()).unwrap(),
            json!({"k": 10, "precision": 1.0, "window": null, "gate": "none", "sequence_gate": {
                "window": 5, "level": 0.8, "speed": 1.0, "tolerance": 2.0, "drift": 0.2}})
        );
    }
}
