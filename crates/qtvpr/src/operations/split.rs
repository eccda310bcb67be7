//! One set of queries split in query order: the first calibrate, the rest are
//! thresholded.
//!
//! This is the calibration rule of the evaluation protocol (semantics §8.1:
//! `floor(f |Q|)` queries for a fraction `f`, or a count), applied by every front end
//! that takes one similarity matrix (or one set of query descriptors) and ground truth
//! for every query in place of a calibration traverse and a deployment traverse:
//! `qtvpr-cli threshold --similarity` and `calibrate --db-descriptors` with
//! `--cal-queries` / `--cal-fraction`, and Python's `cal_queries=` / `cal_fraction=`.
//! [`QuerySplit`] holds the two ranges of queries, checks and cuts the ground truth of
//! the calibration queries, and gives an error of the deployment queries' transfer its
//! position in the whole matrix, so that no front end counts columns itself.

use std::ops::Range;

use ndarray::s;

use crate::error::{Error, Result};
use crate::input::GroundTruth;
use crate::input::params::{Options, Params};
use crate::operations::calibration::Calibration;
use crate::operations::evaluate::Split;
use crate::operations::source::ScoreSource;
use crate::operations::transfer::Transfer;
use crate::rules::decisions::Matching;

/// The queries of one |DB| x |Q| similarity matrix (or of a range of query
/// descriptors), split: the first [`QuerySplit::calibration`] calibrate and the rest,
/// [`QuerySplit::deployment`], are thresholded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QuerySplit {
    /// |DB|.
    database_size: usize,
    /// The queries split: `0..|Q|` for a matrix, the selected range for descriptors.
    queries: Range<usize>,
    /// How many of the first queries calibrate, between 1 and `|queries| - 1`.
    calibration_queries: usize,
}

impl QuerySplit {
    /// Split the |Q| queries of a similarity matrix of shape (|DB|, |Q|) as `split`
    /// says ([`Split::calibration_size`]).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a fraction outside (0, 1) or a count of 0;
    /// [`Error::CalibrationSize`] when no query is left to calibrate or to threshold.
    pub fn new(split: Split, (database_size, queries): (usize, usize)) -> Result<Self> {
        Self::of_range(split, database_size, 0..queries)
    }

    /// Split the queries `queries` (e.g. a range of query descriptors) of a similarity
    /// with `database_size` rows: the first of them calibrate. Ranges count in the
    /// same indices as `queries`.
    ///
    /// # Errors
    /// As [`QuerySplit::new`].
    pub fn of_range(split: Split, database_size: usize, queries: Range<usize>) -> Result<Self> {
        let calibration_queries = split.calibration_size_of(Some(database_size), queries.len())?;
        Ok(Self {
            database_size,
            queries,
            calibration_queries,
        })
    }

    /// The calibration queries, the first ones.
    pub fn calibration(&self) -> Range<usize> {
        self.queries.start..self.queries.start + self.calibration_queries
    }

    /// The deployment queries, every one after the calibration queries.
    pub fn deployment(&self) -> Range<usize> {
        self.queries.start + self.calibration_queries..self.queries.end
    }

    /// The shape (|DB|, |Qcal|) of the calibration similarity (and ground truth).
    pub fn calibration_shape(&self) -> (usize, usize) {
        (self.database_size, self.calibration_queries)
    }

    /// The shape (|DB|, |Q|) of the similarity split, which its ground truth must have.
    pub fn shape(&self) -> (usize, usize) {
        (self.database_size, self.queries.len())
    }

    /// The ground truth of the calibration queries: the first columns of `gt`, which
    /// labels every query split (the deployment queries' labels are not used).
    ///
    /// # Errors
    /// [`Error::SplitTruthShape`] when `gt` is not of [`QuerySplit::shape`].
    pub fn calibration_truth(&self, gt: &GroundTruth) -> Result<GroundTruth> {
        if gt.dim() != self.shape() {
            return Err(Error::SplitTruthShape {
                shape: gt.dim(),
                similarity_shape: self.shape(),
                calibration: self.calibration_queries,
            });
        }
        Ok(
            GroundTruth::from_truth(gt.view().slice(s![.., ..self.calibration_queries]).to_owned())
                .with_record(gt.record().cloned()),
        )
    }

    /// Check that a calibration of `calibration_queries` queries (a calibration file's)
    /// can be that of this split's calibration queries, as when a stream of a recorded
    /// traverse skips the queries its calibration was made on (`qtvpr-cli stream --val
    /// S.npy --cal-queries N` after `calibrate --similarity S.npy --cal-queries N`):
    /// skipping fewer would decide queries that calibrated, more would drop queries.
    ///
    /// # Errors
    /// [`Error::Protocol`] when the counts differ, naming both.
    pub fn check_calibration(&self, calibration_queries: usize) -> Result<()> {
        if calibration_queries == self.calibration_queries {
            return Ok(());
        }
        Err(Error::Protocol(format!(
            "the split makes the first {} queries the calibration queries, but the calibration holds {}: \
             skip the queries it was calibrated on",
            self.calibration_queries, calibration_queries
        )))
    }

