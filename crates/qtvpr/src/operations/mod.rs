//! What a user runs: a batch of deployment queries ([`transfer`]: §4-§6 together), one
//! query at a time over a causal window ([`online`]: §11), and the paper's protocol
//! with every method ([`evaluate`](mod@evaluate): §8); the [`calibration`] all of them
//! read, what they read of the deployment queries, a matrix or descriptors ([`source`],
//! and a chunk at a time, [`chunks`]), and one matrix split into calibration and
//! deployment queries ([`split`]: §8.1).

pub(crate) mod calibration;
pub(crate) mod chunks;
pub(crate) mod evaluate;
pub(crate) mod online;
pub(crate) mod source;
pub(crate) mod split;
pub(crate) mod transfer;
