//! Beyond the paper, and not sections of the semantics: the similarity and ground-truth
//! matrices the method takes, made from what users have (descriptors, positions,
//! `@utm_east@utm_north@` image names, frame-aligned traverses), and sequence matching.

pub(crate) mod ground_truth;
pub(crate) mod image_names;
mod kd_tree;
pub(crate) mod sequence;
pub(crate) mod similarity;
