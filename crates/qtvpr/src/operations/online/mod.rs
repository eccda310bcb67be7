//! semantics §11: online thresholds over a causal window, for a system that decides
//! each query as it arrives.
//!
//! Deployment query `j` gets its quantile `q_j` and weight `w_j` from the calibration
//! alone, exactly as in a batch transfer (the same function computes them). Its
//! threshold `theta_j` is section 6 applied to its *window*, its last `min(m, j + 1)`
//! queries (itself included): the lower weighted median of their `q` with weights `w`,
//! read off all their raw scores. So `theta_j` equals what
//! [`Calibration::transfer`](crate::Calibration::transfer) returns, with no segment
//! size, for the matrix of just the window's columns. Query `j` is then decided at
//! `theta_j`: in single matching its best match (the first maximum) is accepted when
//! its score is `>= theta_j`; in multi matching every score `>= theta_j` is.
//!
//! *Warm-up*: with `min_window = w`, a query with `j + 1 < w` is reject-all (quantile 1,
//! threshold the next `f64` above the window's highest score), so that no decision rests
//! on fewer than `w` queries.
//!
//! [`Online`] keeps only what the window needs: a ring of the last `m` columns, each
//! sorted once when it arrives, with their `q` and `w`, and one column's buffers, reused
//! from push to push. Memory is `8 m |DB|` bytes, and `16 |DB|` more for those (the
//! columns are kept as `f64`, whatever the type pushed, so that one state takes `f32`
//! and `f64` columns alike; widening is exact, so thresholds are those of the input's
//! own type). A push sorts its column, finds its neighbours among the calibration
//! profiles (bounds from block summaries, `f64` correlations where they leave doubt), and finds
//! the window's threshold by bisection over the sorted columns, so no column is ever
//! sorted twice and no score copied again.

use std::any::Any;
use std::collections::VecDeque;
use std::sync::Arc;

use ndarray::{ArrayView1, ArrayView2, ArrayViewMut1, Axis, ShapeBuilder, s};

mod record;

pub use record::{Decision, Field, Kind, Value};

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::extensions::sequence::CausalStream;
use crate::gates::{GateSignals, Gates};
use crate::input::params::OnlineParams;
use crate::input::{Score, validate_scores};
use crate::operations::calibration::{Calibration, QueryTransfer, Wanted};
use crate::operations::chunks::CHUNK_SCORES;
use crate::platform::threads;
use crate::rules::decisions::{Matching, first_at};
use crate::rules::deployment::{sorted_columns_threshold, weighted_median};
use crate::rules::ranked_correlation::Ranked;

/// The state of an online deployment: a calibration, parameters and the window.
///
/// ```
/// use std::sync::Arc;
/// use ndarray::array;
/// use qtvpr::{Calibration, Gate, GroundTruth, Matching, Online, OnlineParams, SequenceParams};
///
/// let s_cal = array![[0.9, 0.2], [0.1, 0.8], [0.3, 0.4]];
/// let gt = GroundTruth::new(array![[true, false], [false, true], [false, false]].view())?;
/// let cal = Arc::new(Calibration::new(s_cal.view(), &gt, Matching::Single)?);
/// let params = OnlineParams {
///     k: 1, precision: 1.0, window: 2, min_window: 1, gate: Gate::None, sequence_gate: SequenceParams::default(),
/// };
/// let mut online = Online::new(cal, params)?;
/// let d = online.push(array![0.7, 0.2, 0.1].view())?;
/// assert_eq!(d.query, 0);
/// assert_eq!((d.best, d.score), (0, 0.7));
/// # Ok::<(), qtvpr::Error>(())
/// ```
pub struct Online {
    calibration: Arc<Calibration>,
    params: OnlineParams,
    n_db: usize,
    /// The window's sorted columns, slot after slot (|DB| scores each, ascending).
    sorted: Vec<f64>,
    /// Per slot: `q` and `w` of the query in it.
    q: Vec<f64>,
    w: Vec<f64>,
    /// The slot the next query goes into (the oldest once the window is full).
    next: usize,
    pushed: usize,
    accepted: Vec<usize>,
    threshold: Option<f64>,
    /// The gates the parameters enable, at their levels on the calibration.
    gates: Gates,
    /// With the sequence gate: the best matches of the last `W` queries decided, the
    /// most recent last (semantics §15).
    recent: VecDeque<usize>,
    /// With a calibration of sequence length `L > 1`: the last `L - 1` raw columns,
    /// which match each arriving column (semantics §15).
    stream: Option<CausalStream>,
    /// What a push finds of its column: the signals of the gates, the PA-score for the
    /// confidence (semantics §14: single matching, |DB| >= 2).
    wanted: Wanted,
    /// Buffers a push reuses (a fresh |DB|-long buffer per push would cost the kernel
    /// zeroing its pages every time): a [`Scratch`] of the type last pushed, and the
    /// standardised profile.
    scratch: Option<Box<dyn Any + Send + Sync>>,
    profile: Vec<f64>,
}

/// A pushed column, contiguous, its sequence-matched column (`L > 1`) and the ranked
/// copy of the column decided.
#[derive(Default)]
struct Scratch<T> {
    column: Vec<T>,
    matched: Vec<T>,
    ranked: Ranked<T>,
}

