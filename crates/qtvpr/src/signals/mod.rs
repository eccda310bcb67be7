//! What is said of each query beyond its decision: the confidence that its best match
//! is right (semantics §14).

pub(crate) mod confidence;
pub(crate) mod self_motion;
