//! semantics §4: calibration sampling by ranked correlation.
//!
//! Every query column is sorted into a *ranked profile*; the Pearson correlation of two
//! profiles is the dot product of their centred, unit-norm forms. Each deployment query
//! keeps its `k` most correlated calibration queries ([`top_k`]).
//!
//! Profiles are kept in *ascending* order: reversing both profiles of a pair changes
//! neither their correlation nor any count of scores below a threshold, and ascending
//! is what the radix sort gives. `Ranked` gathers a block of columns into a
//! column-major buffer of the input's own type (tile by tile, so a C-order matrix is
//! read row-wise rather than with one cache miss per score), checks every score is
//! finite, and sorts and standardises each column while it is in cache.
//!
//! # An exact screen that reads about `k` profiles
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

use ndarray::{Array2, ArrayView2, ArrayViewMut1, ShapeBuilder, s};
use rayon::prelude::*;

use crate::error::names::Input;
use crate::error::{Error, Result, try_reserve};
use crate::input::{Score, check_nonempty};
use crate::platform::threads;

/// Correlations are compared on a grid of `2^-40` (about 9.1e-13) when choosing
/// neighbours, so that correlations equal in exact arithmetic tie (and go to the lower
/// calibration index) whatever the floating-point summation order.
pub const CORRELATION_GRID: f64 = 1.0 / (1u64 << 40) as f64;

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

/// What an allocation failure names: the sorted profiles of `n` columns of `n_db` scores.
fn profiles(what: Input, n_db: usize, n: usize) -> String {
    format!("the sorted profiles of the {what} ({n_db}x{n})")
}

/// A block of columns, each sorted ascending, column-major, in the input's type; with
/// each column's standardisation.
#[derive(Default)]
pub(crate) struct Ranked<T> {
    n_db: usize,
    sorted: Vec<T>,
    standard: Vec<Standard>,
}

impl<T: Score> Ranked<T> {
    /// Gather, check, sort and standardise the columns of `s`. `first_col` is the column
    /// index of `s`'s first column in the matrix `what` names, for error messages.
    ///
    /// # Errors
    /// [`Error::Empty`]; [`Error::NotFinite`] naming the first offending score in
    /// column-major order.
    pub(crate) fn new(what: Input, s: ArrayView2<'_, T>, first_col: usize) -> Result<Self> {
        let mut ranked = Self::default();
        ranked.refill(what, s, first_col)?;
        Ok(ranked)
    }

    /// [`Ranked::new`] in the buffers of `self`, for a stream of chunks (fresh buffers
    /// for each would cost the kernel zeroing their pages again and again).
    ///
    /// # Errors
    /// As [`Ranked::new`]; `self` is then left in an unspecified but valid state.
    pub(crate) fn refill(&mut self, what: Input, s: ArrayView2<'_, T>, first_col: usize) -> Result<()> {
        check_nonempty(what, s.dim())?;
        self.refill_with(what, s.dim(), first_col, |out| gather(s, out))
    }

    /// [`Ranked::refill`] with the |DB| x `n` scores written by `fill` into the
    /// column-major buffer it is given, where they are then sorted: the scores are never
    /// copied (the fused transfer computes them there).
    ///
    /// # Errors
    /// As [`Ranked::new`].
    pub(crate) fn refill_with(
        &mut self,
        what: Input,
        (n_db, n): (usize, usize),
        first_col: usize,
        fill: impl FnOnce(&mut [T]),
    ) -> Result<()> {
        self.n_db = n_db;
        let len = n_db.saturating_mul(n);
        let more = len.saturating_sub(self.sorted.len());
        try_reserve(&mut self.sorted, more, || profiles(what, n_db, n))?;
        self.sorted.resize(len, T::default());
        self.standard.clear();
        self.rank_from(what, first_col, fill)
    }

    /// No columns yet, room for `n` columns of `n_db` scores, to be added by
    /// [`Ranked::extend_with`] (a calibration built a few columns at a time).
    ///
    /// # Errors
    /// [`Error::Allocation`] when memory for them cannot be had.
    pub(crate) fn with_capacity(what: Input, n_db: usize, n: usize) -> Result<Self> {
        let mut sorted = Vec::new();
        try_reserve(&mut sorted, n_db.saturating_mul(n), || profiles(what, n_db, n))?;
        Ok(Self {
            n_db,
            sorted,
            standard: Vec::with_capacity(n),
        })
    }

