//! semantics §15: sequence consistency and the sequence gate, a check on each
//! single-match decision that reads no score.
//!
//! A robot's queries are a sequence and its database a traverse: when query `j`'s best
//! match `b_j` is right, the best matches of the queries just before it lie on the line
//! it draws through the database (the agreement of
//! [`Line`](crate::input::params::Line), shared with the
//! self-motion labels of §16). The *consistency* of query `j` is the share of its
//! previous `W` queries (the *window*) whose best matches agree, a query missing from the
//! window (before the start of the stream) counting as disagreeing; the gate passes a
//! query whose consistency reaches a fixed *level*. It reads neither a score nor ground
//! truth, so nothing of it is calibrated: the level was chosen by measurement
//! (`docs/sequence.md`), and a traverse that is not a sequence fails safe (nothing
//! agrees, nothing passes).
//!
//! The consistency is causal (it reads no later query) and is computed from the best
//! match and the previous best matches alone ([`SequenceParams::consistency`]), so a
//! batch over a matrix's columns and a stream pushed one query at a time give the same
//! values.

use ndarray::ArrayView2;

use super::{GateSignals, QueryGate};
use crate::error::names::Input;
use crate::error::{Error, Result};
pub(crate) use crate::input::params::SequenceParams;
use crate::input::{Score, validate_scores};
use crate::rules::decisions::{Matching, best_match};

/// The slack of "at least the level" (semantics §3's).
const LEVEL_SLACK: f64 = 1e-12;

impl SequenceParams {
    /// Check that decisions in `matching` mode over a database of `n_db` images can be
    /// gated on their consistency: single matching (the gate keeps or drops a best
    /// match), and a database on which the widest tolerance does not cover every row
    /// (`Line::check_database`: `2 floor(a + b W) + 1 < |DB|`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `gate`.
    pub fn check(&self, matching: Matching, n_db: usize) -> Result<()> {
        if matching == Matching::Multi {
            return Err(Error::param(
                "gate",
                "sequence needs single matching: it gates each query's best match, and multi matching \
                 accepts every database entry at or above the threshold",
            ));
        }
        // Named `gate`, as the other checks of a gate are (and as front ends spell it).
        self.line
            .check_database("sequence", self.window, n_db)
            .map_err(|e| match e {
                Error::InvalidParameter { name, message } => Error::param("gate", format!("{name} {message}")),
                e => e,
            })
    }

    /// How many queries a stream starts with that cannot pass: `ceil(level W)`, the
    /// agreeing previous queries the level needs (4 with the defaults).
    pub fn warm_up(&self) -> usize {
        (self.level * self.window as f64 - LEVEL_SLACK).ceil() as usize
    }

    /// The consistency of a query whose best match is `best`, from the best matches of
    /// the queries before it in the stream, most recent first (`b_{j-1}, b_{j-2}, ...`;
    /// those beyond the window are not read): the share of the window that agrees.
    pub fn consistency(&self, best: usize, previous: impl IntoIterator<Item = usize>) -> f64 {
        let neighbours = previous
            .into_iter()
            .take(self.window)
            .zip(1isize..)
            .map(|(b, d)| (-d, b));
        self.line.agreeing(best, neighbours) as f64 / self.window as f64
    }

    /// Whether a consistency reaches the level (inclusive).
    pub fn passes(&self, consistency: f64) -> bool {
        consistency >= self.level - LEVEL_SLACK
    }

    /// How many queries before a query its consistency reads: the window.
    pub(crate) fn lookback(&self) -> usize {
        self.window
    }
}

/// The sequence gate at its fixed level: nothing of it is calibrated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SequenceGate {
    /// Its parameters; the level is theirs.
    pub(crate) params: SequenceParams,
}

impl QueryGate for SequenceGate {
    fn level(&self) -> f64 {
        self.params.level
    }

    fn passes(&self, query: &GateSignals) -> bool {
        query.consistency.is_none_or(|c| self.params.passes(c))
    }
}

/// The consistency of every query of a stream from its best matches, in the order the
/// queries were decided (`best[j]` is query `j`'s).
pub(crate) fn of_best_matches(params: &SequenceParams, best: &[usize]) -> Vec<f64> {
    (0..best.len())
        .map(|j| params.consistency(best[j], best[..j].iter().rev().copied()))
        .collect()
}