impl Online {
    /// An empty window over `calibration`.
    ///
    /// The window's memory is taken as queries arrive, up to `8 x window x |DB|` bytes
    /// once it is full.
    ///
    /// A calibration of sequence length `L > 1` ([`Calibration::sequence`]) makes a
    /// state that decides each query on its causal sequence-matched column.
    ///
    /// # Errors
    /// Invalid `params` ([`OnlineParams::validate`]), a gate the calibration cannot
    /// have ([`Calibration::check_gate`]), or a window whose full state
    /// (`window x |DB|` scores) is more than any allocation can hold
    /// ([`Error::InvalidParameter`] naming the window).
    pub fn new(calibration: Arc<Calibration>, params: OnlineParams) -> Result<Online> {
        params.validate()?;
        let gates = calibration.gates(params.gate, &params.sequence_gate, params.precision)?;
        // The confidence map is found here, once, not by the first push.
        let wanted = Wanted::of(&gates, &calibration);
        let n_db = calibration.db_size();
        // The full window holds `window x |DB|` scores as f64 (and a q and w per
        // query): a window whose state exceeds what any allocation can hold would only
        // fail later, after taking memory with every push.
        let limit = isize::MAX as usize / std::mem::size_of::<f64>();
        if params.window.checked_mul(n_db).is_none_or(|n| n > limit) {
            return Err(Error::param(
                "window",
                format!(
                    "{} is too large: its state would hold {} x {n_db} scores, more memory than can be allocated; \
                     the window must be at most {}",
                    params.window,
                    params.window,
                    limit / n_db
                ),
            ));
        }
        let length = calibration.sequence();
        let stream = (length > 1).then(|| CausalStream::new(length, n_db));
        Ok(Online {
            n_db: calibration.db_size(),
            calibration,
            recent: VecDeque::new(),
            stream,
            params,
            sorted: Vec::new(),
            q: Vec::new(),
            w: Vec::new(),
            next: 0,
            pushed: 0,
            accepted: Vec::new(),
            threshold: None,
            gates,
            wanted,
            scratch: None,
            profile: Vec::new(),
        })
    }

    /// Decide one deployment query from its |DB| scores (any stride, f32 or f64).
    ///
    /// # Errors
    /// [`Error::ColumnLength`] for a column of another length than |DB|,
    /// [`Error::NotFinite`] naming the query (as the column) and the row of a NaN or
    /// infinite score. The state is then unchanged.
    pub fn push<T: Score>(&mut self, column: ArrayView1<'_, T>) -> Result<Decision> {
        // On the calling thread: every step of one push is sequential, so it never
        // waits for the pool's threads (a hand-over each way, tens of microseconds).
        self.check_length(column.len())?;
        let mut scratch: Box<Scratch<T>> = match self.scratch.take().map(|s| s.downcast()) {
            Some(Ok(s)) => s,
            _ => Box::default(),
        };
        let decision = self.push_with(column, &mut scratch);
        self.scratch = Some(scratch);
        decision
    }

    /// [`Online::push`] with its buffers.
    fn push_with<T: Score>(&mut self, column: ArrayView1<'_, T>, scratch: &mut Scratch<T>) -> Result<Decision> {
        let Scratch {
            column: copy,
            matched,
            ranked,
        } = scratch;
        // A strided column (a column of a C-order matrix) is read once, into a
        // contiguous copy that the sort and the decision then share: each strided read
        // costs about a cache miss a score.
        let column = if column.is_standard_layout() {
            column
        } else {
            // One tight loop (ndarray's `assign`), so that many of those misses are in
            // flight at once.
            copy.resize(column.len(), T::default());
            ArrayViewMut1::from(&mut copy[..]).assign(&column);
            ArrayView1::from(&copy[..])
        };
        // The column decided: the pushed one, or its sequence-matched column.
        let decided = match &self.stream {
            None => column,
            Some(stream) => {
                // The raw scores are checked first, so that an error names them.
                validate_scores(Input::DeploymentSimilarity, column.insert_axis(Axis(1)))
                    .map_err(|e| e.shifted(self.pushed))?;
                matched.resize(self.n_db, T::default());
                stream.matched(column, matched);
                ArrayView1::from(&matched[..])
            }
        };
        self.calibration
            .rank(ranked, decided.insert_axis(Axis(1)), self.pushed)?;
        self.profile.resize(self.n_db, 0.0);
        let p = &self.params;
        let r = self
            .calibration
            .query(ranked, 0, p.k, p.precision, self.wanted, &mut self.profile);
        self.reserve()?;
        let decision = self.commit(ranked.column(0), decided, r);
        self.keep_raw(column);
        Ok(decision)
    }

    /// Keep a decided query's raw column for the sequence matching of the next ones
    /// ([`Online::reserve`] has made room for it).
    fn keep_raw<T: Score>(&mut self, column: ArrayView1<'_, T>) {
        if let Some(stream) = &mut self.stream {
            stream.keep(column);
        }
    }

