//! The paper's rules, one module per section of the semantics (§2-§7): what a decision
//! is, the best threshold under a precision target, the calibration neighbours, the
//! quantile of a subset threshold, a segment's deployment threshold, and the baselines.

pub(crate) mod baselines;
pub(crate) mod best_threshold;
pub(crate) mod decisions;
pub(crate) mod deployment;
pub(crate) mod ranked_correlation;
pub(crate) mod subset_quantile;
