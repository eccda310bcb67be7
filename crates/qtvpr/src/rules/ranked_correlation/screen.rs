//! The exact screen of semantics §4: a deployment query's neighbours found reading
//! about `k` calibration profiles.
//!
//! A deployment query needs the `f64` correlations of its `k` neighbours (their mean is
//! its weight) and of no other calibration query. `Screen` finds them reading about
//! `k` calibration profiles in full, with the same neighbours and weight, bit for bit,
//! as computing every correlation in `f64` and ranking them all ([`top_k`]):
//!
//! 1. **Blocks.** The rank axis `0..|DB|` is cut into at most 64 blocks (`BLOCKS`), with
//!    edges fixed from the calibration alone (*Edges* below). A standardised profile `x`
//!    is summarised on each block `b` of `n` ranks (`x_b`, its values there) by four
//!    numbers, with `1_b` the block's unit constant vector and `r_b` its unit centred
//!    ramp (`r_t` proportional to `t - (n - 1) / 2`, `t = 0..n`; none when `n = 1`):
//!    - `P = x_b . 1_b = sum(x_b) / sqrt(n)`,
//!    - `a = x_b . r_b`,
//!    - `e = |x_b - P 1_b - a r_b|`, what the constant and the ramp leave,
//!    - `s = |x_b - P 1_b|`, the centred block's norm (`s^2 = a^2 + e^2`).
//!
//!    A calibration keeps these `4 B` numbers per profile, not a screen of |DB|.
//! 2. **Bounds.** For a calibration profile `p` and a deployment profile `u` (primed),
//!    each block's share of `p . u` is `P P' + d . d'`, with `d = p_b - P 1_b` and `d'`
//!    the centred blocks, and:
//!    - `d . d' >= 0`: both profiles are non-decreasing (sorted, and standardising is an
//!      increasing affine map; rounding is monotone, so the computed `f64` profiles are
//!      non-decreasing too), and by Chebyshev's sum inequality two similarly ordered
//!      sequences have `n sum x_t y_t >= sum x_t sum y_t`, that is `d . d' >= 0`;
//!    - `d . d' <= s s'` (Cauchy-Schwarz);
//!    - `d = a r_b + f` with `f` orthogonal to `r_b` and `|f| = e`, so
//!      `d . d' = a a' + f . f'`, within `a a' +- e e'` (Cauchy-Schwarz again).
//!
//!    So, summing over blocks, `lower <= p . u <= upper` with
//!    `lower = sum_b P P' + max(0, a a' - e e')` and
//!    `upper = sum_b P P' + min(s s', a a' + e e')`. Both are exact bounds of the dot
//!    product of the very `f64` vectors whose rounded dot product is the correlation.
//! 3. **Search** (the optimal multi-step k-nearest-neighbour search of Seidl and
//!    Kriegel). With `mu` the floating-point margin below and `g` the 2^-40 grid, let
//!    `L` be the `k`-th largest lower bound. Then `k` correlations are at least
//!    `L - mu`, so the `k`-th largest `v` of all correlations is too. A correlation
//!    `c < v - 2 g` cannot be chosen, nor tie into the top `k`: rounded to the grid it
//!    is more than one step below `v` (`round(c / g) <= c / g + 1/2 < v / g - 3/2`), so
//!    it ranks after `k` others whatever its index. Hence every query whose upper bound
//!    is below `L - 2 mu - 2 g` is dropped at once; the rest have their correlations
//!    computed in decreasing upper bound, and the search stops when the `k`-th largest
//!    correlation `v'` computed so far is above the next upper bound by more than
//!    `mu + 2 g` (then every query left has `c <= upper + mu < v' - 2 g <= v - 2 g`).
//!    The neighbours and weight are then [`top_k`] of the computed correlations, which
//!    hold the true top `k`: the same set, ranked and summed in the same order.
//!    Correlations are computed a few at a time (the first `k` together, then up to
//!    four the stop does not yet rule out), in one pass over `u` each few: one more
//!    than needed changes nothing, as the top `k` of a superset of the true top `k` is
//!    the same. Each is summed in the same lanes and order alone or in a group.
//!
//! # Floating-point margin
//!
//! The bounds above hold for exact summaries; `mu` covers what rounding does to them,
//! with `u = 2^-53`, `gamma(m) = m u / (1 - m u)`, and `N`, `N'` the norms of a block of
//! `p` and `u`:
//! - every computed summary is within `tau N` of its exact value, `tau = 8 gamma(|DB| + 16)`:
//!   `P` is a rounded sum (`gamma(n)` times `sum |x_t| <= sqrt(n) N`) divided by a
//!   rounded `sqrt(n)`; `a` a rounded dot product with a ramp whose factor is rounded a
//!   few times (`gamma(n + 4) N`); `e` and `s` are norms of residuals taken with the
//!   computed mean and ramp coefficient, whose exact value can only exceed the exact
//!   `e` (a component along `1_b` and `r_b` is added, orthogonal to the rest) by less
//!   than `2 gamma(n + 4) N`, each rounded residual is off by at most
//!   `3 u (|x_t| + |mean| + |ramp_t|)` (at most `10 u N` as a vector), and the rounded
//!   norm adds `gamma(n + 2)` relative;
//! - so each rounded product of two summaries is within `(2 tau + tau^2 + 2 u) N N'` of
//!   the exact one (`|P| <= N` and so on, exactly and with `1 + tau` when computed);
//!   a block's lower or upper term (a product, a sum or difference of two, a min or
//!   max, which cost nothing, and two rounded additions) is within
//!   `3 (2 tau + tau^2) N N' + 16 u N N'`, and summing the `B` terms adds
//!   `gamma(B)` times their magnitudes, at most `3 (1 + tau)^2 N N'` each;
//! - the blocks' `N N'` add up to at most `|p| |u|` (Cauchy-Schwarz), and a computed
//!   standardised profile has norm at most `1 + gamma(|DB| + 3) < 1.01`;
//! - the correlation itself, a rounded dot product, is within `gamma(|DB|) |p| |u|` of
//!   the exact dot product of the two vectors.
//!
//! So `mu = 1.05 (3 (2 tau + tau^2) + 16 u + 4 gamma(B) + gamma(|DB|))` bounds the
//! distance from each computed bound to the exact one plus that of the computed
//! correlation to the exact dot product (`margin`): about `1.6e-10` at |DB| = 27,592,
//! far below the gaps the screen relies on and above none of the grid's ties (near
//! ties are computed exactly, as every candidate within the margin is).
//!
//! # Edges
//!
//! Equal-count blocks are loose: the tails of sorted profiles hold most of the
//! within-block variance. The edges are chosen greedily on the calibration: starting
//! from one block, split the block (at the best of up to 512 (`EDGE_TRIALS`) evenly spaced
//! ranks) whose split most reduces the summed squared residual `e^2` of a sample of
//! calibration profiles, until there are 64 blocks or no split helps. The edges
//! then run down to a rank or two at the extremes (a block of two ranks is fitted
//! exactly by its mean and ramp). They only decide how tight the bounds
//! are, never what is chosen. Below |DB| = 256 (`DIRECT_BELOW`), summaries would save
//! little: every correlation is computed, as [`top_k`] asks.

