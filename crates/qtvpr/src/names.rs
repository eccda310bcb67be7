//! The names of the matrices an [`Error`](crate::Error) can be about.
//!
//! Every error about a matrix carries one of these in its `what` (and `other`) field,
//! and [`Error::about`](crate::Error::about) returns them, so that a front end maps an
//! error to the argument or file it came from by looking these constants up
//! ([`Error::inputs`](crate::Error::inputs)), never by matching message text.

/// The one similarity matrix of [`best_threshold`](crate::best_threshold),
/// [`counts`](crate::counts), [`evaluate`](crate::evaluate), ...
pub const SIMILARITY: &str = "similarity";
/// The calibration similarity of a [`Calibration`](crate::Calibration).
pub const CAL_SIMILARITY: &str = "calibration similarity";
/// The deployment similarity of [`Calibration::transfer`](crate::Calibration::transfer).
pub const DEPLOYMENT_SIMILARITY: &str = "deployment similarity";
/// Hard ground truth.
pub const GROUND_TRUTH: &str = "ground truth";
/// Soft ground truth.
pub const SOFT_GROUND_TRUTH: &str = "soft ground truth";
/// The database descriptors of [`cosine_similarity`](crate::cosine_similarity).
pub const DB_DESCRIPTORS: &str = "database descriptor matrix";
/// The query descriptors of [`cosine_similarity`](crate::cosine_similarity).
pub const QUERY_DESCRIPTORS: &str = "query descriptor matrix";
/// The database positions of [`within_radius`](crate::ground_truth::within_radius).
pub const DB_POSITIONS: &str = "database position matrix";
/// The query positions of [`within_radius`](crate::ground_truth::within_radius).
pub const QUERY_POSITIONS: &str = "query position matrix";
