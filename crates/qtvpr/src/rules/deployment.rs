//! semantics §6: one threshold per batch (segment) of deployment queries.
//!
//! The batch quantile is the lower weighted median of its queries' quantiles; the
//! threshold is that quantile of all the batch's raw scores, by linear interpolation.
//! The two order statistics the interpolation needs are found by a radix select on the
//! scores where they lie (four 16-bit passes over order-preserving integer keys), so a
//! batch of any size is read a few times but never copied or sorted.

use std::ops::Range;

use ndarray::ArrayView2;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::input::Score;
use crate::platform::threads;

/// Consecutive runs of `size` queries over `n` (the last one shorter if need be);
/// `None` is one batch of all `n`.
///
/// # Errors
/// A size of 0 or larger than `n`.
pub fn segments(n: usize, size: Option<usize>) -> Result<Vec<Range<usize>>> {
    let size = size.unwrap_or(n);
    if size == 0 || size > n {
        return Err(Error::param(
            "segment size",
            format!("must be between 1 and the number of deployment queries ({n}), got {size}"),
        ));
    }
    Ok((0..n).step_by(size).map(|s| s..(s + size).min(n)).collect())
}

/// The lower weighted median: sort by `q` (stable), take the first `q` whose cumulative
/// weight reaches half the total (less 1e-12). A zero total weight counts every weight
/// as 1. `q` must not be empty.
pub fn weighted_median(q: &[f64], w: &[f64]) -> f64 {
    assert!(
        !q.is_empty() && q.len() == w.len(),
        "weighted_median needs equal, non-empty slices"
    );
    let total: f64 = w.iter().sum();
    let weight = |i: usize| if total > 0.0 { w[i] } else { 1.0 };
    let total = if total > 0.0 { total } else { q.len() as f64 };
    let mut order: Vec<usize> = (0..q.len()).collect();
    order.sort_by(|&a, &b| q[a].total_cmp(&q[b]));
    let mut cumulative = 0.0;
    for &i in &order {
        cumulative += weight(i);
        if cumulative >= 0.5 * total - 1e-12 {
            return q[i];
        }
    }
    q[order[order.len() - 1]]
}

/// The threshold for quantile `q` of every score in `s` (semantics §6.2): linear
/// interpolation between order statistics, and for `q >= 1` the next `f64` above the
/// maximum (finite, accepts nothing).
pub fn deployment_threshold<T: Score>(s: ArrayView2<'_, T>, q: f64) -> f64 {
    interpolate(
        s.len(),
        q,
        || s.iter().map(|v| v.to_f64()).fold(f64::NEG_INFINITY, f64::max),
        |lo, need_hi| {
            if s.len() <= COPY_LIMIT {
                select_copied(s, lo)
            } else {
                select_in_place(s, lo, need_hi)
            }
        },
    )
}

/// [`deployment_threshold`] of scores whose every column is already sorted ascending (in
/// total order), as the transfer has them at hand: each order statistic is found by a
/// bisection on order-preserving keys that counts by binary search in every column, so
/// the scores are neither copied nor scanned.
pub(crate) fn sorted_columns_threshold<T: Score>(sorted: ArrayView2<'_, T>, q: f64) -> f64 {
    let columns: Vec<&[T]> = sorted
        .columns()
        .into_iter()
        .map(|c| c.to_slice().expect("sorted columns are contiguous"))
        .collect();
    let key = |v: &T| to_key(v.to_f64());
    // How many scores have a key at most `k`.
    let at_most = |k: u64| -> usize { columns.iter().map(|c| c.partition_point(|v| key(v) <= k)).sum() };
    interpolate(
        sorted.len(),
        q,
        || {
            columns
                .iter()
                .map(|c| c[c.len() - 1].to_f64())
                .fold(f64::NEG_INFINITY, f64::max)
        },
        |lo, need_hi| {
            // The smallest key with more than `lo` scores at or below it. It lies between
            // the columns' order statistics near rank lo / m (the m columns of a matrix):
            // below L = min_j c_j[lo / m], each column has at most lo / m scores, so all
            // of them at most lo; at U = max_j c_j[ceil((lo + 1) / m) - 1], each column
            // has at least ceil((lo + 1) / m), so all of them more than lo. Bisecting
            // between their keys takes a few steps where 0..2^64 takes 64.
            let m = columns.len();
            let (mut low, mut high) = (
                columns.iter().map(|c| key(&c[lo / m])).min().expect("columns"),
                columns
                    .iter()
                    .map(|c| key(&c[(lo + 1).div_ceil(m) - 1]))
                    .max()
                    .expect("columns"),
            );
            while low < high {
                let mid = low + (high - low) / 2;
                if at_most(mid) > lo { high = mid } else { low = mid + 1 }
            }
            let x_lo = from_key(low);
            if !need_hi || at_most(low) > lo + 1 {
                return (x_lo, x_lo);
            }
            let above = columns
                .iter()
                .filter_map(|c| c.get(c.partition_point(|v| key(v) <= low)))
                .map(key)
                .min();
            (x_lo, above.map_or(x_lo, from_key))
        },
    )
}