use rayon::prelude::*;

use super::kernels::{Bounds, GROUP, Summarise};
use super::profiles::Ranked;
use super::{CORRELATION_GRID, top_k, top_k_of};
use crate::input::Score;
use crate::platform::threads;

/// The most blocks a [`Screen`] cuts the rank axis into.
const BLOCKS: usize = 64;
/// Below this |DB|, a [`Screen`] computes every correlation.
const DIRECT_BELOW: usize = 4 * BLOCKS;
/// The most calibration profiles (evenly spaced) the edges are fitted to ...
const EDGE_PROFILES: usize = 16;
/// ... and the most scores of them (the edge fit's working memory is 16 bytes a score).
const EDGE_SCORES: usize = 1 << 20;
/// The most split points tried per block when fitting edges (evenly spaced).
const EDGE_TRIALS: usize = 512;

/// The block summaries of every calibration profile, which bound each correlation of a
/// deployment query from its own summaries (see the module docs).
pub(crate) struct Screen {
    n_cal: usize,
    /// The block edges, from 0 to |DB| (`B + 1` of them); empty for no screen (every
    /// correlation is computed).
    edges: Vec<usize>,
    /// Field by field (`P`, `a`, `e`, `s`), block by block, the calibration profiles'
    /// values: `summaries[(field * B + block) * n_cal + i]`, so that one deployment
    /// query's bounds sweep them in order.
    summaries: Vec<f64>,
    /// The floating-point margin `mu` of the bounds and correlations.
    margin: f64,
}

