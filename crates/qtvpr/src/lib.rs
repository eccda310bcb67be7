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
//! The semantics are those of `docs/semantics.md` in the repository, one module per
//! section, grouped in folders by what they are:
//!
//! | folder | modules (semantics §) | what they are |
//! |---|---|---|
//! | `input/` | `mod.rs` (§1), `params` | what an operation is given: scores and ground truth and their checks; the parameters (the gate among them), resolved once |
//! | `rules/` | `decisions` (§2), `best_threshold` (§3), `ranked_correlation` (§4), `subset_quantile` (§5), `deployment` (§6), `baselines` (§7) | the paper's rules, one per section |
//! | `operations/` | `transfer` (§4-§6), `online` (§11), `evaluate/` (§8), `source` (§1), `split` (§8.1) | what a user runs: a batch, a stream, the protocol; what each reads (a matrix or descriptors), and one matrix split into calibration and deployment |
//! | `signals/` | `margin` (§13), `confidence` (§14), `orientation` (§1) | what is said of each query beyond its threshold, and of the layout |
//! | `extensions/` | `similarity`, `sequence`, `ground_truth`, `kd_tree`, `image_names` | beyond the paper: the matrices from what users have |
//! | `files/` | `calibration_file` (§12), `report` (§9), `npy/` | reading and writing: the calibration file, the JSON documents, `.npy`/`.npz` |
//! | `error/` | `mod.rs`, `names` | the one error enum, and the inputs ([`Input`]) errors are about |
//! | `platform/` | `sort`, `threads` (§10) | the machine: the sort of a profile (AVX-512 quicksort, else `radsort`), the thread pool rebuilt in a forked child |
//!
//! Every public item is exported here, at the crate's root, and `npy` (feature `npy`)
//! is the one public module: the modules themselves are the crate's own, so that moving
//! a rule from one file to another changes no user's code.
//!
//! The extensions are beyond the paper and are not sections of the semantics: they make the
//! similarity and ground-truth matrices the method takes from what users have
//! (descriptors, positions, frame-aligned traverses).
//!
//! Matrices are |DB| x |Q| [`ndarray::ArrayView2`]s of `f32` or `f64` with any strides
//! (pass `.t()` of a query-major matrix); nothing is copied up front and every value
//! the results depend on is computed in `f64` (bounds from block summaries only rule out
//! neighbours that provably cannot be chosen; see [`ranked_correlation()`] and `rules/ranked_correlation.rs`).
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
mod input;

mod error;
mod extensions;
mod files;
mod operations;
mod platform;
mod rules;
mod signals;

pub use error::names::Input;
pub use error::{Error, Result};
pub use extensions::ground_truth::{GtSpec, HardSoft, check_radius, within_radius, within_tolerance};
#[cfg(feature = "npy")]
pub use extensions::image_names::image_paths;
pub use extensions::image_names::{IMAGE_EXTENSIONS, utm_position, utm_positions};
pub use extensions::sequence::{Sequence, sequence_match};
pub use extensions::similarity::{Descriptors, TILE, cosine_similarity};
#[cfg(feature = "npy")]
pub use files::npy;
#[cfg(feature = "serde")]
pub use files::report::{Report, ThresholdParams, ThresholdReport};
pub use input::params::{DEFAULT_K, DEFAULT_PRECISION, Defaults, Gate, OnlineParams, Options, Params};
pub use input::{GroundTruth, Label, Score, ScoreMatrix, ScoresView, Truth, check_nonempty};
pub use operations::evaluate::{
    ABLATION_DEPLOY_FRACTION, Ablation, DEFAULT_CAL_FRACTION, DEFAULT_SEGMENT_FRACTION, Evaluation, Layout, Method,
    MethodResult, PrPoint, Protocol, SegmentResult, Split, ablation, evaluate,
};
pub use operations::online::{Decision, Online};
pub use operations::source::ScoreSource;
pub use operations::split::QuerySplit;
pub use operations::transfer::{Calibration, Segment, Transfer};
pub use platform::threads::{MAX_THREADS, current_threads, install as run_in_pool, set_threads};
pub use rules::baselines::schubert_threshold;
pub use rules::best_threshold::best_threshold;
pub use rules::decisions::{Counts, Matching, best_match, counts};
pub use rules::deployment::deployment_threshold;
pub use rules::ranked_correlation::{ranked_correlation, top_k};
pub use signals::confidence::{Block as ConfidenceBlock, ConfidenceMap, Signal, Signals, pa_score};
pub use signals::margin::margins;
pub use signals::orientation::{Evidence, Orientation, hint as orientation_hint};