    /// Append `n` columns, written by `fill` as by [`Ranked::refill_with`]; `first_col`
    /// is the first's column index, for errors.
    ///
    /// # Errors
    /// As [`Ranked::new`].
    pub(crate) fn extend_with(
        &mut self,
        what: Input,
        n: usize,
        first_col: usize,
        fill: impl FnOnce(&mut [T]),
    ) -> Result<()> {
        let more = self.n_db.saturating_mul(n);
        try_reserve(&mut self.sorted, more, || profiles(what, self.n_db, n))?;
        self.sorted.resize(self.sorted.len() + more, T::default());
        self.rank_from(what, first_col, fill)
    }

    /// Fill the columns after the last standardised one with `fill`, then check, sort
    /// and standardise them: in parallel, or on the calling thread for one column (a
    /// push, which then never waits for the pool).
    fn rank_from(&mut self, what: Input, first_col: usize, fill: impl FnOnce(&mut [T])) -> Result<()> {
        let Self { n_db, sorted, standard } = self;
        let new = &mut sorted[standard.len() * *n_db..];
        fill(new);
        let base = standard.len();
        standard.resize(base + new.len() / *n_db, Standard::CONSTANT);
        let rank = |col: usize, (column, standard): (&mut [T], &mut Standard)| {
            if !column.iter().fold(true, |finite, v| finite & v.to_f64().is_finite()) {
                let (row, v) = column.iter().enumerate().find(|(_, v)| !v.to_f64().is_finite())?;
                return Some(Error::NotFinite {
                    what,
                    row,
                    col: first_col + col,
                    value: v.to_f64(),
                });
            }
            T::sort_ascending(column);
            *standard = pulp::Arch::new().dispatch(Standardise(column));
            None
        };
        let columns = new.chunks_mut(*n_db).zip(&mut standard[base..]);
        let bad = if columns.len() == 1 {
            columns.enumerate().find_map(|(col, c)| rank(col, c))
        } else {
            threads::install(|| {
                let columns = new.par_chunks_mut(*n_db).zip(&mut standard[base..]);
                columns.enumerate().find_map_first(|(col, c)| rank(col, c))
            })
        };
        bad.map_or(Ok(()), Err)
    }

    pub(crate) fn ncols(&self) -> usize {
        self.standard.len()
    }

    /// Column `j`, ascending.
    pub(crate) fn column(&self, j: usize) -> &[T] {
        &self.sorted[j * self.n_db..(j + 1) * self.n_db]
    }

    /// All columns as a |DB| x n view (the same multiset of scores per column as the input).
    pub(crate) fn view(&self) -> ArrayView2<'_, T> {
        ArrayView2::from_shape((self.n_db, self.ncols()).f(), &self.sorted).expect("length is n_db * ncols")
    }

    /// The standardised profile of column `j`, in `f64`, into `out`.
    pub(crate) fn profile(&self, j: usize, out: &mut [f64]) {
        let standard = self.standard[j];
        out.iter_mut()
            .zip(self.column(j))
            .for_each(|(o, &x)| *o = standard.apply(x));
    }

    /// The correlation of column `j` with a standardised profile `u`, in `f64`: one
    /// [`sum_lanes`], the order [`Ranked::correlations`] keeps in its groups.
    #[cfg(test)]
    fn correlation(&self, j: usize, u: &[f64]) -> f64 {
        let standard = self.standard[j];
        sum_lanes(u, self.column(j), |a, x| a * standard.apply(x))
    }

    /// The correlations of columns `js` with a standardised profile `u` into `out`, each
    /// the same bits as [`Ranked::correlation`]'s: [`GROUP`] columns in one pass over
    /// `u`, so that `u` is read once a group and the group's sums run side by side
    /// (one column's sum is a chain of dependent additions, which alone leaves the
    /// core waiting on each).
    pub(crate) fn correlations(&self, js: &[usize], u: &[f64], out: &mut [f64]) {
        let arch = pulp::Arch::new();
        for (js, out) in js.chunks(GROUP).zip(out.chunks_mut(GROUP)) {
            // A short group repeats its last column, whose sums are then dropped.
            let j = |m: usize| js[m.min(js.len() - 1)];
            let sums = Correlations {
                u,
                columns: std::array::from_fn(|m| self.column(j(m))),
                standard: std::array::from_fn(|m| self.standard[j(m)]),
            }
            .sums(arch);
            out.copy_from_slice(&sums[..out.len()]);
        }
    }
}

/// How many correlations [`Ranked::correlations`] sums in one pass.
const GROUP: usize = 4;