/// The four summaries of a block.
const FIELDS: usize = 4;

impl Screen {
    /// The screen of calibration profiles `cal`: edges fitted to them and their
    /// summaries. No screen (every correlation computed) below |DB| = [`DIRECT_BELOW`].
    pub(crate) fn new<T: Score>(cal: &Ranked<T>) -> Self {
        let (n_db, n_cal) = (cal.n_db(), cal.ncols());
        if n_db < DIRECT_BELOW {
            return Self {
                n_cal,
                edges: Vec::new(),
                summaries: Vec::new(),
                margin: 0.0,
            };
        }
        threads::install(|| {
            let edges = fit_edges(cal);
            let blocks = edges.len() - 1;
            let per_profile: Vec<f64> = (0..n_cal)
                .into_par_iter()
                .map_init(
                    || vec![0.0; n_db],
                    |x, i| {
                        cal.profile(i, x);
                        summarise(x, &edges)
                    },
                )
                .flatten_iter()
                .collect();
            let mut summaries = vec![0.0; per_profile.len()];
            for (i, one) in per_profile.chunks(FIELDS * blocks).enumerate() {
                for (f, v) in one.iter().enumerate() {
                    summaries[f * n_cal + i] = *v;
                }
            }
            Self {
                n_cal,
                margin: margin(n_db, blocks),
                edges,
                summaries,
            }
        })
    }

    /// The bytes it holds (edges and summaries).
    #[cfg(test)]
    fn bytes(&self) -> usize {
        std::mem::size_of_val(self.edges.as_slice()) + std::mem::size_of_val(self.summaries.as_slice())
    }

    /// The number of blocks (0 for no screen).
    fn blocks(&self) -> usize {
        self.edges.len().saturating_sub(1)
    }

    /// The lower and upper bounds of the correlation of a standardised deployment
    /// profile `u` with every calibration profile, before the margin.
    fn bounds(&self, u: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let query = summarise(u, &self.edges);
        pulp::Arch::new().dispatch(Bounds {
            cal: &self.summaries,
            query: &query,
            n_cal: self.n_cal,
            blocks: self.blocks(),
        })
    }

    /// [`top_k`] of the correlations of a standardised deployment profile `u` with the
    /// calibration profiles, where `exact(is, out)` puts into `out` the `f64`
    /// correlations with calibration queries `is`, asked only for the queries the bounds
    /// cannot rule out (module docs).
    pub(crate) fn top_k(&self, u: &[f64], k: usize, exact: impl Fn(&[usize], &mut [f64])) -> (Vec<usize>, f64) {
        let k = k.min(self.n_cal);
        if self.edges.is_empty() || k == self.n_cal {
            let all: Vec<usize> = (0..self.n_cal).collect();
            let mut row = vec![0.0; self.n_cal];
            exact(&all, &mut row);
            return top_k(&row, k);
        }
        let (lower, upper) = self.bounds(u);
        let mut kth = lower.clone();
        let (_, &mut kth_lower, _) = kth.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
        let cut = kth_lower - 2.0 * self.margin - 3.0 * CORRELATION_GRID;
        let mut order: Vec<(f64, usize)> = (upper.iter().zip(&lower).enumerate())
            .map(|(i, (&hi, &lo))| (hi.max(lo), i))
            .filter(|&(hi, _)| hi >= cut)
            .collect();
        order.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let slack = self.margin + 3.0 * CORRELATION_GRID;
        // The k largest correlations computed so far, descending.
        let mut best: Vec<f64> = Vec::with_capacity(k + 1);
        let (mut is, mut cs) = (Vec::with_capacity(2 * k), Vec::with_capacity(2 * k));
        let mut next = 0;
        while next < order.len() {
            // The first k are always computed, together; after them, the queries that
            // the k-th correlation so far does not rule out, a group at a time (one
            // computed beyond the stop changes nothing: the top k of more candidates
            // that hold the true top k is the same).
            let end = if best.len() < k {
                k
            } else {
                let kth = best[k - 1];
                next + order[next..]
                    .iter()
                    .take(GROUP)
                    .take_while(|&&(hi, _)| hi + slack >= kth)
                    .count()
            };
            if end == next {
                break;
            }
            let end = end.min(order.len());
            is.extend(order[next..end].iter().map(|&(_, i)| i));
            cs.resize(is.len(), 0.0);
            exact(&is[next..], &mut cs[next..]);
            for &c in &cs[next..] {
                let at = best.partition_point(|&b| b >= c);
                if at < k {
                    best.insert(at, c);
                    best.truncate(k);
                }
            }
            next = end;
        }
        top_k_of(is.into_iter().zip(cs).collect(), k)
    }
}

