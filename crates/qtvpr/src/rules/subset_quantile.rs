//! semantics §5: a subset threshold expressed as a quantile of the subset's scores.
//!
//! `q = (c - 1) / (n - 1)` with `c` the number of sample scores `<= t`: the exact
//! inverse of the linear-interpolation quantile of section 6. The sample is the union
//! of the subset's columns, whose ranked profiles are already sorted, so `c` is a sum
//! of binary searches and nothing is sorted again.

use crate::input::Score;

/// The quantile of threshold `t` in the union of `columns` (each sorted ascending).
/// Reject-all (`t = inf`) gives 1; a sample of one score gives 0.
pub fn subset_quantile<'a, T: Score>(columns: impl IntoIterator<Item = &'a [T]>, t: f64) -> f64 {
    if t == f64::INFINITY {
        return 1.0;
    }
    let (mut n, mut c) = (0usize, 0usize);
    for col in columns {
        n += col.len();
        c += col.partition_point(|x| x.to_f64() <= t);
    }
    if n <= 1 {
        return 0.0;
    }
    // t is the score of a candidate in the sample, so c >= 1.
    c.saturating_sub(1) as f64 / (n - 1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_scores_at_or_below_the_threshold() {
        // Sample {1, 2, 3} u {0, 4, 5}: n = 6; scores <= 2 are 2, 1, 0 -> c = 3;
        // q = (3 - 1) / (6 - 1) = 0.4. Round trip: ascending [0,1,2,3,4,5], h = 5 * 0.4 = 2 -> 2.
        let cols: [&[f64]; 2] = [&[1.0, 2.0, 3.0], &[0.0, 4.0, 5.0]];
        assert_eq!(subset_quantile(cols, 2.0), 0.4);
        // The maximum: c = 6 -> q = 1. The minimum: c = 1 -> q = 0.
        assert_eq!(subset_quantile(cols, 5.0), 1.0);
        assert_eq!(subset_quantile(cols, 0.0), 0.0);
    }

    #[test]
    fn ties_count_together() {
        // {1, 2, 2}: t = 2 -> c = 3, q = 2 / 2 = 1; t = 1 -> c = 1, q = 0.
        let cols: [&[f32]; 1] = [&[1.0, 2.0, 2.0]];
        assert_eq!(subset_quantile(cols, 2.0), 1.0);
        assert_eq!(subset_quantile(cols, 1.0), 0.0);
    }

    #[test]
    fn reject_all_and_single_score() {
        let cols: [&[f64]; 1] = [&[1.0, 2.0]];
        assert_eq!(subset_quantile(cols, f64::INFINITY), 1.0);
        let one: [&[f64]; 1] = [&[0.7]];
        assert_eq!(subset_quantile(one, 0.7), 0.0);
        // Reject-all wins over n = 1.
        assert_eq!(subset_quantile(one, f64::INFINITY), 1.0);
    }
}