/// The semantics §6.2 threshold for quantile `q` of `n` scores, given their maximum
/// and a selection of the `lo`-th and `(lo + 1)`-th smallest (the second only needed
/// when the flag says so).
fn interpolate(n: usize, q: f64, max: impl FnOnce() -> f64, select: impl FnOnce(usize, bool) -> (f64, f64)) -> f64 {
    assert!(n > 0, "deployment_threshold needs scores");
    if q >= 1.0 {
        return max().next_up();
    }
    let h = (n - 1) as f64 * q.max(0.0);
    let lo = h.floor() as usize;
    let frac = h - lo as f64;
    let (x_lo, x_hi) = select(lo, frac > 0.0);
    if frac == 0.0 {
        return x_lo;
    }
    let t = x_lo + frac * (x_hi - x_lo);
    if t.is_finite() {
        t
    } else {
        // x_hi - x_lo overflowed (scores near +-f64::MAX): the same point, as a convex
        // combination, which cannot overflow; clamped against rounding.
        ((1.0 - frac) * x_lo + frac * x_hi).clamp(x_lo, x_hi)
    }
}

/// Batches up to this many scores are copied and selected (fast, 8 bytes a score);
/// larger ones are selected in place by radix passes (no copy).
const COPY_LIMIT: usize = 1 << 22;

/// The `lo`-th and `(lo + 1)`-th smallest scores (the latter clamped to the last), with
/// both zeros read as +0 like the radix path.
fn select_copied<T: Score>(s: ArrayView2<'_, T>, lo: usize) -> (f64, f64) {
    let mut v: Vec<f64> = s.iter().map(|x| x.to_f64() + 0.0).collect();
    let (_, &mut x_lo, above) = v.select_nth_unstable_by(lo, f64::total_cmp);
    (x_lo, above.iter().copied().reduce(f64::min).unwrap_or(x_lo))
}

/// As [`select_copied`], by radix select on the scores where they lie; the second
/// order statistic costs one more pass and is only found if `need_hi`.
fn select_in_place<T: Score>(s: ArrayView2<'_, T>, lo: usize, need_hi: bool) -> (f64, f64) {
    let key = select_key(s, lo);
    let x_lo = from_key(key);
    let x_hi = if need_hi && lo + 1 < s.len() {
        next_value(s, key, lo)
    } else {
        x_lo
    };
    (x_lo, x_hi)
}

/// Order-preserving map from `f64` to `u64` (both zeros map to the key of +0).
fn to_key(x: f64) -> u64 {
    let bits = (x + 0.0).to_bits();
    if bits >> 63 == 1 { !bits } else { bits | (1 << 63) }
}

fn from_key(k: u64) -> f64 {
    f64::from_bits(if k >> 63 == 1 { k & !(1 << 63) } else { !k })
}

const DIGIT: u32 = 16;