/// The floating-point margin `mu` of a screen of `blocks` blocks over |DB| = `n_db`
/// (module docs, *Floating-point margin*).
fn margin(n_db: usize, blocks: usize) -> f64 {
    let u = f64::EPSILON / 2.0;
    let gamma = |m: usize| m as f64 * u / (1.0 - m as f64 * u);
    let tau = 8.0 * gamma(n_db + 16);
    1.05 * (3.0 * (2.0 * tau + tau * tau) + 16.0 * u + 4.0 * gamma(blocks) + gamma(n_db))
}

/// The summaries of a standardised profile `x` on the blocks of `edges`, field by field:
/// `[P; B]`, `[a; B]`, `[e; B]`, `[s; B]`.
fn summarise(x: &[f64], edges: &[usize]) -> Vec<f64> {
    let blocks = edges.len().saturating_sub(1);
    let mut out = vec![0.0; FIELDS * blocks];
    pulp::Arch::new().dispatch(Summarise {
        x,
        edges,
        out: &mut out,
    });
    out
}

/// Block edges for the calibration profiles `cal` (module docs, *Edges*): `0`, the
/// edges, `|DB|`.
fn fit_edges<T: Score>(cal: &Ranked<T>) -> Vec<usize> {
    let n = cal.n_db();
    let n_prof = cal.ncols().min(EDGE_PROFILES).min((EDGE_SCORES / n).max(1));
    let stride = n + 1;
    // Prefix sums, per sampled profile, of x_t and t x_t; and of x_t^2 over all of them.
    let mut s0 = vec![0.0; n_prof * stride];
    let mut s1 = vec![0.0; n_prof * stride];
    let mut s2 = vec![0.0; stride];
    let mut x = vec![0.0; n];
    for j in 0..n_prof {
        cal.profile(j * cal.ncols() / n_prof, &mut x);
        let (p0, p1) = (
            &mut s0[j * stride..(j + 1) * stride],
            &mut s1[j * stride..(j + 1) * stride],
        );
        for (t, &v) in x.iter().enumerate() {
            p0[t + 1] = p0[t] + v;
            p1[t + 1] = p1[t] + t as f64 * v;
            s2[t + 1] += v * v;
        }
    }
    for t in 0..n {
        s2[t + 1] += s2[t];
    }
    // The summed squared residual of the mean and the ramp on ranks lo..hi.
    let cost = |lo: usize, hi: usize| {
        let len = (hi - lo) as f64;
        let centre = (lo + hi - 1) as f64 / 2.0;
        let ramp2 = len * (len * len - 1.0) / 12.0;
        let mut fitted = 0.0;
        for j in 0..n_prof {
            let (p0, p1) = (&s0[j * stride..], &s1[j * stride..]);
            let sum = p0[hi] - p0[lo];
            let ramp = (p1[hi] - p1[lo]) - centre * sum;
            fitted += sum * sum / len + if ramp2 > 0.0 { ramp * ramp / ramp2 } else { 0.0 };
        }
        (s2[hi] - s2[lo] - fitted).max(0.0)
    };
    // The best split of lo..hi: (gain, rank).
    let best_split = |lo: usize, hi: usize| -> (f64, usize) {
        if hi - lo < 2 {
            return (0.0, lo);
        }
        let whole = cost(lo, hi);
        let step = (hi - lo - 1).div_ceil(EDGE_TRIALS).max(1);
        let trials = (lo + 1..hi).step_by(step).chain(std::iter::once(hi - 1));
        trials
            .map(|t| (whole - cost(lo, t) - cost(t, hi), t))
            .fold((0.0, lo), |best, c| if c.0 > best.0 { c } else { best })
    };
    let mut blocks = vec![(0, n, best_split(0, n))];
    while blocks.len() < BLOCKS {
        let (at, &(lo, hi, (gain, t))) = (blocks.iter().enumerate())
            .max_by(|a, b| (a.1.2.0).total_cmp(&b.1.2.0).then(b.0.cmp(&a.0)))
            .expect("at least one block");
        if gain <= 0.0 {
            break;
        }
        blocks[at] = (lo, t, best_split(lo, t));
        blocks.insert(at + 1, (t, hi, best_split(t, hi)));
    }
    std::iter::once(0).chain(blocks.iter().map(|b| b.1)).collect()
}