/// Copy the columns of `s` into `out`, column-major: one column (a push) on the calling
/// thread; contiguous columns (a Fortran-order matrix) as slices; otherwise a tile of
/// columns at a time in parallel, in blocks of rows (so that a C-order matrix is read
/// row by row).
fn gather<T: Score>(s: ArrayView2<'_, T>, out: &mut [T]) {
    let n_db = s.nrows();
    if s.ncols() == 1 {
        ArrayViewMut1::from(out).assign(&s.column(0));
        return;
    }
    if s.strides()[0] == 1 {
        threads::install(|| {
            out.par_chunks_mut(n_db).enumerate().for_each(|(j, out)| {
                out.copy_from_slice(s.column(j).to_slice().expect("a column of unit stride"));
            });
        });
        return;
    }
    threads::install(|| gather_tiles(s, out));
}

/// [`gather`] of a matrix whose columns are strided, in parallel over tiles of columns.
fn gather_tiles<T: Score>(s: ArrayView2<'_, T>, out: &mut [T]) {
    const TILE: usize = 64;
    let n_db = s.nrows();
    out.par_chunks_mut(n_db * TILE).enumerate().for_each(|(tile, out)| {
        let cols = tile * TILE..(tile * TILE + out.len() / n_db);
        for rows in (0..n_db).step_by(4 * TILE).map(|r| r..(r + 4 * TILE).min(n_db)) {
            let block = s.slice(s![rows.clone(), cols.clone()]);
            for (i, row) in rows.zip(block.rows()) {
                for (j, &v) in row.iter().enumerate() {
                    out[j * n_db + i] = v;
                }
            }
        }
    });
}

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
        let (n_db, n_cal) = (cal.n_db, cal.ncols());
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

/// The kernel of [`summarise`], compiled for the widest vectors the CPU has.
struct Summarise<'a> {
    x: &'a [f64],
    edges: &'a [usize],
    out: &'a mut [f64],
}

impl pulp::WithSimd for Summarise<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let blocks = self.edges.len() - 1;
        for (b, w) in self.edges.windows(2).enumerate() {
            let xb = &self.x[w[0]..w[1]];
            let n = xb.len() as f64;
            let centre = (n - 1.0) / 2.0;
            // Pass 1: the sum and the dot product with the centred ramp `t - centre`. A
            // chunk's ramp is the last one's plus LANES: exact (every value is a multiple
            // of 1/2 far below 2^52), so the same bits as `t as f64 - centre` without a
            // conversion a score.
            let first: [f64; LANES] = std::array::from_fn(|l| l as f64 - centre);
            let (mut sum, mut ramp, mut r) = ([0.0; LANES], [0.0; LANES], first);
            let (x8, tail) = xb.as_chunks::<LANES>();
            for x in x8 {
                for l in 0..LANES {
                    sum[l] += x[l];
                    ramp[l] += r[l] * x[l];
                    r[l] += LANES as f64;
                }
            }
            let start = xb.len() - tail.len();
            for (t, &x) in tail.iter().enumerate() {
                sum[0] += x;
                ramp[0] += ((start + t) as f64 - centre) * x;
            }
            let (sum, ramp) = (sum.iter().sum::<f64>(), ramp.iter().sum::<f64>());
            let mean = sum / n;
            // The ramp's unit factor 1 / |t - centre| = 1 / sqrt(n (n^2 - 1) / 12).
            let unit = if xb.len() > 1 {
                1.0 / (n * (n * n - 1.0) / 12.0).sqrt()
            } else {
                0.0
            };
            let a = ramp * unit;
            let slope = a * unit;
            // Pass 2: the norms of the residuals of the mean, and of the mean and ramp; in
            // two loops, which the compiler turns into vector code each (one loop of
            // both it left scalar, twice as slow as the two).
            let (mut s2, mut e2, mut r) = ([0.0; LANES], [0.0; LANES], first);
            for x in x8 {
                for l in 0..LANES {
                    let d = x[l] - mean;
                    s2[l] += d * d;
                }
            }
            for x in x8 {
                for l in 0..LANES {
                    let e = (x[l] - mean) - slope * r[l];
                    e2[l] += e * e;
                    r[l] += LANES as f64;
                }
            }
            for (t, &x) in tail.iter().enumerate() {
                let d = x - mean;
                let e = d - slope * ((start + t) as f64 - centre);
                s2[0] += d * d;
                e2[0] += e * e;
            }
            self.out[b] = sum / n.sqrt();
            self.out[blocks + b] = a;
            self.out[2 * blocks + b] = e2.iter().sum::<f64>().sqrt();
            self.out[3 * blocks + b] = s2.iter().sum::<f64>().sqrt();
        }
    }
}

/// The kernel of [`Screen::bounds`]: block by block, every calibration profile at once.
struct Bounds<'a> {
    cal: &'a [f64],
    query: &'a [f64],
    n_cal: usize,
    blocks: usize,
}

