//! Whether two queries' best matches lie on one line through the database: the
//! agreement test of semantics §15, written once for the sequence gate (§15, the
//! previous queries of a stream) and the self-motion labels (§16, the neighbours on both
//! sides of a calibration query).
//!
//! A robot that drives the database's route at a known speed ratio `v` (database rows
//! per query) sees query `j + d` at database row `b_j + v d` when query `j`'s best match
//! `b_j` is right. Query `j + d`'s best match agrees when it lies within `a + b |d|` rows
//! of that prediction: `a` for the jitter of one match, `b` for a speed ratio that is only
//! roughly known, whose error grows with the distance. Best matches are row indices,
//! compared in `f64` (exact below 2^53).

use crate::error::{Error, Result};
// The parameters, defined with every request's (`input/params.rs`), so that a request
// below this layer can hold them.
pub(crate) use crate::input::params::Line;

/// The slack that makes a tolerance inclusive whatever the rounding of `a + b |d|`
/// (`2 + 0.2 * 3` is `2.6000000000000001`): far below the spacing of the values
/// compared (integer rows, and `v d` for speeds of a few digits), so it decides ties only.
const SLACK: f64 = 1e-9;

impl Line {
    /// Whether `other`, the best match of the query `d` steps from the query whose best
    /// match is `best` (`d < 0` earlier, `d > 0` later), lies on that query's line:
    /// `|other - (best + v d)| <= a + b |d|`, inclusive.
    pub fn agrees(&self, best: usize, other: usize, d: isize) -> bool {
        let predicted = best as f64 + self.speed * d as f64;
        (other as f64 - predicted).abs() <= self.tolerance + self.drift * d.unsigned_abs() as f64 + SLACK
    }

    /// How many of `neighbours`, each `(d, b)`: the best match `b` of the query `d` steps
    /// away, agree with the query whose best match is `best`.
    pub(crate) fn agreeing(&self, best: usize, neighbours: impl IntoIterator<Item = (isize, usize)>) -> usize {
        neighbours
            .into_iter()
            .filter(|&(d, other)| self.agrees(best, other, d))
            .count()
    }

    /// Check that agreement over neighbours up to `reach` steps away can tell a line from
    /// chance on a database of `n_db` images: the widest tolerance, `a + b reach`, covers
    /// `2 floor(a + b reach) + 1` rows around a prediction, which must be fewer than
    /// |DB| (else every best match near the prediction agrees, wherever it is).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `what` (the rule asking), saying how many
    /// database images it needs.
    pub(crate) fn check_database(&self, what: &'static str, reach: usize, n_db: usize) -> Result<()> {
        let widest = self.tolerance + self.drift * reach as f64;
        let covered = 2.0 * (widest + SLACK).floor() + 1.0;
        if covered >= n_db as f64 {
            return Err(Error::param(
                what,
                format!(
                    "cannot tell a line from chance with |DB| = {n_db}: its widest tolerance, +-{widest} rows {reach} \
                     steps away (sequence tolerance {} and drift {}), covers {covered} rows; it needs |DB| >= {}",
                    self.tolerance,
                    self.drift,
                    covered + 1.0
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_neighbour_agrees_within_the_tolerance_of_its_distance_inclusive() {
        let line = Line::default(); // v = 1, a = 2, b = 0.2
        // best 100, d = -3: predicted 97, tolerance 2 + 0.2 * 3 = 2.6.
        assert!(line.agrees(100, 95, -3)); // |95 - 97| = 2
        assert!(line.agrees(100, 99, -3)); // 2
        assert!(!line.agrees(100, 94, -3)); // 3 > 2.6
        assert!(!line.agrees(100, 100, -3)); // 3: standing still for three queries
        // d = 5: predicted 105, tolerance 2 + 1 = 3: rows 102..=108, both ends inclusive.
        assert!(line.agrees(100, 102, 5) && line.agrees(100, 108, 5));
        assert!(!line.agrees(100, 101, 5) && !line.agrees(100, 109, 5));
        // Near row 0 the prediction may be negative: best 1, d = -3 predicts -2; row 0 is
        // 2 away.
        assert!(line.agrees(1, 0, -3));
        // v = 2: best 100, d = -2 predicts 96 (tolerance 2.4: 93.6..=98.4).
        let fast = Line { speed: 2.0, ..line };
        assert!(fast.agrees(100, 96, -2) && fast.agrees(100, 94, -2) && !fast.agrees(100, 99, -2));
        // v = -1, the route driven backwards: d = -1 predicts 101.
        let back = Line { speed: -1.0, ..line };
        assert!(back.agrees(100, 101, -1) && !back.agrees(100, 96, -1));
    }

    #[test]
    fn rounding_never_decides_a_tie() {
        // a = 0.9, b = 0.7, d = 3: 0.9 + 2.1 = 3 exactly, but in f64 0.7 * 3 =
        // 2.0999999999999996 and the sum 2.9999999999999996. With v = 0 a neighbour 3
        // rows away is exactly on the bound, and agrees.
        let line = Line {
            speed: 0.0,
            tolerance: 0.9,
            drift: 0.7,
        };
        assert!(line.tolerance + line.drift * 3.0 < 3.0);
        assert!(line.agrees(10, 13, 3) && line.agrees(10, 7, -3));
        assert!(!line.agrees(10, 14, 3));
    }

    #[test]
    fn agreeing_counts_the_neighbours_that_agree() {
        let line = Line::default();
        // Best match 14 and the previous four, most recent first: 40 (d = -1, predicted
        // 13): no; 12, 11, 10 (d = -2, -3, -4): on the line.
        assert_eq!(line.agreeing(14, [(-1, 40), (-2, 12), (-3, 11), (-4, 10)]), 3);
        // Best match 12 and two neighbours on each side: 10, 11 and 14 agree, 40 does not.
        assert_eq!(line.agreeing(12, [(-2, 10), (-1, 11), (1, 40), (2, 14)]), 3);
        assert_eq!(line.agreeing(12, []), 0);
    }

    #[test]
    fn parameters_and_a_database_too_small_for_the_tolerance_are_errors() {
        let err = |line: Line| line.validate().unwrap_err().to_string();
        let line = Line::default();
        assert_eq!(
            err(Line {
                speed: f64::NAN,
                ..line
            }),
            "sequence speed must be finite, got NaN"
        );
        assert_eq!(
            err(Line {
                tolerance: -1.0,
                ..line
            }),
            "sequence tolerance must be finite and >= 0, got -1"
        );
        assert_eq!(
            err(Line {
                drift: f64::INFINITY,
                ..line
            }),
            "sequence drift must be finite and >= 0, got inf"
        );
        // Reach 5: 2 + 0.2 * 5 = 3 rows either side, 2 * 3 + 1 = 7 rows: 7 images are too
        // few, 8 enough.
        assert_eq!(
            line.check_database("gate", 5, 7).unwrap_err().to_string(),
            "gate cannot tell a line from chance with |DB| = 7: its widest tolerance, +-3 rows 5 steps away \
             (sequence tolerance 2 and drift 0.2), covers 7 rows; it needs |DB| >= 8"
        );
        line.check_database("gate", 5, 8).unwrap();
    }
}