    /// Decide several queries, the columns of `s` (|DB| x n) in arrival order. Their
    /// `q` and `w` are found for blocks of columns at once (sorted in parallel),
    /// with the same results as pushing them one by one.
    ///
    /// # Errors
    /// As [`Online::push`], for the first bad column; the queries before it are kept
    /// (decided and in the window), the bad one and those after it are not.
    pub fn push_many<T: Score>(&mut self, s: ArrayView2<'_, T>) -> Result<Vec<Decision>> {
        threads::install(|| {
            let n = s.ncols();
            if n == 0 {
                return Ok(Vec::new());
            }
            self.check_length(s.nrows())?;
            let chunk = (CHUNK_SCORES / self.n_db).clamp(1, 1024);
            let mut decisions = Vec::with_capacity(n);
            let mut ranked = Ranked::default();
            let mut matched: Vec<T> = Vec::new();
            for start in (0..n).step_by(chunk) {
                let end = (start + chunk).min(n);
                let block = s.slice(s![.., start..end]);
                // The columns decided: the block's, or their sequence-matched columns
                // (formed ahead by a copy of the stream, which the pushes then advance).
                let decided = match &self.stream {
                    None => Ok(block),
                    Some(stream) => validate_scores(Input::DeploymentSimilarity, block).and_then(|()| {
                        let mut ahead = stream.clone();
                        matched.resize(self.n_db * block.ncols(), T::default());
                        for (column, out) in block.columns().into_iter().zip(matched.chunks_exact_mut(self.n_db)) {
                            ahead.matched(column, out);
                            ahead.reserve()?;
                            ahead.keep(column);
                        }
                        Ok(ArrayView2::from_shape((self.n_db, block.ncols()).f(), &matched[..])
                            .expect("the block's shape"))
                    }),
                };
                let ranked_ok = decided.and_then(|d| self.calibration.rank(&mut ranked, d, self.pushed).map(|()| d));
                let Ok(decided) = ranked_ok else {
                    // A bad score in the block: push its columns one by one, which keeps
                    // those before the bad one and reports it.
                    for j in start..end {
                        decisions.push(self.push(s.column(j))?);
                    }
                    continue;
                };
                for (j, r) in self.per_query(&ranked).into_iter().enumerate() {
                    self.reserve()?;
                    decisions.push(self.commit(ranked.column(j), decided.column(j), r));
                    self.keep_raw(block.column(j));
                }
            }
            Ok(decisions)
        })
    }

    /// Continue a stream at query `first_query` on a fresh state, as if queries
    /// `0..first_query` had been pushed: `before` holds the scores of those of them
    /// that a decision looks back at, the last [`Online::lookback`]`(first_query)`
    /// (|DB| x that many). The next push is then query `first_query`, decided as in the
    /// whole stream (its window, its warm-up, its consistency, its sequence-matched
    /// column and the numbering of queries and of errors are the stream's), so that
    /// blocks of a stream can be decided independently.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`resume`) for a state that has decided queries, or
    /// a `before` with another number of columns; as [`Online::push_many`] for its
    /// scores, naming their queries in the stream. The state is then fresh again.
    pub fn resume<T: Score>(&mut self, first_query: usize, before: ArrayView2<'_, T>) -> Result<()> {
        if self.pushed != 0 {
            return Err(Error::param(
                "resume",
                format!("needs a fresh state, but {} queries were pushed", self.pushed),
            ));
        }
        let needed = self.lookback(first_query);
        if before.ncols() != needed {
            // What the decisions look back at (Online::lookback).
            let mut what = format!("a window of {}", self.params.window);
            if self.params.gate.sequence() {
                what += &format!(", a sequence window of {}", self.params.sequence_gate.window);
            }
            if self.calibration.sequence() > 1 {
                what += &format!(", a sequence length of {}", self.calibration.sequence());
            }
            return Err(Error::param(
                "resume",
                format!(
                    "at query {first_query} with {what} takes the {needed} queries before it, got {}",
                    before.ncols()
                ),
            ));
        }
        // The queries decided again (for the window and the consistency), after those
        // whose raw columns only match the first of them.
        let decided = needed.min(self.decided_lookback());
        self.pushed = first_query - needed;
        let resumed = (|| {
            for column in before.columns().into_iter().take(needed - decided) {
                self.check_length(column.len())?;
                validate_scores(Input::DeploymentSimilarity, column.insert_axis(Axis(1)))
                    .map_err(|e| e.shifted(self.pushed))?;
                if let Some(stream) = &mut self.stream {
                    stream.reserve()?;
                    stream.keep(column);
                }
                self.pushed += 1;
            }
            self.push_many(before.slice(s![.., needed - decided..]))
        })();
        if let Err(err) = resumed {
            self.sorted.clear();
            self.q.clear();
            self.w.clear();
            (self.next, self.pushed, self.threshold) = (0, 0, None);
            self.accepted.clear();
            self.recent.clear();
            self.stream = self.stream.as_ref().map(|s| CausalStream::new(s.length(), self.n_db));
            return Err(err);
        }
        Ok(())
    }

    /// How many queries before query `first_query` a decision of a resumed state looks
    /// back at ([`Online::resume`]'s `before`): the queries its window and its
    /// consistency read (`max(window - 1, W)`, `W` with the sequence gate only), and the
    /// `L - 1` raw columns before each of them with a calibration of sequence length
    /// `L` (semantics §11, §15); fewer at the start of the stream.
    pub fn lookback(&self, first_query: usize) -> usize {
        let matching = self.calibration.sequence() - 1;
        first_query.min(self.decided_lookback().saturating_add(matching))
    }

    /// The queries before a query whose decisions its own reads: its window's others
    /// and, with the sequence gate, the `W` its consistency reads.
    fn decided_lookback(&self) -> usize {
        let consistency = if self.params.gate.sequence() {
            self.params.sequence_gate.window
        } else {
            0
        };
        (self.params.window - 1).max(consistency)
    }

    /// Database indices accepted for the last pushed query, ascending (multi: every
    /// score `>= threshold`; single: the best match if accepted, else none).
    pub fn accepted(&self) -> &[usize] {
        &self.accepted
    }