impl pulp::WithSimd for Bounds<'_> {
    type Output = (Vec<f64>, Vec<f64>);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> (Vec<f64>, Vec<f64>) {
        let (n, blocks) = (self.n_cal, self.blocks);
        let (mut lower, mut upper) = (vec![0.0; n], vec![0.0; n]);
        let field = |f: usize, b: usize| &self.cal[(f * blocks + b) * n..(f * blocks + b + 1) * n];
        for b in 0..blocks {
            let q = |f: usize| self.query[f * blocks + b];
            let (qp, qa, qe, qs) = (q(0), q(1), q(2), q(3));
            let (p, a, e, s) = (field(0, b), field(1, b), field(2, b), field(3, b));
            for i in 0..n {
                let base = p[i] * qp;
                let (aa, ee) = (a[i] * qa, e[i] * qe);
                lower[i] += base + (aa - ee).max(0.0);
                upper[i] += base + (s[i] * qs).min(aa + ee);
            }
        }
        (lower, upper)
    }
}

/// Block edges for the calibration profiles `cal` (module docs, *Edges*): `0`, the
/// edges, `|DB|`.
fn fit_edges<T: Score>(cal: &Ranked<T>) -> Vec<usize> {
    let n = cal.n_db;
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

/// How a sorted profile is centred and scaled to unit norm: `(x * inv_scale - mean) *
/// inv_norm`, where `inv_scale` is a power of two that keeps squares from overflowing
/// or underflowing (so scaling is exact), and `inv_norm` is 0 for a constant profile.
#[derive(Debug, Clone, Copy)]
struct Standard {
    inv_scale: f64,
    mean: f64,
    inv_norm: f64,
}

impl Standard {
    const CONSTANT: Self = Self {
        inv_scale: 1.0,
        mean: 0.0,
        inv_norm: 0.0,
    };

    /// The standardisation of a sorted, finite profile. Zero variance is tested exactly
    /// (first == last), not as a small norm.
    #[inline(always)]
    fn of<T: Score>(profile: &[T]) -> Self {
        let (first, last) = (profile[0].to_f64(), profile[profile.len() - 1].to_f64());
        if first == last {
            return Self::CONSTANT;
        }
        // 2^-e for the exponent e of the largest magnitude, within range both ways.
        let exponent = first.abs().max(last.abs()).log2().floor().clamp(-1000.0, 1000.0);
        let inv_scale = (-exponent).exp2();
        let mean = sum_lanes(profile, profile, |x, _| x.to_f64() * inv_scale) / profile.len() as f64;
        let centred = Self {
            inv_scale,
            mean,
            inv_norm: 1.0,
        };
        let norm = sum_lanes(profile, profile, |x, _| centred.apply(x).powi(2)).sqrt();
        Self {
            inv_norm: 1.0 / norm,
            ..centred
        }
    }

    #[inline(always)]
    fn apply<T: Score>(self, x: T) -> f64 {
        (x.to_f64() * self.inv_scale - self.mean) * self.inv_norm
    }
}

/// The correlations of a standardised profile `u` with [`GROUP`] sorted columns,
/// compiled for the widest vectors the CPU has: each column's sum in the lanes and
/// order of [`sum_lanes`], so every CPU, and every grouping, gets the same bits.
struct Correlations<'a, T> {
    u: &'a [f64],
    columns: [&'a [T]; GROUP],
    standard: [Standard; GROUP],
}

impl<T: Score> Correlations<'_, T> {
    /// The group's sums: in explicit 8-lane vectors where the CPU has AVX-512 or AVX2,
    /// else as the compiler vectorises them.
    ///
    /// Explicit, because the compiler's own vectorisation of four columns' 32 lanes in
    /// one loop was a lottery: some builds packed the lanes across columns (a score of
    /// each column in a vector, gathered by scalar inserts) or left them scalar, 2.5 to
    /// 3.5x slower, and which a build got changed with unrelated code elsewhere in the
    /// crate. The vectors hold each column's lanes in order and do the scalar code's
    /// operations, so every path gives the same bits.
    #[inline]
    fn sums(self, arch: pulp::Arch) -> [f64; GROUP] {
        #[cfg(target_arch = "x86_64")]
        {
            if let Some(simd) = pulp::x86::V4::try_new() {
                return pulp::Simd::vectorize(simd, Explicit(simd, self));
            }
            if let Some(simd) = pulp::x86::V3::try_new() {
                return pulp::Simd::vectorize(simd, Explicit(simd, self));
            }
        }
        arch.dispatch(self)
    }

    /// Each column's 8 lane sums, from `lanes` over the whole chunks of `u`, and the
    /// tail after them: the order of [`sum_lanes`].
    #[inline(always)]
    fn finish(self, lanes: [[f64; LANES]; GROUP]) -> [f64; GROUP] {
        let Self { u, columns, standard } = self;
        let body = u.len() / LANES * LANES;
        std::array::from_fn(|m| {
            let tail: f64 = (u[body..].iter().zip(&columns[m][body..]))
                .map(|(&a, &x)| a * standard[m].apply(x))
                .sum();
            lanes[m].iter().sum::<f64>() + tail
        })
    }

    /// Each column's whole chunks of 8 scores, as many as `u` has.
    #[inline(always)]
    fn chunks(&self) -> [&[[T; LANES]]; GROUP] {
        let n = self.u.len() / LANES;
        std::array::from_fn(|m| &self.columns[m][..n * LANES].as_chunks().0[..n])
    }
}

