//! What a user runs: a batch of deployment queries ([`transfer`]: §4-§6 together), one
//! query at a time over a causal window ([`online`]: §11), and the paper's protocol
//! with every method ([`evaluate`](mod@evaluate): §8); what each of them reads, a matrix
//! or descriptors ([`source`]), and one matrix split into calibration and deployment
//! queries ([`split`]: §8.1).

pub(crate) mod evaluate;
pub(crate) mod online;
pub(crate) mod source;
pub(crate) mod split;
pub(crate) mod transfer;
