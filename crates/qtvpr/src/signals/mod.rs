//! What is said of each query beyond its threshold: its margin and the gate on it (§13),
//! the confidence of its decision (§14); and of the whole input, the layout assumed and
//! what the ground truth says of it (the orientation, §1).

pub(crate) mod confidence;
pub(crate) mod margin;
pub(crate) mod orientation;