    /// An error of the transfer of the deployment columns alone (a view of
    /// [`QuerySplit::deployment`], whose columns count from 0), with its position in
    /// the columns split: a non-finite score's column moves past the calibration
    /// queries. Other errors are returned unchanged.
    #[must_use]
    pub fn deployment_error(&self, err: Error) -> Error {
        err.shifted(self.calibration_queries)
    }

    /// The transfer within the queries split: calibrate on the calibration queries of
    /// `scores` (a matrix, or descriptors, of the queries split) with `gt`, their ground
    /// truth ([`QuerySplit::calibration_truth`], or made for them alone), and transfer
    /// to the deployment queries with `options`. The one place front ends that take one
    /// set of queries do so: `qtvpr-cli threshold --similarity` (or descriptors) with
    /// `--cal-queries`, and Python's `quantile_transfer(cal_queries=...)`.
    ///
    /// The calibration keeps neither the scores nor the ground truth
    /// ([`Calibration::for_transfer`]); it is returned with the transfer, for what a
    /// report says of it. The queries split are one traverse, one stream (semantics
    /// §15): the deployment queries' decisions look back into the calibration queries
    /// (the sequence gate's consistency reads their best matches, never their labels).
    ///
    /// # Errors
    /// [`SplitError::Calibration`] for the calibration's input (its similarity, its
    /// ground truth); [`SplitError::Deployment`] for the transfer's, a position in the
    /// columns split ([`QuerySplit::deployment_error`]).
    pub fn transfer<'s, 'd: 's, 'p>(
        &self,
        scores: impl Into<ScoreSource<'s, 'd>>,
        gt: GroundTruth,
        matching: Matching,
        options: impl Into<Options<'p, Params>>,
    ) -> Result<(Calibration, Transfer), SplitError> {
        let scores = scores.into();
        let cal = Calibration::for_transfer(scores.columns(self.calibration()), gt, matching)
            .map_err(SplitError::Calibration)?;
        let options = options.into();
        let p = &options.params;
        let before = cal.lookback(p.gate, &p.sequence_gate).min(self.calibration_queries);
        let (dep, first) = (self.deployment(), self.queries.start);
        // Errors name columns of the columns given, which start `before` columns into
        // the calibration queries.
        let out = cal
            .transfer_after(
                scores.columns(dep.start - before - first..dep.end - first),
                options,
                before,
            )
            .map_err(|e| SplitError::Deployment(e.shifted(self.calibration_queries - before)))?;
        Ok((cal, out))
    }
}

/// An error of [`QuerySplit::transfer`], told by the queries it is about (a front end
/// names the inputs of each differently).
#[derive(Debug, Clone, PartialEq)]
pub enum SplitError {
    /// Calibrating on the calibration queries failed: their similarity, or their ground
    /// truth.
    Calibration(Error),
    /// The transfer to the deployment queries failed: their scores (positions in the
    /// columns split) or the transfer's parameters.
    Deployment(Error),
}

impl From<SplitError> for Error {
    fn from(err: SplitError) -> Self {
        match err {
            SplitError::Calibration(e) | SplitError::Deployment(e) => e,
        }
    }
}

#[cfg(test)]
mod tests {
    use ndarray::{Array2, array};

    use super::*;
    use crate::error::names::Input;
    use crate::input::Truth;

    #[test]
    fn the_first_queries_calibrate() {
        // 7 queries, a count of 2: 0..2 calibrate, 2..7 are thresholded.
        let split = QuerySplit::new(Split::Count(2), (3, 7)).unwrap();
        assert_eq!((split.calibration(), split.deployment()), (0..2, 2..7));
        assert_eq!(split.calibration_shape(), (3, 2));
        // floor(0.5 * 7) = 3.
        let split = QuerySplit::new(Split::Fraction(0.5), (3, 7)).unwrap();
        assert_eq!((split.calibration(), split.deployment()), (0..3, 3..7));
        // Descriptor queries 10..20, a fraction of 0.25: floor(2.5) = 2 of them.
        let split = QuerySplit::of_range(Split::Fraction(0.25), 3, 10..20).unwrap();
        assert_eq!((split.calibration(), split.deployment()), (10..12, 12..20));
        assert_eq!(split.shape(), (3, 10));
    }

    #[test]
    fn bad_splits_say_why() {
        let message = |split, n_q| QuerySplit::new(split, (3, n_q)).unwrap_err().to_string();
        assert_eq!(message(Split::Count(0), 6), "cal queries must be >= 1, got 0");
        assert_eq!(
            message(Split::Count(6), 6),
            "the calibration set must have between 1 and 5 of the 6 queries, got 6"
        );
        assert_eq!(
            message(Split::Count(9), 6),
            "the calibration set must have between 1 and 5 of the 6 queries, got 9"
        );
        assert_eq!(
            message(Split::Fraction(0.0), 6),
            "cal fraction must be in (0, 1), got 0"
        );
        assert_eq!(
            message(Split::Fraction(1.5), 6),
            "cal fraction must be in (0, 1), got 1.5"
        );
        // floor(0.1 * 6) = 0: no calibration query.
        assert_eq!(
            message(Split::Fraction(0.1), 6),
            "the calibration set must have between 1 and 5 of the 6 queries, got 0"
        );
    }