#[cfg(test)]
mod tests {
    use super::super::tests::{close, lcg};
    use super::*;
    use crate::error::names::Input;
    use ndarray::{Array2, ArrayView2};

    /// The screen of `cal`'s columns and, for each column of `val`: every correlation
    /// within its bounds widened by the margin, and the screen's top `k` equal, bit for
    /// bit, to [`top_k`] of all the correlations, for several `k`. Returns the screen and
    /// the number of correlations it computed at `k = 3`.
    fn check_screen(cal: ArrayView2<'_, f64>, val: ArrayView2<'_, f64>) -> (Screen, usize) {
        let cal = Ranked::new(Input::CalSimilarity, cal, 0).unwrap();
        let val = Ranked::new(Input::DeploymentSimilarity, val, 0).unwrap();
        let screen = Screen::new(&cal);
        let mut u = vec![0.0; cal.n_db()];
        let mut computed = 0;
        for j in 0..val.ncols() {
            val.profile(j, &mut u);
            let row: Vec<f64> = (0..cal.ncols()).map(|i| cal.correlation(i, &u)).collect();
            if !screen.edges.is_empty() {
                let (lower, upper) = screen.bounds(&u);
                for (i, &r) in row.iter().enumerate() {
                    let (lo, hi) = (lower[i] - screen.margin, upper[i] + screen.margin);
                    assert!(lo <= r && r <= hi, "column {j}, profile {i}: {r} outside [{lo}, {hi}]");
                }
            }
            for k in [1, 3, 10, cal.ncols()] {
                let calls = std::cell::Cell::new(0);
                let got = screen.top_k(&u, k, |is, out| {
                    calls.set(calls.get() + is.len());
                    out.iter_mut().zip(is).for_each(|(o, &i)| *o = row[i]);
                });
                let want = top_k(&row, k);
                assert_eq!(got.0, want.0, "column {j}, k = {k}: {row:?}");
                assert_eq!(got.1.to_bits(), want.1.to_bits(), "column {j}, k = {k}");
                if k == 3 {
                    computed += calls.get();
                }
            }
        }
        (screen, computed)
    }

    #[test]
    fn summaries_and_bounds_by_hand() {
        // One block of 4 ranks, ramp t - 3/2 = [-3/2, -1/2, 1/2, 3/2], |ramp|^2 = 5.
        // x = [0, 1, 2, 3]: P = 6 / 2 = 3; a = (0 - 1/2 + 1 + 9/2) / sqrt 5 = sqrt 5;
        //   a straight line, so e = 0; s = |x - 3/2| = sqrt 5.
        // y = [0, 0, 1, 1]: P = 2 / 2 = 1; a = (1/2 + 3/2) / sqrt 5 = 2 / sqrt 5;
        //   s = |[-1/2, -1/2, 1/2, 1/2]| = 1; e = sqrt(s^2 - a^2) = sqrt(1 - 4/5) = 1 / sqrt 5.
        let edges = [0, 4];
        let x = summarise(&[0.0, 1.0, 2.0, 3.0], &edges);
        let y = summarise(&[0.0, 0.0, 1.0, 1.0], &edges);
        let s5 = 5f64.sqrt();
        for (got, want) in x.iter().zip([3.0, s5, 0.0, s5]) {
            assert!(close(*got, want), "{x:?}");
        }
        for (got, want) in y.iter().zip([1.0, 2.0 / s5, 1.0 / s5, 1.0]) {
            assert!(close(*got, want), "{y:?}");
        }
        // x . y = 2 + 3 = 5. Bounds: P P' = 3; a a' = 2, e e' = 0, s s' = sqrt 5:
        // lower = 3 + max(0, 2 - 0) = 5, upper = 3 + min(sqrt 5, 2 + 0) = 5: exact.
        let screen = Screen {
            n_cal: 1,
            edges: edges.to_vec(),
            summaries: x,
            margin: margin(4, 1),
        };
        let (lower, upper) = screen.bounds(&[0.0, 0.0, 1.0, 1.0]);
        assert!(close(lower[0], 5.0) && close(upper[0], 5.0), "{lower:?} {upper:?}");
        // y . y = 2: P P' = 1; a a' = 4/5, e e' = 1/5, s s' = 1: lower = 1 + 3/5,
        // upper = 1 + min(1, 1) = 2. The lower bound is loose where the ramp fits badly.
        let screen = Screen { summaries: y, ..screen };
        let (lower, upper) = screen.bounds(&[0.0, 0.0, 1.0, 1.0]);
        assert!(close(lower[0], 1.6) && close(upper[0], 2.0), "{lower:?} {upper:?}");
    }