/// The consistency of every column of `s` (|DB| x |Q|), the columns a stream in order
/// (semantics §15): what the sequence gate compares with its level.
///
/// # Errors
/// Empty or non-finite scores, invalid `params` ([`SequenceParams::validate`]) or a
/// database too small for them ([`SequenceParams::check`]).
pub fn sequence_consistency<T: Score>(s: ArrayView2<'_, T>, params: &SequenceParams) -> Result<Vec<f64>> {
    params.validate()?;
    validate_scores(Input::Similarity, s)?;
    params.check(Matching::Single, s.nrows())?;
    let best: Vec<usize> = s.columns().into_iter().map(best_match).collect();
    Ok(of_best_matches(params, &best))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::params::Line;
    use ndarray::Array2;

    /// The consistencies of a stream of best matches, with the defaults.
    fn of(best: &[usize]) -> Vec<f64> {
        of_best_matches(&SequenceParams::default(), best)
    }

    #[test]
    fn a_forward_traverse_passes_from_its_fifth_query() {
        // b_j = 100 + j: every previous query agrees exactly. Query j has min(j, 5) of 5
        // in its window: 0, 0.2, 0.4, 0.6, 0.8, 1, 1, ...
        let c = of(&(100..108).collect::<Vec<_>>());
        assert_eq!(c, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.0, 1.0]);
        let p = SequenceParams::default();
        assert_eq!(p.warm_up(), 4); // ceil(0.8 * 5)
        let passes: Vec<bool> = c.iter().map(|&c| p.passes(c)).collect();
        assert_eq!(passes, [false, false, false, false, true, true, true, true]);
    }

    #[test]
    fn a_stop_passes_two_queries_then_goes_silent() {
        // 100..=105 (queries 0..=5), then the robot stands still at row 105 for queries
        // 6..=10. Queries 5, 6 and 7: every previous query within its tolerance (query 7:
        // d = 1..5 are 105, 105, 104, 103, 102 against 104, 103, 102, 101, 100, each 1 or
        // 2 away, within 2.2, 2.4, 2.6, 2.8, 3): 1.
        // Query 8: d = 1 (105 vs 104), 2 (105 vs 103) agree; d = 3 (105 vs 102: 3 > 2.6),
        // 4 (104 vs 101: 3 > 2.8) do not; d = 5 (103 vs 100: 3 <= 3) does: 0.6.
        // Queries 9 and 10: only d = 1, 2 agree: 0.4.
        let c = of(&[100, 101, 102, 103, 104, 105, 105, 105, 105, 105, 105]);
        assert_eq!(&c[5..], [1.0, 1.0, 1.0, 0.6, 0.4, 0.4]);
    }

    #[test]
    fn a_jump_is_rejected_for_four_queries() {
        // 100..=105, then a jump to 300..=305. Query 6 (300): nothing before agrees (0);
        // query 7 (301): only 300 (0.2); ...; query 10 (304): 300..=303 (0.8) passes.
        let best: Vec<usize> = (100..106).chain(300..306).collect();
        let c = of(&best);
        assert_eq!(&c[6..], [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
    }

    #[test]
    fn a_reverse_traverse_passes_nothing_unless_its_speed_is_minus_one() {
        // b_j = 200 - j: at v = 1 the query d = -k back predicts b_j - k but lies at
        // b_j + k, 2k away: only k = 1 (2 <= 2.2) agrees, 0.2 at most.
        let best: Vec<usize> = (0..10).map(|j| 200 - j).collect();
        assert!(of(&best).iter().all(|&c| c <= 0.2));
        let back = SequenceParams {
            line: Line {
                speed: -1.0,
                ..Line::default()
            },
            ..SequenceParams::default()
        };
        assert_eq!(of_best_matches(&back, &best)[5..], [1.0; 5]);
    }

    #[test]
    fn a_matrix_is_a_stream_of_its_columns() {
        // 20 database images, 7 queries whose best match is row 2 + j, except query 5
        // (row 17). Query 5: d = 1..5 are rows 6, 5, 4, 3, 2, predicted 16, 15, ...: none
        // agrees (0). Query 6 (row 8): d = 1 is row 17 (predicted 7): no; d = 2..5 (rows
        // 6, 5, 4, 3, predicted 6, 5, 4, 3): 4 of 5.
        let best = [2, 3, 4, 5, 6, 17, 8];
        let s = Array2::from_shape_fn((20, 7), |(i, j)| if i == best[j] { 1.0 } else { 0.1 * (i % 3) as f64 });
        let c = sequence_consistency(s.view(), &SequenceParams::default()).unwrap();
        assert_eq!(c, [0.0, 0.2, 0.4, 0.6, 0.8, 0.0, 0.8]);
        // Only the previous best matches are read, one query at a time.
        let p = SequenceParams::default();
        assert_eq!(p.consistency(8, [17, 6, 5, 4, 3, 2, 99]), 0.8);
    }

    #[test]
    fn parameters_matching_and_a_small_database_are_checked() {
        let p = SequenceParams::default();
        let err = |p: SequenceParams| p.validate().unwrap_err().to_string();
        assert_eq!(
            err(SequenceParams { window: 0, ..p }),
            "sequence window must be >= 1, got 0"
        );
        assert_eq!(
            err(SequenceParams { level: 0.0, ..p }),
            "sequence level must be in (0, 1], got 0"
        );
        assert_eq!(
            err(SequenceParams { level: f64::NAN, ..p }),
            "sequence level must be in (0, 1], got NaN"
        );
        assert!(
            p.check(Matching::Multi, 100)
                .unwrap_err()
                .to_string()
                .starts_with("gate sequence needs single matching")
        );
        // W = 5: +-3 rows, 7 of them: |DB| = 7 is too small.
        let s = Array2::<f64>::zeros((7, 3));
        assert!(
            sequence_consistency(s.view(), &p)
                .unwrap_err()
                .to_string()
                .ends_with("it needs |DB| >= 8")
        );
    }
}