    /// The threshold of the last decision (`None` before the first push).
    pub fn threshold(&self) -> Option<f64> {
        self.threshold
    }

    /// The number of queries decided so far.
    pub fn pushed(&self) -> usize {
        self.pushed
    }

    /// The parameters.
    pub fn params(&self) -> &OnlineParams {
        &self.params
    }

    /// The calibration.
    pub fn calibration(&self) -> &Arc<Calibration> {
        &self.calibration
    }

    fn check_length(&self, len: usize) -> Result<()> {
        if len != self.n_db {
            return Err(Error::ColumnLength {
                query: self.pushed,
                len,
                db: self.n_db,
            });
        }
        Ok(())
    }

    fn per_query<T: Score>(&self, ranked: &Ranked<T>) -> Vec<QueryTransfer> {
        let p = &self.params;
        self.calibration.queries(ranked, p.k, p.precision, self.wanted)
    }

    /// Make room for one more query while the window fills: doubling, up to the full
    /// window and no further, and fallibly, so that memory running out is an error
    /// (naming the window) rather than an abort.
    fn reserve(&mut self) -> Result<()> {
        if let Some(stream) = &mut self.stream {
            stream.reserve()?;
        }
        let (n_db, m, len) = (self.n_db, self.params.window, self.q.len());
        if len >= m {
            return Ok(());
        }
        let needed = (len + 1) * n_db;
        let grow = |v: &mut Vec<f64>, needed: usize, full: usize| {
            if v.capacity() >= needed {
                return Ok(());
            }
            let target = needed.max(v.capacity().saturating_mul(2)).min(full);
            v.try_reserve_exact(target - v.len())
        };
        grow(&mut self.sorted, needed, m * n_db)
            .and_then(|()| grow(&mut self.q, len + 1, m))
            .and_then(|()| grow(&mut self.w, len + 1, m))
            .map_err(|_| {
                Error::param(
                    "window",
                    format!(
                        "{m} needs memory for {} x {n_db} scores at query {}, which cannot be allocated",
                        len + 1,
                        self.pushed
                    ),
                )
            })
    }