/// The interleaved lanes of every sum here ([`sum_lanes`], the correlations' kernels
/// and the block summaries): they fix each sum's order, and so its bits.
const LANES: usize = 8;

/// The portable kernel (no AVX2): the same operations, lane by lane.
impl<T: Score> pulp::WithSimd for Correlations<'_, T> {
    type Output = [f64; GROUP];

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> [f64; GROUP] {
        let (u8, _) = self.u.as_chunks::<LANES>();
        let x8 = self.chunks();
        let mut lanes = [[0.0; LANES]; GROUP];
        for (c, u8) in u8.iter().enumerate() {
            for (m, lanes) in lanes.iter_mut().enumerate() {
                for l in 0..LANES {
                    lanes[l] += u8[l] * self.standard[m].apply(x8[m][c][l]);
                }
            }
        }
        self.finish(lanes)
    }
}

/// 8 scores as `f32` when they are, for the explicit kernels' widening loads (the
/// score types are sealed: `f32` or `f64`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn as_f32<T: Score>(x: &[T; LANES]) -> Option<&[f32; LANES]> {
    (x as &dyn std::any::Any).downcast_ref()
}

/// The 8 lanes of [`sum_lanes`] in the vectors of one x86 level, with the operations of
/// [`Correlations`]' explicit kernel: each does the scalar code's operation in every
/// lane, one vector instruction a vector.
#[cfg(target_arch = "x86_64")]
trait Lanes8: pulp::Simd {
    /// 8 `f64` lanes, in the layout of `[f64; 8]`.
    type V: pulp::bytemuck::Pod;
    fn splat(self, v: f64) -> Self::V;
    /// 8 scores widened to `f64`.
    fn widen<T: Score>(self, x: &[T; LANES]) -> Self::V;
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    #[inline(always)]
    fn load(x: [f64; LANES]) -> Self::V {
        pulp::bytemuck::cast(x)
    }
    #[inline(always)]
    fn store(v: Self::V) -> [f64; LANES] {
        pulp::bytemuck::cast(v)
    }
}

/// AVX-512: one `f64x8`.
#[cfg(target_arch = "x86_64")]
impl Lanes8 for pulp::x86::V4 {
    type V = pulp::f64x8;
    #[inline(always)]
    fn splat(self, v: f64) -> Self::V {
        self.splat_f64x8(v)
    }
    #[inline(always)]
    fn widen<T: Score>(self, x: &[T; LANES]) -> Self::V {
        match as_f32(x) {
            Some(&x) => self.convert_f32x8_to_f64x8(pulp::bytemuck::cast(x)),
            None => Self::load(x.map(Score::to_f64)),
        }
    }
    #[inline(always)]
    fn add(self, a: Self::V, b: Self::V) -> Self::V {
        self.add_f64x8(a, b)
    }
    #[inline(always)]
    fn sub(self, a: Self::V, b: Self::V) -> Self::V {
        self.sub_f64x8(a, b)
    }
    #[inline(always)]
    fn mul(self, a: Self::V, b: Self::V) -> Self::V {
        self.mul_f64x8(a, b)
    }
}

/// AVX2: two `f64x4`, lanes 0-3 and 4-7.
#[cfg(target_arch = "x86_64")]
impl Lanes8 for pulp::x86::V3 {
    type V = [pulp::f64x4; 2];
    #[inline(always)]
    fn splat(self, v: f64) -> Self::V {
        [self.splat_f64x4(v); 2]
    }
    #[inline(always)]
    fn widen<T: Score>(self, x: &[T; LANES]) -> Self::V {
        match as_f32(x) {
            Some(&x) => {
                let [lo, hi]: [pulp::f32x4; 2] = pulp::bytemuck::cast(x);
                [self.convert_f32x4_to_f64x4(lo), self.convert_f32x4_to_f64x4(hi)]
            }
            None => Self::load(x.map(Score::to_f64)),
        }
    }
    #[inline(always)]
    fn add(self, a: Self::V, b: Self::V) -> Self::V {
        [self.add_f64x4(a[0], b[0]), self.add_f64x4(a[1], b[1])]
    }
    #[inline(always)]
    fn sub(self, a: Self::V, b: Self::V) -> Self::V {
        [self.sub_f64x4(a[0], b[0]), self.sub_f64x4(a[1], b[1])]
    }
    #[inline(always)]
    fn mul(self, a: Self::V, b: Self::V) -> Self::V {
        [self.mul_f64x4(a[0], b[0]), self.mul_f64x4(a[1], b[1])]
    }
}