    #[test]
    fn ground_truth_labels_every_query_and_the_first_columns_are_kept() {
        let split = QuerySplit::new(Split::Count(2), (2, 4)).unwrap();
        let gt = GroundTruth::new(array![[true, false, true, false], [false, true, false, false]].view())
            .unwrap()
            .with_soft(array![[true, false, true, false], [true, true, false, false]].view())
            .unwrap();
        let cal = split.calibration_truth(&gt).unwrap();
        assert_eq!(
            cal.view(),
            array![[Truth::True, Truth::False], [Truth::Ignored, Truth::True]]
        );
        // Ground truth of the calibration queries alone is the wrong shape.
        let short = GroundTruth::new(Array2::from_elem((2, 2), false).view()).unwrap();
        let err = split.calibration_truth(&short).unwrap_err();
        assert_eq!(err.about(), [Input::GroundTruth]);
        assert_eq!(
            err.to_string(),
            "ground truth shape 2x2 does not match similarity shape 2x4; the ground truth of a split \
             labels every query, of which the first 2 calibrate"
        );
        assert_eq!(
            err.transposed().to_string(),
            "ground truth shape 2x2 does not match similarity shape 4x2; the ground truth of a split \
             labels every query, of which the first 2 calibrate"
        );
    }

    #[test]
    fn a_calibration_of_the_split_has_its_number_of_queries() {
        // floor(0.1 * 111) = 11 calibration queries: a calibration of 11 is theirs.
        let split = QuerySplit::new(Split::Fraction(0.1), (111, 111)).unwrap();
        assert_eq!(split.check_calibration(11), Ok(()));
        assert_eq!(
            split.check_calibration(10).unwrap_err().to_string(),
            "the split makes the first 11 queries the calibration queries, but the calibration holds 10: skip \
             the queries it was calibrated on"
        );
    }

    #[test]
    fn deployment_errors_count_columns_of_the_whole_matrix() {
        let split = QuerySplit::new(Split::Count(3), (2, 7)).unwrap();
        let err = Error::NotFinite {
            what: Input::DeploymentSimilarity,
            row: 1,
            col: 2,
            value: f64::NAN,
        };
        // Column 2 of the deployment view is column 3 + 2 = 5 of the matrix.
        assert_eq!(
            split.deployment_error(err).to_string(),
            "deployment similarity contains NaN at row 1, column 5; scores must be finite"
        );
        let err = Error::param("k", "must be >= 1, got 0");
        assert_eq!(split.deployment_error(err.clone()), err);
    }

    #[test]
    fn a_split_transfer_is_the_transfer_of_its_columns_and_says_which_failed() {
        // The case of transfer.rs's tests as one matrix: c0, c1 calibrate (hard GT rows
        // 0 and 2, 0 and 1), v0 and v1 are thresholded.
        let s = array![[3.0, 1.0, 2.0, 2.0], [1.0, 4.0, 6.0, 5.0], [2.0, 1.0, 4.0, 2.0]];
        let gt = GroundTruth::new(array![[1, 1, 0, 0], [0, 1, 0, 0], [1, 0, 0, 0]].view()).unwrap();
        let split = QuerySplit::new(Split::Count(2), s.dim()).unwrap();
        let params = Params {
            k: 1,
            ..Params::default()
        };
        let gt_cal = split.calibration_truth(&gt).unwrap();
        let (cal, out) = split
            .transfer(s.view(), gt_cal.clone(), Matching::Multi, &params)
            .unwrap();
        let alone = Calibration::new(s.slice(s![.., ..2]), &gt_cal, Matching::Multi).unwrap();
        assert_eq!(out, alone.transfer(s.slice(s![.., 2..]), &params).unwrap());
        // 2 queries calibrated, kept nothing to save.
        assert_eq!((cal.len(), cal.scores()), (2, None));
        // A bad calibration score, then a bad deployment score (column 3 of the matrix).
        let mut bad = s.clone();
        bad[[1, 0]] = f64::NAN;
        let err = split.transfer(bad.view(), gt_cal.clone(), Matching::Multi, &params);
        assert!(matches!(
            err,
            Err(SplitError::Calibration(Error::NotFinite { col: 0, .. }))
        ));
        let mut bad = s.clone();
        bad[[1, 3]] = f64::INFINITY;
        let err = split.transfer(bad.view(), gt_cal, Matching::Multi, &params);
        assert!(matches!(
            err,
            Err(SplitError::Deployment(Error::NotFinite { col: 3, .. }))
        ));
    }
}