    /// Put a checked query (its sorted scores, its column and its `q`, `w`) into the
    /// window and decide it; [`Online::reserve`] has made room for it. Cannot fail, so a
    /// failed push changes nothing.
    fn commit<T: Score>(&mut self, sorted: &[T], column: ArrayView1<'_, T>, r: QueryTransfer) -> Decision {
        let (n_db, m) = (self.n_db, self.params.window);
        let slot = self.next;
        if self.q.len() < m {
            self.sorted.extend(sorted.iter().map(|v| v.to_f64()));
            self.q.push(r.quantile);
            self.w.push(r.weight);
        } else {
            let dst = &mut self.sorted[slot * n_db..(slot + 1) * n_db];
            dst.iter_mut().zip(sorted).for_each(|(d, v)| *d = v.to_f64());
            (self.q[slot], self.w[slot]) = (r.quantile, r.weight);
        }
        self.next = (slot + 1) % m;
        let len = self.q.len();
        let query = self.pushed;
        let quantile = if query + 1 < self.params.min_window {
            1.0
        } else {
            // Oldest first, as the window's columns stand in a deployment matrix (the
            // weighted median sums weights in that order).
            let order: Vec<usize> = if len < m {
                (0..len).collect()
            } else {
                (self.next..m).chain(0..self.next).collect()
            };
            let q: Vec<f64> = order.iter().map(|&i| self.q[i]).collect();
            let w: Vec<f64> = order.iter().map(|&i| self.w[i]).collect();
            weighted_median(&q, &w)
        };
        let window = ArrayView2::from_shape((n_db, len).f(), &self.sorted[..n_db * len]).expect("slots of n_db scores");
        let threshold = sorted_columns_threshold(window, quantile);
        self.accepted.clear();
        // The first maximum, whose value the sorted column ends with.
        let best = first_at(column, sorted[sorted.len() - 1].to_f64());
        let score = column[best].to_f64();
        // Semantics §15: the consistency with the best matches of the queries before.
        let consistency = self
            .gates
            .sequence
            .map(|g| g.params.consistency(best, self.recent.iter().rev().copied()));
        if let Some(g) = self.gates.sequence {
            self.recent.push_back(best);
            if self.recent.len() > g.params.window {
                self.recent.pop_front();
            }
        }
        let signals = GateSignals { consistency, ..r.gates };
        match self.calibration.matching() {
            Matching::Single => {
                let kept = self.gates.keeps(score, threshold, &signals);
                self.accepted.extend(kept.then_some(best));
            }
            Matching::Multi => {
                let above = column.iter().enumerate().filter(|(_, v)| v.to_f64() >= threshold);
                self.accepted.extend(above.map(|(i, _)| i));
            }
        }
        self.pushed += 1;
        self.threshold = Some(threshold);
        let (confidence, confidence_lower95) = r
            .pa_score
            .zip(self.calibration.confidence_of_decisions())
            .map_or((f64::NAN, f64::NAN), |(m, map)| map.of(m));
        Decision {
            query,
            query_quantile: r.quantile,
            weight: r.weight,
            quantile,
            threshold,
            best,
            score,
            accepted: self.accepted.len(),
            margin: self.gates.margin.and(r.gates.margin),
            gate: self.gates.margin_level(),
            consistency,
            consistency_level: self.gates.consistency_level(),
            confidence,
            confidence_lower95,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::GroundTruth;
    use crate::input::params::{Defaults, Gate, Params};
    use ndarray::{Array2, array};

    /// The calibration of the transfer tests (|DB| = 3):
    /// - c0 = [3, 1, 2], hard GT rows 0 and 2: multi candidates 3 T, 2 T, 1 F;
    /// - c1 = [1, 4, 1], hard GT rows 0 and 1: multi candidates 4 T, 1 T, 1 F.
    ///
    /// With k = 1 and tau = 1 (see transfer.rs), a query whose profile is linear
    /// (v0 = [2, 6, 4], v2 = [1, 3, 2]) takes c0: t = 2, q = 0.5, w = 1; v1 = [2, 5, 2]
    /// takes c1: t = 4 (the 1-group holds a FP), q = 1, w = 1.
    fn multi() -> Arc<Calibration> {
        let s_cal = array![[3.0, 1.0], [1.0, 4.0], [2.0, 1.0]];
        let gt = GroundTruth::new(array![[1, 1], [0, 1], [1, 0]].view()).unwrap();
        Arc::new(Calibration::new(s_cal.view(), &gt, Matching::Multi).unwrap())
    }

    /// v0, v1, v2 as columns.
    fn deployment() -> Array2<f64> {
        array![[2.0, 2.0, 1.0], [6.0, 5.0, 3.0], [4.0, 2.0, 2.0]]
    }

    fn params(window: usize, min_window: usize) -> OnlineParams {
        OnlineParams {
            k: 1,
            precision: 1.0,
            window,
            min_window,
            gate: Gate::None,
            sequence_gate: Default::default(),
        }
    }

    fn run(cal: &Arc<Calibration>, p: OnlineParams, s: &Array2<f64>) -> (Vec<Decision>, Vec<Vec<usize>>) {
        let mut online = Online::new(Arc::clone(cal), p).unwrap();
        let mut accepted = Vec::new();
        let decisions = s
            .columns()
            .into_iter()
            .map(|c| {
                let d = online.push(c).unwrap();
                accepted.push(online.accepted().to_vec());
                d
            })
            .collect();
        (decisions, accepted)
    }

    #[test]
    fn pushes_of_either_type_and_stride_share_buffers() {
        // |DB| = 400 (past the screen's direct path), 30 calibration columns from a fixed
        // LCG. The same deployment columns pushed alternately as strided f32 views (a
        // column of a C-order matrix) and contiguous f64, into one state whose buffers
        // change type from push to push, decide exactly as pushing them all as f64
        // (widening f32 is exact).
        let mut x = 3u64;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 40) as f32 / (1u64 << 24) as f32
        };
        let s_cal = Array2::from_shape_fn((400, 30), |_| next());
        let gt = GroundTruth::new(Array2::from_shape_fn((400, 30), |(i, j)| i == j).view()).unwrap();
        let cal = Arc::new(Calibration::new(s_cal.view(), &gt, Matching::Single).unwrap());
        let s_val = Array2::from_shape_fn((400, 12), |(i, j)| next() + if i == 7 * j { 0.5 } else { 0.0 });
        let p = OnlineParams {
            k: 5,
            precision: 1.0,
            window: 4,
            min_window: 1,
            gate: Gate::None,
            sequence_gate: Default::default(),
        };
        let (mut mixed, mut wide) = (Online::new(Arc::clone(&cal), p).unwrap(), Online::new(cal, p).unwrap());
        for (j, c) in s_val.columns().into_iter().enumerate() {
            let c64 = c.mapv(f64::from);
            let a = if j % 2 == 0 {
                mixed.push(c).unwrap()
            } else {
                mixed.push(c64.view()).unwrap()
            };
            assert_eq!(a, wide.push(c64.view()).unwrap(), "query {j}");
            assert!(a.weight > 0.0);
        }
        // A push runs on the caller's thread: it never enters the pool (push_many does).
        let installs = || crate::platform::threads::INSTALLS.with(std::cell::Cell::get);
        let before = installs();
        for c in s_val.columns() {
            mixed.push(c).unwrap();
            mixed.push(c.mapv(f64::from).view()).unwrap();
        }
        assert_eq!(installs(), before);
        mixed.push_many(s_val.view()).unwrap();
        assert!(installs() > before);
    }