    #[test]
    fn the_margin() {
        // u = 2^-53; gamma(27608) = 3.0646e-12, tau = 8 gamma = 2.4517e-11;
        // 1.05 (6 tau + 16 u + 4 gamma(64) + gamma(27592)) = 1.05 (1.47102e-10 + 1.8e-15
        // + 2.84e-14 + 3.0634e-12) = 1.5769e-10.
        let mu = margin(27592, 64);
        assert!((mu / 1.5769e-10 - 1.0).abs() < 1e-3, "{mu}");
    }

    #[test]
    fn edges_run_down_to_single_ranks_at_the_tails() {
        // Gaussian-like profiles (sums of uniforms): steep tails, a flat middle. The edges
        // fitted to them start and end with blocks of a rank or two, and the middle
        // blocks are wider than equal-count ones.
        let mut rand = lcg(5);
        let n_db = 2000;
        let cal = Array2::from_shape_fn((n_db, 20), |_| (0..4).map(|_| rand()).sum::<f64>());
        let cal = Ranked::new(Input::CalSimilarity, cal.view(), 0).unwrap();
        let edges = fit_edges(&cal);
        assert_eq!(edges.len(), BLOCKS + 1);
        assert_eq!((edges[0], edges[BLOCKS]), (0, n_db));
        assert!(edges.windows(2).all(|w| w[0] < w[1]), "{edges:?}");
        // A block of two ranks is fitted exactly by its mean and ramp (e = 0).
        assert!(edges[1] <= 2 && edges[BLOCKS - 1] >= n_db - 2, "{edges:?}");
        let widest = edges.windows(2).map(|w| w[1] - w[0]).max().unwrap();
        assert!(widest > n_db / BLOCKS, "{edges:?}");
    }

    #[test]
    fn screen_of_constant_and_two_valued_profiles() {
        // |DB| = 300 (screened). Constant columns (correlation 0 with everything) and
        // two-valued ones (0/1 in several proportions, and 0/1 in another position), in
        // both roles.
        let n_db = 300;
        let column = |c: usize, i: usize| match c {
            0 => 0.25,
            1 => 7.0,
            c => f64::from(u8::from(i * (c + 1) % 17 < c)),
        };
        let cal = Array2::from_shape_fn((n_db, 12), |(i, c)| column(c, i));
        let val = Array2::from_shape_fn((n_db, 8), |(i, c)| column((c * 5) % 12, i));
        let (screen, _) = check_screen(cal.view(), val.view());
        // A constant deployment profile is all zeros: both bounds are exactly 0.
        let (lower, upper) = screen.bounds(&vec![0.0; n_db]);
        assert!(lower.iter().chain(&upper).all(|&b| b == 0.0));
    }

    #[test]
    fn screen_with_ties() {
        // Few distinct values (many tied scores), duplicated columns and a column scaled by a
        // power of two (the same standardised profile, so exactly tied correlations, which
        // go to the lower index), and columns that differ in one score.
        let mut rand = lcg(21);
        let n_db = 1000;
        let base = Array2::from_shape_fn((n_db, 6), |_| (rand() * 5.0).floor());
        let mut cal = Array2::zeros((n_db, 14));
        for c in 0..14 {
            let mut col = base.column(c % 6).to_owned();
            if c >= 12 {
                col *= 4.0;
            }
            if c == 7 {
                col[3] += 1.0;
            }
            cal.column_mut(c).assign(&col);
        }
        check_screen(cal.view(), base.view());
        check_screen(cal.view(), cal.view());
    }