/// The key of the `rank`-th smallest (0-based) score of `s`, by most-significant-digit
/// radix select: each pass histograms one 16-bit digit of the keys that share the
/// digits fixed so far.
fn select_key<T: Score>(s: ArrayView2<'_, T>, mut rank: usize) -> u64 {
    threads::install(|| {
        let mut prefix = 0u64;
        for pass in 0..(64 / DIGIT) {
            let shift = 64 - DIGIT * (pass + 1);
            let fixed = if pass == 0 { 0 } else { u64::MAX << (shift + DIGIT) };
            let hist = (0..s.ncols())
                .into_par_iter()
                .fold(
                    || vec![0usize; 1 << DIGIT],
                    |mut h, j| {
                        for v in s.column(j) {
                            let k = to_key(v.to_f64());
                            if k & fixed == prefix {
                                h[((k >> shift) & ((1 << DIGIT) - 1)) as usize] += 1;
                            }
                        }
                        h
                    },
                )
                .reduce(
                    || vec![0usize; 1 << DIGIT],
                    |mut a, b| {
                        a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                        a
                    },
                );
            for (digit, &count) in hist.iter().enumerate() {
                if rank < count {
                    prefix |= (digit as u64) << shift;
                    break;
                }
                rank -= count;
            }
        }
        prefix
    })
}

