//! The matrices an [`Error`](crate::Error) can be about.
//!
//! Every error about a matrix carries an [`Input`] in its `what` (and `other`) field,
//! and [`Error::about`](crate::Error::about) returns them, so that a front end maps an
//! error to the argument or file it came from by matching on the enum
//! ([`Error::inputs`](crate::Error::inputs)), never on message text. The enum is
//! exhaustive on purpose: a front end that names every input with one `match` (the
//! Python binding names each by its argument) fails to compile when an input is added
//! and it has not said what to call it.

use std::fmt;

/// A matrix of the core's input, as its errors name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Input {
    /// The one similarity matrix of [`best_threshold`](crate::best_threshold()),
    /// [`counts`](crate::counts()), [`evaluate`](crate::evaluate()), ...
    Similarity,
    /// The calibration similarity of a [`Calibration`](crate::Calibration).
    CalSimilarity,
    /// The deployment similarity of [`Calibration::transfer`](crate::Calibration::transfer).
    DeploymentSimilarity,
    /// Hard ground truth.
    GroundTruth,
    /// Soft ground truth.
    SoftGroundTruth,
    /// The database descriptors of [`cosine_similarity`](crate::cosine_similarity).
    DbDescriptors,
    /// The query descriptors of [`cosine_similarity`](crate::cosine_similarity).
    QueryDescriptors,
    /// The database positions of [`within_radius`](crate::extensions::ground_truth::within_radius).
    DbPositions,
    /// The query positions of [`within_radius`](crate::extensions::ground_truth::within_radius).
    QueryPositions,
}

impl Input {
    /// Every input.
    pub const ALL: [Input; 9] = [
        Input::Similarity,
        Input::CalSimilarity,
        Input::DeploymentSimilarity,
        Input::GroundTruth,
        Input::SoftGroundTruth,
        Input::DbDescriptors,
        Input::QueryDescriptors,
        Input::DbPositions,
        Input::QueryPositions,
    ];

    /// The name messages give it, e.g. `calibration similarity`.
    pub fn as_str(self) -> &'static str {
        match self {
            Input::Similarity => "similarity",
            Input::CalSimilarity => "calibration similarity",
            Input::DeploymentSimilarity => "deployment similarity",
            Input::GroundTruth => "ground truth",
            Input::SoftGroundTruth => "soft ground truth",
            Input::DbDescriptors => "database descriptor matrix",
            Input::QueryDescriptors => "query descriptor matrix",
            Input::DbPositions => "database position matrix",
            Input::QueryPositions => "query position matrix",
        }
    }

    /// What every value of it must be, as [`Error::NotFinite`](crate::Error::NotFinite)
    /// says: similarity matrices hold scores (semantics §1), the extensions' inputs
    /// values.
    pub(crate) fn finite_rule(self) -> &'static str {
        match self {
            Input::Similarity | Input::CalSimilarity | Input::DeploymentSimilarity => "scores must be finite",
            Input::GroundTruth
            | Input::SoftGroundTruth
            | Input::DbDescriptors
            | Input::QueryDescriptors
            | Input::DbPositions
            | Input::QueryPositions => "every value must be finite",
        }
    }
}

impl fmt::Display for Input {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_distinct() {
        let mut names: Vec<&str> = Input::ALL.iter().map(|i| i.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), Input::ALL.len());
        assert_eq!(Input::DbDescriptors.to_string(), "database descriptor matrix");
    }
}