    #[test]
    fn window_of_one() {
        let (d, accepted) = run(&multi(), params(1, 1), &deployment());
        // v0 alone: q = 0.5 of [2, 4, 6]: h = 2 * 0.5 = 1 -> 4; accepts rows 1 (6) and 2 (4).
        // v1 alone: q = 1 -> reject-all, the next f64 above its maximum 5.
        // v2 alone: q = 0.5 of [1, 2, 3] -> 2; accepts rows 1 (3) and 2 (2).
        let t: Vec<f64> = d.iter().map(|d| d.threshold).collect();
        assert_eq!(t, vec![4.0, 5.0f64.next_up(), 2.0]);
        assert_eq!(d.iter().map(|d| d.quantile).collect::<Vec<_>>(), vec![0.5, 1.0, 0.5]);
        assert_eq!(
            d.iter().map(|d| d.query_quantile).collect::<Vec<_>>(),
            vec![0.5, 1.0, 0.5]
        );
        assert_eq!(d.iter().map(|d| d.query).collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(accepted, vec![vec![1, 2], vec![], vec![1, 2]]);
        // Multi matching reports the column's best match too: v0 = [2, 6, 4], v1 = [2, 5, 2].
        assert_eq!((d[0].best, d[0].score, d[0].accepted, d[0].accept()), (1, 6.0, 2, true));
        assert_eq!(
            (d[1].best, d[1].score, d[1].accepted, d[1].accept()),
            (1, 5.0, 0, false)
        );
        assert!(d.iter().all(|d| (d.weight - 1.0).abs() < 1e-12));
    }

    #[test]
    fn window_of_two_slides() {
        let (d, accepted) = run(&multi(), params(2, 1), &deployment());
        // j = 0: window {v0}: 4, as above.
        // j = 1: window {v0, v1}: q {0.5, 1}, weights 1, 1: the lower median 0.5. Scores
        //   ascending [2, 2, 2, 4, 5, 6]: h = 5 * 0.5 = 2.5 -> 2 + 0.5 * (4 - 2) = 3;
        //   v1 = [2, 5, 2] accepts row 1 only.
        // j = 2: window {v1, v2} (v0 left): q {1, 0.5} -> 0.5. Scores [1, 2, 2, 2, 3, 5]:
        //   h = 2.5 -> 2 + 0.5 * (2 - 2) = 2; v2 = [1, 3, 2] accepts rows 1 and 2.
        assert_eq!(d.iter().map(|d| d.threshold).collect::<Vec<_>>(), vec![4.0, 3.0, 2.0]);
        assert_eq!(d.iter().map(|d| d.quantile).collect::<Vec<_>>(), vec![0.5, 0.5, 0.5]);
        assert_eq!(accepted, vec![vec![1, 2], vec![1], vec![1, 2]]);
    }

    #[test]
    fn window_larger_than_the_stream() {
        // m = 5 > 3 pushed: j = 2's window is {v0, v1, v2}: q {0.5, 1, 0.5}, weights 1:
        // sorted 0.5, 0.5, 1, half of 3 is 1.5 -> cumulative 1, 2 -> 0.5. Scores ascending
        // [1, 2, 2, 2, 2, 3, 4, 5, 6]: h = 8 * 0.5 = 4 -> x[4] = 2.
        let (d, _) = run(&multi(), params(5, 1), &deployment());
        assert_eq!(d.iter().map(|d| d.threshold).collect::<Vec<_>>(), vec![4.0, 3.0, 2.0]);
    }

    #[test]
    fn warm_up_rejects_everything() {
        // min_window 3 of m = 3: j = 0 and 1 are reject-all at the next f64 above their
        // window's maximum (6 both times: v0 holds it); j = 2 as with m = 5 above.
        let (d, accepted) = run(&multi(), params(3, 3), &deployment());
        assert_eq!(
            d.iter().map(|d| d.threshold).collect::<Vec<_>>(),
            vec![6.0f64.next_up(), 6.0f64.next_up(), 2.0]
        );
        assert_eq!(d.iter().map(|d| d.quantile).collect::<Vec<_>>(), vec![1.0, 1.0, 0.5]);
        // q_j is still each query's own.
        assert_eq!(d[0].query_quantile, 0.5);
        assert_eq!(accepted[..2], [Vec::<usize>::new(), Vec::new()]);
    }

    #[test]
    fn soft_ground_truth_and_lower_precision() {
        // Row 2 of c1 soft: its 1 F is ignored, so c1's candidates are 4 T, 1 T: t = 1,
        // sample {1, 4, 1}: c(<= 1) = 2, q = (2 - 1) / 2 = 0.5. v1 alone: q = 0.5 of
        // [2, 2, 5]: h = 1 -> 2, accepting all three rows.
        let s_cal = array![[3.0, 1.0], [1.0, 4.0], [2.0, 1.0]];
        let gt = GroundTruth::new(array![[1, 1], [0, 1], [1, 0]].view())
            .unwrap()
            .with_soft(array![[0, 0], [0, 0], [0, 1]].view())
            .unwrap();
        let soft = Arc::new(Calibration::new(s_cal.view(), &gt, Matching::Multi).unwrap());
        let (d, accepted) = run(&soft, params(1, 1), &deployment());
        assert_eq!((d[1].query_quantile, d[1].threshold), (0.5, 2.0));
        assert_eq!(accepted[1], vec![0, 1, 2]);
        // tau = 0.6 without soft GT: c1's 1-group gives TP 2, FP 1, 2 >= 0.6 * 3, so
        // t = 1 and q = 0.5 likewise.
        let p = OnlineParams {
            precision: 0.6,
            ..params(1, 1)
        };
        let (d, _) = run(&multi(), p, &deployment());
        assert_eq!((d[1].query_quantile, d[1].threshold), (0.5, 2.0));
    }

    #[test]
    fn single_matching_ties_and_inclusive_threshold() {
        // Single: c0's best match 3 (row 0) is correct, c1's 4 (row 1) is not (GT row 2).
        // k = 2 takes both: candidates 4 F, 3 T; at tau 0.5 the 4-group has TP 0 and the
        // 3-group 1 >= 0.5 * 2: t = 3. Sample {1, 1, 1, 2, 3, 4}: c(<= 3) = 5 -> q = 4/5.
        let s_cal = array![[3.0, 1.0], [1.0, 4.0], [2.0, 1.0]];
        let gt = GroundTruth::new(array![[1, 0], [0, 0], [0, 1]].view()).unwrap();
        let cal = Arc::new(Calibration::new(s_cal.view(), &gt, Matching::Single).unwrap());
        let p = OnlineParams {
            k: 2,
            precision: 0.5,
            window: 1,
            min_window: 1,
            gate: Gate::None,
            sequence_gate: Default::default(),
        };
        // u0 = [5, 5, 1]: best is the first maximum, row 0; ascending [1, 5, 5],
        //   h = 2 * 0.8 = 1.6 -> 5 + 0.6 * 0 = 5: 5 >= 5 is accepted (inclusive).
        // u1 = [2, 6, 4]: [2, 4, 6], h = 1.6 -> 4 + 0.6 * 2 = 5.2; best row 1 (6) accepted.
        // u2 = [4, 1, 4.5]: [1, 4, 4.5], h = 1.6 -> 4 + 0.6 * 0.5 = 4.3; best row 2 (4.5).
        // u3 = [1, 2, 1.2]: [1, 1.2, 2] -> 1.2 + 0.6 * 0.8 = 1.68; best 2 (row 1) accepted.
        let s = array![[5.0, 2.0, 4.0, 1.0], [5.0, 6.0, 1.0, 2.0], [1.0, 4.0, 4.5, 1.2]];
        let (d, accepted) = run(&cal, p, &s);
        for (d, (best, score, t)) in d
            .iter()
            .zip([(0, 5.0, 5.0), (1, 6.0, 5.2), (2, 4.5, 4.3), (1, 2.0, 1.68)])
        {
            assert_eq!(d.query_quantile, 0.8);
            assert!((d.threshold - t).abs() < 1e-12, "{} vs {t}", d.threshold);
            assert_eq!((d.best, d.score, d.accepted, d.accept()), (best, score, 1, true));
        }
        assert_eq!(accepted, vec![vec![0], vec![1], vec![2], vec![1]]);
        // A best match below the threshold is rejected: u = [1, 0, 3] alone gives
        // [0, 1, 3], h = 1.6 -> 1 + 0.6 * 2 = 2.2 <= 3 accepted; at tau 0.5 with a window of
        // 2 after u = [9, 9, 9] (q 0.8): scores [0, 1, 3, 9, 9, 9], h = 5 * 0.8 = 4 -> 9.
        let (d, accepted) = run(
            &cal,
            OnlineParams { window: 2, ..p },
            &array![[9.0, 1.0], [9.0, 0.0], [9.0, 3.0]],
        );
        assert_eq!(d[1].threshold, 9.0);
        assert_eq!(
            (d[1].best, d[1].score, d[1].accepted, d[1].accept()),
            (2, 3.0, 0, false)
        );
        assert_eq!(accepted[1], Vec::<usize>::new());
    }

    /// A fixed LCG in [0, 1), quantised to force ties.
    fn lcg(seed: u64) -> impl FnMut() -> f64 {
        let mut x = seed;
        move || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 200) as f64 / 200.0
        }
    }

    #[test]
    fn push_many_equals_pushes_and_windows_equal_transfer() {
        let mut rand = lcg(5);
        let s_cal = Array2::from_shape_fn((9, 12), |_| rand());
        let gt =
            GroundTruth::new(Array2::from_shape_fn((9, 12), |(i, j)| i == j % 9 || i == (j + 1) % 9).view()).unwrap();
        let s_val = Array2::from_shape_fn((9, 40), |_| rand());
        for matching in [Matching::Single, Matching::Multi] {
            let cal = Arc::new(Calibration::new(s_cal.view(), &gt, matching).unwrap());
            for (window, min_window, precision) in [(1, 1, 1.0), (4, 1, 0.8), (7, 3, 1.0), (60, 2, 0.9)] {
                let p = OnlineParams {
                    k: 3,
                    precision,
                    window,
                    min_window,
                    gate: Gate::None,
                    sequence_gate: Default::default(),
                };
                let (one, _) = run(&cal, p, &s_val);
                let mut online = Online::new(Arc::clone(&cal), p).unwrap();
                let many = online.push_many(s_val.view()).unwrap();
                assert_eq!(one, many, "{matching:?} {p:?}");
                let batch = cal
                    .transfer(
                        s_val.view(),
                        &Params {
                            k: 3,
                            precision,
                            segment_size: None,
                            gate: Gate::None,
                            sequence_gate: Default::default(),
                        },
                    )
                    .unwrap();
                for (j, d) in many.iter().enumerate() {
                    assert_eq!(d.query_quantile.to_bits(), batch.query_quantiles[j].to_bits());
                    assert_eq!(d.weight.to_bits(), batch.query_weights[j].to_bits());
                    if j + 1 < min_window {
                        assert_eq!(d.quantile, 1.0);
                        continue;
                    }
                    let first = (j + 1).saturating_sub(window);
                    let w = cal
                        .transfer(
                            s_val.slice(s![.., first..=j]),
                            &Params {
                                k: 3,
                                precision,
                                segment_size: None,
                                gate: Gate::None,
                                sequence_gate: Default::default(),
                            },
                        )
                        .unwrap();
                    assert_eq!(d.quantile.to_bits(), w.segments[0].quantile.to_bits(), "query {j}");
                    assert_eq!(d.threshold.to_bits(), w.segments[0].threshold.to_bits(), "query {j}");
                }
            }
        }
    }

    #[test]
    fn f32_columns_and_strides() {
        let cal = multi();
        let s = deployment();
        let (a, _) = run(&cal, params(2, 1), &s);
        let mut online = Online::new(Arc::clone(&cal), params(2, 1)).unwrap();
        let f = s.mapv(|x| x as f32);
        let b: Vec<Decision> = f.columns().into_iter().map(|c| online.push(c).unwrap()).collect();
        assert_eq!(a, b);
        // A query-major matrix's rows, and push_many over a transposed view.
        let query_major = s.t().to_owned();
        let mut online = Online::new(Arc::clone(&cal), params(2, 1)).unwrap();
        assert_eq!(online.push_many(query_major.t()).unwrap(), a);
        assert_eq!(online.pushed(), 3);
        assert_eq!(online.threshold(), Some(2.0));
    }

    #[test]
    fn errors_leave_the_state_unchanged() {
        let cal = multi();
        let mut online = Online::new(Arc::clone(&cal), params(2, 1)).unwrap();
        assert_eq!(online.threshold(), None);
        online.push(array![2.0, 6.0, 4.0].view()).unwrap();
        let err = online.push(array![1.0, 2.0].view()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "deployment query 1 has 2 scores but the calibration has 3 database images; \
             a query's column holds one score per database image"
        );
        let err = online.push(array![1.0, f64::NAN, 0.0].view()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "deployment similarity contains NaN at row 1, column 1; scores must be finite"
        );
        assert_eq!(
            (online.pushed(), online.threshold(), online.accepted()),
            (1, Some(4.0), &[1, 2][..])
        );
        // The next good query is decided as if the bad ones never came (window {v0, v1}: 3).
        assert_eq!(online.push(array![2.0, 5.0, 2.0].view()).unwrap().threshold, 3.0);
        // push_many keeps the queries before a bad column: v2 is decided, then column 1 fails.
        let bad = array![[1.0, 0.0], [3.0, f64::INFINITY], [2.0, 0.0]];
        let err = online.push_many(bad.view()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "deployment similarity contains inf at row 1, column 3; scores must be finite"
        );
        assert_eq!((online.pushed(), online.threshold()), (3, Some(2.0)));
        assert!(
            online
                .push_many(Array2::<f64>::zeros((3, 0)).view())
                .unwrap()
                .is_empty()
        );
        assert!(matches!(
            online.push_many(Array2::<f64>::zeros((2, 1)).view()),
            Err(Error::ColumnLength {
                query: 3,
                len: 2,
                db: 3
            })
        ));
    }

    #[test]
    fn a_window_no_allocation_could_hold_is_refused() {
        // |DB| = 3. The largest allocation is isize::MAX = 2^63 - 1 bytes, i.e.
        // floor((2^63 - 1) / 8) = 1152921504606846975 f64 scores, so at most
        // floor(1152921504606846975 / 3) = 384307168202282325 queries of 3 scores.
        let largest = 384_307_168_202_282_325;
        let msg = |window: usize| Online::new(multi(), params(window, 1)).err().unwrap().to_string();
        assert_eq!(
            msg(usize::MAX),
            "window 18446744073709551615 is too large: its state would hold 18446744073709551615 x 3 scores, \
             more memory than can be allocated; the window must be at most 384307168202282325"
        );
        assert!(msg(largest + 1).starts_with("window 384307168202282326 is too large"));
        // The largest is accepted, takes memory only as queries arrive, and decides as a
        // window longer than the stream does (window_larger_than_the_stream).
        let mut online = Online::new(multi(), params(largest, 1)).unwrap();
        let (want, _) = run(&multi(), params(3, 1), &deployment());
        let got: Vec<Decision> = deployment()
            .columns()
            .into_iter()
            .map(|c| online.push(c).unwrap())
            .collect();
        assert_eq!(got, want);
        assert!(
            online.sorted.capacity() <= 4 * 3,
            "capacity {}",
            online.sorted.capacity()
        );
    }

    #[test]
    fn parameters() {
        let msg = |p: OnlineParams| p.validate().unwrap_err().to_string();
        assert_eq!(msg(OnlineParams { k: 0, ..params(2, 1) }), "k must be >= 1, got 0");
        assert_eq!(
            msg(OnlineParams {
                precision: 0.0,
                ..params(2, 1)
            }),
            "precision must be in (0, 1], got 0"
        );
        assert_eq!(msg(params(0, 1)), "window must be >= 1, got 0");
        assert_eq!(
            msg(params(2, 3)),
            "min window must be between 1 and the window (2), got 3"
        );
        assert_eq!(
            msg(params(2, 0)),
            "min window must be between 1 and the window (2), got 0"
        );
        assert!(Online::new(multi(), params(0, 1)).is_err());
        let d = Defaults {
            k: 4,
            precision: 0.9,
            window: Some(28),
            gate: Gate::None,
            sequence_gate: Default::default(),
        };
        assert_eq!(
            OnlineParams::resolve(&d, None, None, None, None, None, Default::default()).unwrap(),
            OnlineParams {
                k: 4,
                precision: 0.9,
                window: 28,
                min_window: 1,
                gate: Gate::None,
                sequence_gate: Default::default(),
            }
        );
        assert_eq!(
            OnlineParams::resolve(&d, Some(2), Some(1.0), Some(5), Some(5), None, Default::default()).unwrap(),
            OnlineParams {
                k: 2,
                precision: 1.0,
                window: 5,
                min_window: 5,
                gate: Gate::None,
                sequence_gate: Default::default(),
            }
        );
        let none = Defaults::default();
        assert_eq!(
            OnlineParams::resolve(&none, None, None, None, None, None, Default::default())
                .unwrap_err()
                .to_string(),
            "window is not given and the calibration sets none"
        );
        assert_eq!(
            OnlineParams::resolve(&none, None, None, Some(3), Some(4), None, Default::default())
                .unwrap_err()
                .to_string(),
            "min window must be between 1 and the window (3), got 4"
        );
    }
}
