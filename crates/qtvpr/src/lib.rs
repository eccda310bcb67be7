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
//! The semantics are those of `docs/semantics.md` in the repository; each section lives
//! in one module named after it (the table of "§ -> file" in that document, which a test
//! keeps true), grouped in folders by what they are:
//!
//! | folder | modules (semantics §) | what they are |
//! |---|---|---|
//! | `input/` | `mod.rs` (§1), `orientation` (§1), `params` | what an operation is given: scores and ground truth and their checks, the layout they were read in; the parameters (the gate among them), resolved once |
//! | `rules/` | `decisions` (§2), `best_threshold` (§3), `ranked_correlation/` (§4), `subset_quantile` (§5), `deployment` (§6), `baselines` (§7) | the paper's rules, one per section |
//! | `gates/` | `mod.rs`, `margin` (§13), `sequence` (§15) | the gates of a decision, composed once: a best match is kept when its score reaches the threshold and every enabled gate passes |
//! | `signals/` | `confidence` (§14) | what is said of each query beyond its decision |
//! | `operations/` | `calibration`, `transfer` (§4-§6), `online/` (§11), `evaluate/` (§8), `split` (§8.1), `source`, `chunks` | what a user runs: a batch, a stream, the protocol; the calibration all of them read; what each reads (a matrix or descriptors, a chunk at a time), and one matrix split into calibration and deployment |
//! | `extensions/` | `similarity`, `sequence`, `ground_truth`, `kd_tree`, `image_names` | beyond the paper: the matrices from what users have |
//! | `files/` | `calibration_file` (§12), `report` (§9), `npy/` | reading and writing: the calibration file, the JSON documents, `.npy`/`.npz` |
//! | `error/` | `mod.rs` (§10), `names` | the one error enum, and the inputs ([`Input`]) errors are about |
//! | `platform/` | `sort`, `threads` | the machine: the sort of a profile (AVX-512 quicksort, else `radsort`), the thread pool rebuilt in a forked child |
//!
//! Every public item is exported here, at the crate's root, and `npy` (feature `npy`)
//! is the one public module: the modules themselves are the crate's own, so that moving
//! a rule from one file to another changes no user's code.
//!
//! The extensions are beyond the paper and are not sections of the semantics: they make the
//! similarity and ground-truth matrices the method takes from what users have
//! (descriptors, positions, frame-aligned traverses).
//!
//! # Front-end plumbing
//!
//! The CLI, the Python binding and the C library compute nothing themselves; besides the
//! operations above they use what a program that only computes does not need, exported
//! under one heading below: [`ScoresView`] and [`with_scores!`] (one generic call for
//! `f32` and `f64` matrices), [`ScoreMatrix`], [`Input`] and [`Error::inputs`] (errors
//! named in each front end's terms), [`Orientation`], [`Evidence`] and
//! [`orientation_hint`] (what a layout switch is told), [`QuerySplit`] and
//! [`SplitError`] (one matrix split into calibration and deployment queries), the
//! decision record's list of fields ([`Decision::RECORD`]: [`Field`], [`Kind`],
//! [`Value`]) that every front end lays a record out from, the documents of
//! [`Report`] and [`ThresholdReport`] (feature `serde`), the checks a front end makes
//! before it reads a file ([`check_nonempty`], [`check_radius`], [`check_gate`]), the
//! defaults of its arguments ([`DEFAULT_IMAGE_RADIUS`], the `DEFAULT_*` of the
//! parameters), and the files: [`npy`], [`image_paths`], [`IMAGE_EXTENSIONS`].
//!
//! Matrices are |DB| x |Q| [`ndarray::ArrayView2`]s of `f32` or `f64` with any strides
//! (pass `.t()` of a query-major matrix); nothing is copied up front and every value
//! the results depend on is computed in `f64` (bounds from block summaries only rule out
//! neighbours that provably cannot be chosen; see [`ranked_correlation()`] and `rules/ranked_correlation/screen.rs`).
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
mod gates;
mod operations;
mod platform;
mod rules;
mod signals;

// The library: the rules, the operations, what they take and what they give.
pub use error::{Error, Result};
pub use extensions::ground_truth::{GtSpec, HardSoft, within_radius, within_tolerance};
pub use extensions::image_names::{utm_position, utm_positions};
pub use extensions::sequence::{Sequence, sequence_match};
pub use extensions::similarity::{Descriptors, cosine_similarity};
pub use gates::margin::margins;
pub use gates::sequence::sequence_consistency;
pub use input::params::{
    DEFAULT_DRIFT, DEFAULT_K, DEFAULT_MIN_WINDOW, DEFAULT_PRECISION, DEFAULT_SEQUENCE_LEVEL, DEFAULT_SEQUENCE_WINDOW,
    DEFAULT_SPEED, DEFAULT_TOLERANCE, Defaults, Gate, Line, OnlineParams, Options, Params, SequenceOverrides,
    SequenceParams,
};
pub use input::{GroundTruth, Label, LabelRecord, Score, Truth};
pub use operations::calibration::Calibration;
pub use operations::evaluate::{
    ABLATION_DEPLOY_FRACTION, Ablation, DEFAULT_CAL_FRACTION, DEFAULT_SEGMENT_FRACTION, Evaluation, Layout, Method,
    MethodResult, PrPoint, Protocol, SCORE_HISTOGRAM_BINS, ScoreHistogram, SegmentResult, Split, ablation, evaluate,
};
pub use operations::online::{Decision, Online};
pub use operations::source::ScoreSource;
pub use operations::transfer::{Segment, Transfer};
pub use platform::threads::{MAX_THREADS, current_threads, set_threads};
pub use rules::baselines::schubert_threshold;
pub use rules::best_threshold::best_threshold;
pub use rules::decisions::{Counts, Matching, best_match, counts};
pub use rules::deployment::deployment_threshold;
pub use rules::ranked_correlation::ranked_correlation;
pub use signals::confidence::{Block as ConfidenceBlock, ConfidenceMap, Signal, Signals, pa_score};
pub use signals::self_motion::{
    DEFAULT_NEGATIVE_LEVEL, DEFAULT_NEIGHBOURS, DEFAULT_POSITIVE_LEVEL, LabelCounts, LabelParams, SELF_MOTION,
    SelfMotionLabel, SelfMotionLabels, self_motion_labels,
};

// Front-end plumbing (the crate docs' heading of that name): reading, dispatching on the
// score type, naming inputs, laying out records and documents, early checks.
pub use error::names::Input;
pub use extensions::ground_truth::check_radius;
#[cfg(feature = "npy")]
pub use extensions::image_names::image_paths;
pub use extensions::image_names::{DEFAULT_IMAGE_RADIUS, IMAGE_EXTENSIONS};
#[cfg(feature = "npy")]
pub use files::npy;
#[cfg(feature = "serde")]
pub use files::report::{Report, ThresholdParams, ThresholdReport};
pub use gates::check as check_gate;
pub use input::orientation::{Evidence, Orientation, hint as orientation_hint};
pub use input::{ScoreMatrix, ScoresView, check_nonempty};
pub use operations::online::{Field, Kind, Value};
pub use operations::split::{QuerySplit, SplitError};