/// [`Correlations`] in the explicit vectors of `L`: one 8-lane value a column.
#[cfg(target_arch = "x86_64")]
struct Explicit<'a, L, T>(L, Correlations<'a, T>);

#[cfg(target_arch = "x86_64")]
impl<L: Lanes8, T: Score> pulp::WithSimd for Explicit<'_, L, T> {
    type Output = [f64; GROUP];

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> [f64; GROUP] {
        let Self(simd, group) = self;
        let standard = group
            .standard
            .map(|s| (simd.splat(s.inv_scale), simd.splat(s.mean), simd.splat(s.inv_norm)));
        let (u8, _) = group.u.as_chunks::<LANES>();
        let x8 = group.chunks();
        let mut acc = [simd.splat(0.0); GROUP];
        for (c, &u) in u8.iter().enumerate() {
            let u = L::load(u);
            for m in 0..GROUP {
                let (inv_scale, mean, inv_norm) = standard[m];
                let x = simd.mul(simd.sub(simd.mul(simd.widen(&x8[m][c]), inv_scale), mean), inv_norm);
                acc[m] = simd.add(acc[m], simd.mul(u, x));
            }
        }
        group.finish(acc.map(L::store))
    }
}

/// [`Standard::of`], compiled for the widest vectors the CPU has (the lanes of
/// [`sum_lanes`] fix the summation order, so every CPU gets the same bits).
struct Standardise<'a, T>(&'a [T]);

impl<T: Score> pulp::WithSimd for Standardise<'_, T> {
    type Output = Standard;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Standard {
        Standard::of(self.0)
    }
}

/// The sum of `f(a_i, b_i)` over two equally long slices, in eight interleaved lanes:
/// vectorisable, and the same order every time.
#[inline(always)]
fn sum_lanes<A: Copy, B: Copy>(a: &[A], b: &[B], f: impl Fn(A, B) -> f64) -> f64 {
    let (a8, b8) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f64 = a8.remainder().iter().zip(b8.remainder()).map(|(&x, &y)| f(x, y)).sum();
    let mut lanes = [0.0; LANES];
    for (x, y) in a8.zip(b8) {
        for l in 0..LANES {
            lanes[l] += f(x[l], y[l]);
        }
    }
    lanes.iter().sum::<f64>() + tail
}

/// The `k` (clipped to the row length) calibration indices of highest correlation in
/// `row`, in order of decreasing correlation, ties to the lower index; and the weight:
/// the mean of their correlations, clipped below at 0.
///
/// Correlations are compared on the `CORRELATION_GRID`; the weight uses raw values.
pub fn top_k(row: &[f64], k: usize) -> (Vec<usize>, f64) {
    top_k_of(row.iter().copied().enumerate().collect(), k)
}

/// [`top_k`] of (calibration index, correlation) pairs.
fn top_k_of(mut pairs: Vec<(usize, f64)>, k: usize) -> (Vec<usize>, f64) {
    let k = k.min(pairs.len());
    let key = |r: f64| (r / CORRELATION_GRID).round_ties_even();
    let order = |a: &(usize, f64), b: &(usize, f64)| key(b.1).total_cmp(&key(a.1)).then(a.0.cmp(&b.0));
    if k < pairs.len() {
        pairs.select_nth_unstable_by(k - 1, order);
        pairs.truncate(k);
    }
    pairs.sort_unstable_by(order);
    let mean = pairs.iter().map(|p| p.1).sum::<f64>() / k as f64;
    (pairs.into_iter().map(|p| p.0).collect(), mean.max(0.0))
}

