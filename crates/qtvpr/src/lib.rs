//! # qtvpr: quantile transfer for visual place recognition
//!
//! A VPR system accepts a match when its similarity score is at or above a threshold.
//! Quantile transfer (Rajani, Milford, Fischer, IROS 2026) sets that threshold for each
//! batch of deployment queries without their ground truth: it finds, for every
//! deployment query, the calibration queries whose sorted similarity profiles correlate
//! best with its own, takes the threshold of maximum recall at the target precision on
//! those, expresses it as a quantile of their scores, and reads the batch's weighted
//! median quantile off the deployment scores.
//!
//! The semantics are those of `docs/semantics.md` in the repository, one module per section:
//!
//! | semantics | module |
//! |---|---|
//! | 1 terms, input validation | [`input`] |
//! | 1 the scores an operation reads: a matrix or descriptors | [`source`] |
//! | 1 orientation: what was assumed, what ground truth says of it | [`orientation`] |
//! | 2 decisions and counts | [`decisions`] |
//! | 3 best threshold under a precision target | [`best_threshold`](mod@best_threshold) |
//! | 4 ranked correlation and neighbours | [`ranked_correlation`](mod@ranked_correlation) |
//! | 5 quantile of a subset threshold | [`subset_quantile`](mod@subset_quantile) |
//! | 6 deployment threshold of a segment | [`deployment`] |
//! | 4-6 together | [`transfer`] |
//! | 7 baselines (Schubert et al.'s threshold) | [`baselines`] |
//! | 8 evaluation protocol (%Segs, AvgR@tauP), ablations | [`evaluate`](mod@evaluate) |
//! | 8.1's calibration rule for one matrix: the first queries calibrate | [`split`] |
//! | 9 machine-readable output (feature `serde`) | [`report`] |
//! | 11 online thresholds over a causal window | [`online`] |
//! | 12 the calibration file (save/load: feature `npy`) | [`calibration_file`] |
//! | 13 the margin gate (an extension) | [`margin`] |
//! | 14 confidence: a calibrated probability per decision (an extension) | [`confidence`] |
//! | extension: similarity from descriptors | [`similarity`] |
//! | extension: sequence matching (the paper's future work) | [`sequence`] |
//! | extension: ground truth from a frame tolerance or positions | [`ground_truth`] |
//! | extension: positions from image names (`@utm_east@utm_north@...@.jpg`) | [`image_names`] |
//! | the thread pool, rebuilt in a forked child (§10) | [`threads`] |
//! | the sort of a profile (AVX-512 quicksort, else `radsort`) | `sort` |
//! | file input and output (feature `npy`) | `npy` |
//! | the matrices errors are about ([`Input`]) | [`names`] |
//!
//! The extensions are beyond the paper and are not sections of the semantics: they make the
//! similarity and ground-truth matrices the method takes from what users have
//! (descriptors, positions, frame-aligned traverses).
//!
//! Matrices are |DB| x |Q| [`ndarray::ArrayView2`]s of `f32` or `f64` with any strides
//! (pass `.t()` of a query-major matrix); nothing is copied up front and every value
//! the results depend on is computed in `f64` (bounds from block summaries only rule out
//! neighbours that provably cannot be chosen; see [`ranked_correlation`](mod@ranked_correlation)).
//!
//! ```
//! use ndarray::array;
//! use qtvpr::{Calibration, GroundTruth, Matching, Params};
//!
//! // 3 database images x 2 calibration queries; query j matches database image j.
//! let s_cal = array![[0.9, 0.2], [0.1, 0.8], [0.3, 0.4]];
//! let gt = GroundTruth::new(array![[true, false], [false, true], [false, false]].view())?;
//! let cal = Calibration::new(s_cal.view(), &gt, Matching::Single)?;
//!
//! // 3 deployment queries, thresholded as one batch. With k = 2 each samples both
//! // calibration queries: their best matches 0.9 and 0.8 are correct, so the threshold
//! // of 100% precision and most recall is 0.8, the 5th of their 6 scores, quantile
//! // (5 - 1) / (6 - 1) = 0.8. Read off the 9 deployment scores (0.1 0.1 0.2 0.2 0.3 0.3
//! // 0.5 0.6 0.7), quantile 0.8 falls 0.4 of the way from 0.5 to 0.6: 0.54.
//! let s_val = array![[0.7, 0.1, 0.2], [0.2, 0.6, 0.3], [0.1, 0.3, 0.5]];
//! let out = cal.transfer(s_val.view(), &Params { k: 2, ..Params::default() })?;
//! assert_eq!(out.segments.len(), 1);
//! assert!((out.segments[0].quantile - 0.8).abs() < 1e-12);
//! assert!((out.segments[0].threshold - 0.54).abs() < 1e-12);
//! // So queries 0 and 1 keep their best matches (0.7, 0.6), query 2 (0.5) does not.
//! # Ok::<(), qtvpr::Error>(())
//! ```

// First, so that `with_scores!` (defined beside `ScoresView`) is in scope in every
// module below by name.
#[macro_use]
pub mod input;

pub mod baselines;
pub mod best_threshold;
pub mod calibration_file;
pub mod confidence;
pub mod decisions;
pub mod deployment;
mod error;
pub mod evaluate;
pub mod ground_truth;
pub mod image_names;
mod kd_tree;
pub mod margin;
pub mod names;
#[cfg(feature = "npy")]
pub mod npy;
pub mod online;
pub mod orientation;
pub mod params;
pub mod ranked_correlation;
pub mod report;
pub mod sequence;
pub mod similarity;
mod sort;
pub mod source;
pub mod split;
pub mod subset_quantile;
pub mod threads;
pub mod transfer;

pub use baselines::schubert_threshold;
pub use best_threshold::best_threshold;
pub use confidence::ConfidenceMap;
pub use decisions::{Counts, Matching, counts};
pub use error::{Error, Result};
pub use evaluate::{Ablation, Evaluation, Method, Protocol, Split, ablation, evaluate};
pub use input::{GroundTruth, Label, Score, ScoreMatrix, ScoresView, Truth};
pub use margin::{Gate, margins};
pub use names::Input;
pub use online::{Decision, Online};
pub use orientation::Orientation;
pub use params::{DEFAULT_K, DEFAULT_PRECISION, Defaults, OnlineParams, Options, Params};
pub use ranked_correlation::ranked_correlation;
pub use sequence::{Sequence, sequence_match};
pub use similarity::{Descriptors, cosine_similarity};
pub use source::ScoreSource;
pub use split::QuerySplit;
pub use threads::set_threads;
pub use transfer::{Calibration, Segment, Transfer};