    #[test]
    fn screen_with_all_variance_in_one_rank() {
        // Profiles zero but for one score at the top, at the bottom, or a single step,
        // against each other and against smooth profiles.
        let n_db = 500;
        let spike = |c: usize, i: usize| match c {
            0 => f64::from(u8::from(i == 0)),
            1 => -f64::from(u8::from(i == 0)),
            2 => f64::from(u8::from(i == n_db / 2)) * 1e6,
            3 => i as f64,
            4 => (i as f64).powi(3),
            _ => f64::from(u8::from(i < c)),
        };
        let cal = Array2::from_shape_fn((n_db, 9), |(i, c)| spike(c, i));
        let val = Array2::from_shape_fn((n_db, 9), |(i, c)| spike(8 - c, (i * 7) % n_db));
        check_screen(cal.view(), val.view());
        check_screen(cal.view(), cal.view());
    }

    #[test]
    fn screen_of_tiny_and_huge_databases() {
        // Below the screen (every correlation computed) and at its edge, and a large |DB|.
        let mut rand = lcg(8);
        for n_db in [1, 2, 3, DIRECT_BELOW - 1, DIRECT_BELOW, 200_000] {
            let cal = Array2::from_shape_fn((n_db, 12), |(_, c)| rand() * (1.0 + c as f64) + rand().powi(c as i32));
            let val = Array2::from_shape_fn((n_db, 3), |(_, c)| rand().powi(c as i32 + 1));
            let (screen, _) = check_screen(cal.view(), val.view());
            assert_eq!(screen.edges.is_empty(), n_db < DIRECT_BELOW);
            if n_db == 200_000 {
                // 64 blocks of 4 summaries of 8 bytes per profile, and the edges.
                assert_eq!(screen.bytes(), 12 * 64 * 4 * 8 + 65 * 8);
            }
        }
    }

    #[test]
    fn screen_under_shifts_between_calibration_and_deployment() {
        // Calibration of uniform noise with a diagonal peak; deployment shifted far from
        // zero (the hard case for centring), rescaled to tiny and huge magnitudes, warped
        // (cubed, exponentiated) and with one outlier.
        let mut rand = lcg(13);
        let n_db = 3000;
        let cal = Array2::from_shape_fn((n_db, 40), |(i, c)| {
            rand() + if i.abs_diff(c * 70) < 3 { 2.0 } else { 0.0 }
        });
        let noise = Array2::from_shape_fn((n_db, 8), |_| rand());
        let val = Array2::from_shape_fn((n_db, 8), |(i, c)| {
            let x = noise[[i, c]];
            match c {
                0 => 1e6 + x,
                1 => 1e-300 * x,
                2 => 1e300 * x,
                3 => x.powi(3),
                4 => (8.0 * x).exp(),
                5 => x + if i == 17 { 1e4 } else { 0.0 },
                6 => -x,
                _ => x + if i.abs_diff(1500) < 3 { 2.0 } else { 0.0 },
            }
        });
        check_screen(cal.view(), val.view());
    }

    #[test]
    fn screen_top_k_equals_brute_force_on_random_cases() {
        // Many small random problems mixing profile shapes (noise, peaks, steps, copies of
        // other columns); every screened top k is that of all correlations, bit for bit.
        let mut rand = lcg(77);
        let (mut computed, mut all) = (0, 0);
        for case in 0..150 {
            let n_db = [256, 300, 1000, 2500][case % 4] + case;
            let n_cal = 1 + (case * 7) % 50;
            let shape = |rand: &mut dyn FnMut() -> f64, c: usize, i: usize| match c % 5 {
                0 => rand(),
                1 => rand() + if i.abs_diff(c * 13 % n_db) < 4 { 1.5 } else { 0.0 },
                2 => f64::from(u8::from(rand() < 0.1 * (c % 7) as f64)),
                3 => rand().powi(1 + (c % 4) as i32),
                _ => (rand() * 3.0).floor(),
            };
            let mut cal = Array2::from_shape_fn((n_db, n_cal), |(i, c)| shape(&mut rand, c + case, i));
            if n_cal > 3 {
                let copy = cal.column(1).to_owned();
                cal.column_mut(n_cal - 1).assign(&copy);
            }
            let val = Array2::from_shape_fn((n_db, 3), |(i, c)| shape(&mut rand, c * 3 + case, i));
            computed += check_screen(cal.view(), val.view()).1;
            all += 3 * n_cal;
        }
        println!("screen: {computed} of {all} correlations computed at k = 3");
        assert!(computed < all);
    }
}