/// The `(rank + 1)`-th smallest score, given the key of the `rank`-th: that same value
/// if it occurs more than `rank + 1` times from the bottom, else the smallest larger one.
fn next_value<T: Score>(s: ArrayView2<'_, T>, key: u64, rank: usize) -> f64 {
    threads::install(|| {
        let (at_most, above) = (0..s.ncols())
            .into_par_iter()
            .map(|j| {
                s.column(j).iter().fold((0usize, u64::MAX), |(le, above), v| {
                    let k = to_key(v.to_f64());
                    if k <= key { (le + 1, above) } else { (le, above.min(k)) }
                })
            })
            .reduce(|| (0, u64::MAX), |a, b| (a.0 + b.0, a.1.min(b.1)));
        if at_most > rank + 1 {
            from_key(key)
        } else {
            from_key(above)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, ShapeBuilder, array};

    #[test]
    fn segments_keep_the_remainder() {
        assert_eq!(segments(10, Some(4)).unwrap(), vec![0..4, 4..8, 8..10]);
        assert_eq!(segments(10, None).unwrap(), vec![0..10]);
        assert_eq!(segments(3, Some(3)).unwrap(), vec![0..3]);
        assert!(segments(10, Some(0)).is_err());
        let err = segments(10, Some(11)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "segment size must be between 1 and the number of deployment queries (10), got 11"
        );
    }

    #[test]
    fn lower_weighted_median() {
        // Sorted: 0.1 (w 1), 0.2 (w 2), 0.3 (w 1); total 4, half 2: cumulative 1, 3 -> 0.2.
        assert_eq!(weighted_median(&[0.3, 0.1, 0.2], &[1.0, 1.0, 2.0]), 0.2);
        // Even split: 0.1 (1), 0.2 (1): cumulative 1 >= 1 -> the lower, 0.1.
        assert_eq!(weighted_median(&[0.2, 0.1], &[1.0, 1.0]), 0.1);
        // Heavy top: 0.1 (1), 0.9 (5): total 6, half 3: 1 < 3, 6 >= 3 -> 0.9.
        assert_eq!(weighted_median(&[0.9, 0.1], &[5.0, 1.0]), 0.9);
        // Zero total weight: all weights 1; sorted 0.1, 0.5, 0.9; half 1.5 -> 0.5.
        assert_eq!(weighted_median(&[0.5, 0.1, 0.9], &[0.0, 0.0, 0.0]), 0.5);
        // Zero weights are skipped over: 0.1 (0), 0.4 (1), 0.8 (1): half 1 -> 0.4.
        assert_eq!(weighted_median(&[0.1, 0.4, 0.8], &[0.0, 1.0, 1.0]), 0.4);
    }

    #[test]
    fn linear_interpolation() {
        // Scores {1, 3, 2, 4} -> ascending [1, 2, 3, 4], N = 4.
        let s = array![[1.0, 3.0], [2.0, 4.0]];
        // q = 0.5: h = 1.5, lo = 1 -> 2 + 0.5 * (3 - 2) = 2.5.
        assert_eq!(deployment_threshold(s.view(), 0.5), 2.5);
        // q = 0 -> 1; q = 1/3: h = 1 -> 2.
        assert_eq!(deployment_threshold(s.view(), 0.0), 1.0);
        assert_eq!(deployment_threshold(s.view(), 1.0 / 3.0), 2.0);
        // q = 1: reject-all, the next f64 above the maximum 4.
        assert_eq!(deployment_threshold(s.view(), 1.0), 4.0f64.next_up());
        // Fortran / transposed views read the same set.
        assert_eq!(deployment_threshold(s.t(), 0.5), 2.5);
    }

    #[test]
    fn interpolation_with_ties_negatives_and_zeros() {
        // [1, 1, 1, 2]: q = 0.5 -> h = 1.5 -> 1 + 0.5 * 0 = 1; q = 0.9 -> h = 2.7 -> 1 + 0.7 * 1 = 1.7.
        let s = array![[1.0f32, 1.0], [1.0, 2.0]];
        assert_eq!(deployment_threshold(s.view(), 0.5), 1.0);
        assert!((deployment_threshold(s.view(), 0.9) - 1.7).abs() < 1e-15);
        // [-1.5, -0.0, 0.0, 2.0]: q = 0.25 -> h = 0.75 -> -1.5 + 0.75 * 1.5 = -0.375;
        // q = 0.5 -> h = 1.5 -> 0 + 0.5 * 0 = 0.
        let s = array![[-1.5, -0.0], [0.0, 2.0]];
        assert_eq!(deployment_threshold(s.view(), 0.25), -0.375);
        assert_eq!(deployment_threshold(s.view(), 0.5), 0.0);
        // A single score: any q < 1 gives it back.
        assert_eq!(deployment_threshold(array![[0.3]].view(), 0.7), 0.3);
    }

    #[test]
    fn sorted_columns_give_the_same_threshold() {
        // Scores with repeats, both signs and both zeros; every column sorted ascending.
        // Shapes with one row, one column, more columns than rows and the reverse, so
        // that the bisection's first bracket (the columns' order statistics near rank
        // lo / m) is tried at every rank of each: q on a grid finer than 1 / (n - 1).
        let mut x = 99u64;
        for shape in [(11, 5), (1, 7), (7, 1), (3, 20), (40, 3), (2, 2)] {
            let mut s = Array2::from_shape_fn(shape.f(), |_| {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                match (x >> 40) % 9 {
                    0 => -0.0,
                    1 => 0.0,
                    r => r as f64 / 3.0 - 1.5,
                }
            });
            let unsorted = s.clone();
            for mut c in s.columns_mut() {
                c.as_slice_mut().unwrap().sort_by(f64::total_cmp);
            }
            for q in (0..=400).map(|i| i as f64 / 400.0).chain([0.123, 0.999, 1.5, -0.2]) {
                let (a, b) = (
                    sorted_columns_threshold(s.view(), q),
                    deployment_threshold(unsorted.view(), q),
                );
                assert_eq!(a.to_bits(), b.to_bits(), "{shape:?} q = {q}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn both_selections_match_a_sort() {
        // Pseudo-random scores (a fixed LCG) with many repeats and both signs.
        let mut x = 12345u64;
        let s = Array2::from_shape_fn((13, 7), |_| {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 40) % 50) as f64 / 7.0 - 3.0
        });
        let mut sorted: Vec<f64> = s.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        for rank in 0..sorted.len() {
            assert_eq!(from_key(select_key(s.view(), rank)), sorted[rank], "rank {rank}");
            if rank + 1 < sorted.len() {
                assert_eq!(
                    next_value(s.view(), to_key(sorted[rank]), rank),
                    sorted[rank + 1],
                    "rank {rank}"
                );
            }
        }
    }
}