/// The full |Qval| x |Qcal| ranked-correlation matrix `R` of semantics §4, in `f64`,
/// the same values the transfer ranks neighbours by.
///
/// # Errors
/// Empty or non-finite scores, or a different number of database rows.
pub fn ranked_correlation<T: Score, U: Score>(val: ArrayView2<'_, T>, cal: ArrayView2<'_, U>) -> Result<Array2<f64>> {
    threads::install(|| {
        let cal = Ranked::new(Input::CalSimilarity, cal, 0)?;
        let val = Ranked::new(Input::DeploymentSimilarity, val, 0)?;
        if val.n_db != cal.n_db {
            return Err(Error::DatabaseMismatch {
                calibration: cal.n_db,
                deployment: val.n_db,
            });
        }
        let mut r = vec![0.0; val.ncols() * cal.ncols()];
        let all: Vec<usize> = (0..cal.ncols()).collect();
        r.par_chunks_mut(cal.ncols()).enumerate().for_each_init(
            || vec![0.0; val.n_db],
            |u, (j, row)| {
                val.profile(j, u);
                cal.correlations(&all, u, row);
            },
        );
        Ok(Array2::from_shape_vec((val.ncols(), cal.ncols()), r).expect("shape matches length"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, array};

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn pearson_of_ranked_profiles() {
        // cal profiles (sorted): [3,2,1] -> centred [1,0,-1]; [4,1,1] -> mean 2 -> [2,-1,-1].
        // val profile [2,6,4] sorts to [6,4,2] -> [2,0,-2]: r = 1 with the first; with the
        // second (4 + 0 + 2) / (sqrt 8 * sqrt 6) = 6 / sqrt 48 = 0.8660254037844386.
        let cal = array![[1.0, 1.0], [3.0, 4.0], [2.0, 1.0]];
        let val = array![[2.0f32], [6.0], [4.0]];
        let r = ranked_correlation(val.view(), cal.view()).unwrap();
        assert_eq!(r.dim(), (1, 2));
        assert!(close(r[[0, 0]], 1.0), "{r}");
        assert!(close(r[[0, 1]], 6.0 / 48f64.sqrt()), "{r}");
        // [1,2,3] vs [0,1,3] (sorted [3,2,1], [3,1,0]): centred [1,0,-1] and [5/3,-1/3,-4/3];
        // dot 3, norms sqrt 2 and sqrt(42)/3 -> r = 9 / sqrt 84.
        let r = ranked_correlation(array![[1.0], [2.0], [3.0]].view(), array![[0.0], [1.0], [3.0]].view()).unwrap();
        assert!(close(r[[0, 0]], 9.0 / 84f64.sqrt()), "{r}");
    }

    #[test]
    fn constant_columns_correlate_zero() {
        // A constant profile has zero variance: correlation 0 with everything, itself included.
        let cal = array![[0.1, 5.0], [0.1, 3.0], [0.1, 4.0]];
        let r = ranked_correlation(cal.view(), cal.view()).unwrap();
        assert_eq!(r[[0, 0]], 0.0);
        assert_eq!(r[[0, 1]], 0.0);
        assert_eq!(r[[1, 0]], 0.0);
        assert!(close(r[[1, 1]], 1.0));
    }

    #[test]
    fn huge_and_tiny_scores_do_not_overflow() {
        // Profiles [1e300, 0, -1e300] and [3e-310, 2e-310, 1e-310] are both linear: r = 1.
        let r = ranked_correlation(
            array![[1e300], [0.0], [-1e300]].view(),
            array![[3e-310], [1e-310], [2e-310]].view(),
        )
        .unwrap();
        assert!(close(r[[0, 0]], 1.0), "{r}");
    }

    #[test]
    fn top_k_orders_by_correlation_then_index() {
        // Ties 0.9 (indices 1, 3) and 0.5 (0, 2): order 1, 3, 0; weight (0.9+0.9+0.5)/3.
        let (nb, w) = top_k(&[0.5, 0.9, 0.5, 0.9], 3);
        assert_eq!(nb, vec![1, 3, 0]);
        assert!(close(w, 2.3 / 3.0));
    }

    #[test]
    fn top_k_clips_k_and_weight() {
        let (nb, w) = top_k(&[0.2, 0.1], 5);
        assert_eq!(nb, vec![0, 1]);
        assert!(close(w, 0.15));
        // A negative mean correlation is clipped to weight 0.
        let (nb, w) = top_k(&[-0.5, -0.7], 1);
        assert_eq!((nb, w), (vec![0], 0.0));
    }

    #[test]
    fn grouped_correlations_are_single_sums_bit_for_bit() {
        // Lengths with and without a tail of the 8 lanes; groups of every size, short
        // ones included, in any order and with repeats.
        for n_db in [1, 7, 8, 29, 64, 203] {
            let mut next = lcg(n_db as u64);
            let cal = Array2::from_shape_fn((n_db, 11), |_| next() * 2.0 - 1.0);
            let cal = Ranked::new(Input::CalSimilarity, cal.view(), 0).unwrap();
            let val = Array2::from_shape_fn((n_db, 1), |_| next());
            let val = Ranked::new(Input::DeploymentSimilarity, val.view(), 0).unwrap();
            let mut u = vec![0.0; n_db];
            val.profile(0, &mut u);
            for len in 1..=9 {
                let is: Vec<usize> = (0..len).map(|m| (7 * m + len) % 11).collect();
                let mut got = vec![f64::NAN; len];
                cal.correlations(&is, &u, &mut got);
                for (&i, c) in is.iter().zip(&got) {
                    assert_eq!(
                        c.to_bits(),
                        cal.correlation(i, &u).to_bits(),
                        "|DB| {n_db}, group {is:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn every_kernel_gives_the_bits_of_a_single_sum() {
        // The explicit AVX-512 and AVX2 kernels and the portable one (whichever this CPU
        // runs), on f32 and f64 columns, with and without a tail of the 8 lanes, against
        // `Ranked::correlation`.
        fn check<T: Score>(cal: &Ranked<T>, u: &[f64]) -> usize {
            let js = [3, 0, 5, 3];
            let group = || Correlations {
                u,
                columns: std::array::from_fn(|m| cal.column(js[m])),
                standard: std::array::from_fn(|m| cal.standard[js[m]]),
            };
            let want = js.map(|j| cal.correlation(j, u).to_bits());
            let mut kernels = vec![("portable", pulp::Simd::vectorize(pulp::Scalar, group()))];
            #[cfg(target_arch = "x86_64")]
            {
                if let Some(simd) = pulp::x86::V3::try_new() {
                    kernels.push(("AVX2", pulp::Simd::vectorize(simd, Explicit(simd, group()))));
                }
                if let Some(simd) = pulp::x86::V4::try_new() {
                    kernels.push(("AVX-512", pulp::Simd::vectorize(simd, Explicit(simd, group()))));
                }
            }
            for (name, got) in &kernels {
                assert_eq!(
                    got.map(f64::to_bits),
                    want,
                    "{name} kernel, {}, |DB| {}",
                    T::DTYPE,
                    u.len()
                );
            }
            kernels.len()
        }
        for n_db in [1, 7, 8, 29, 203, 1000] {
            let mut next = lcg(n_db as u64 + 100);
            // Columns of different scales, so that each has its own standardisation.
            let cal = Array2::from_shape_fn((n_db, 6), |(_, j)| (next() * 2.0 - 1.0) * 10f64.powi(j as i32 - 3));
            let val = Array2::from_shape_fn((n_db, 1), |_| next());
            let val = Ranked::new(Input::DeploymentSimilarity, val.view(), 0).unwrap();
            let mut u = vec![0.0; n_db];
            val.profile(0, &mut u);
            let ran = check(&Ranked::new(Input::CalSimilarity, cal.view(), 0).unwrap(), &u);
            let cal = cal.mapv(|v| v as f32);
            assert_eq!(
                check(&Ranked::new(Input::CalSimilarity, cal.view(), 0).unwrap(), &u),
                ran
            );
        }
    }

    #[test]
    fn correlations_within_the_grid_tie() {
        // 0.3 and 0.3 + 1e-15 differ by far less than 2^-40: a tie, so the lower index wins.
        assert_eq!(top_k(&[0.3, 0.3 + 1e-15], 1).0, vec![0]);
        // 1e-9 is far more than the grid: the larger one wins.
        assert_eq!(top_k(&[0.3, 0.3 + 1e-9], 1).0, vec![1]);
    }

    /// The screen of `cal`'s columns and, for each column of `val`: every correlation
    /// within its bounds widened by the margin, and the screen's top `k` equal, bit for
    /// bit, to [`top_k`] of all the correlations, for several `k`. Returns the screen and
    /// the number of correlations it computed at `k = 3`.
    fn check_screen(cal: ArrayView2<'_, f64>, val: ArrayView2<'_, f64>) -> (Screen, usize) {
        let cal = Ranked::new(Input::CalSimilarity, cal, 0).unwrap();
        let val = Ranked::new(Input::DeploymentSimilarity, val, 0).unwrap();
        let screen = Screen::new(&cal);
        let mut u = vec![0.0; cal.n_db];
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

    /// A fixed LCG in [0, 1).
    fn lcg(seed: u64) -> impl FnMut() -> f64 {
        let mut x = seed;
        move || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        }
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

    #[test]
    fn database_sizes_must_agree() {
        let err = ranked_correlation(array![[1.0], [2.0]].view(), array![[1.0], [2.0], [3.0]].view()).unwrap_err();
        assert_eq!(
            err,
            Error::DatabaseMismatch {
                calibration: 3,
                deployment: 2
            }
        );
    }
}
