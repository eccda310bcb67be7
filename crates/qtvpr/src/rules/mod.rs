//! The paper's rules, one module per section of the semantics (§2-§7): what a decision
//! is, the best threshold under a precision target, the calibration neighbours, the
//! quantile of a subset threshold, a segment's deployment threshold, and the baselines;
//! and the agreement of two best matches along a traverse, which §15 and §16 share.

pub(crate) mod agreement;
pub(crate) mod baselines;
pub(crate) mod best_threshold;
pub(crate) mod decisions;
pub(crate) mod deployment;
pub(crate) mod ranked_correlation;
pub(crate) mod subset_quantile;
