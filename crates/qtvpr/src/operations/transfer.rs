//! The quantile-transfer pipeline (semantics §4-§6) behind a calibrate-once,
//! transfer-many API.
//!
//! [`Calibration::new`] does all the work that depends only on the calibration traverse:
//! ranked profiles, their standardisation and screen (block summaries), and the
//! per-column candidates. Each [`Calibration::transfer`] then streams the deployment
//! queries through in column chunks: gather, check, sort and standardise a chunk (in
//! parallel), and for each query pick its neighbours (bounding every correlation from
//! the screen's summaries and computing in `f64` only those the bounds leave in doubt),
//! their subset threshold and its quantile (in parallel). When segments are small, each
//! chunk holds whole segments and their thresholds are read off the chunk's sorted
//! copy, so the deployment scores are read once; a larger batch is read again where it
//! lies. Memory beyond the inputs is the calibration profiles plus one chunk.
//!
//! The deployment scores may also come from descriptors
//! ([`ScoreSource::Descriptors`]): each chunk's columns are then computed
//! when the chunk is needed, by the kernel of [`cosine_similarity`](crate::cosine_similarity),
//! so the |DB| x |Qval| matrix never exists and the result is that of the matrix, bit
//! for bit. Such a source has no random access, so a chunk then always holds whole
//! segments (one segment when a segment is larger than the base chunk).
//!
//! With the sequence gate (semantics §15) the transfer also gives each query's
//! consistency, from its best match and those of the queries before it in the stream:
//! the deployment columns in order, preceded by the columns a caller gives as what
//! comes before them ([`Calibration::transfer_block`]: a split traverse's calibration
//! queries, a scheduler's previous block). A calibration with a sequence length `L > 1`
//! matches the deployment matrix causally first ([`sequence_match`]), so the transfer
//! is that of `similarity --sequence L --causal`'s matrix; from descriptors, that matrix
//! is computed in memory.

use std::ops::Range;

use ndarray::Array2;
use rayon::prelude::*;

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::extensions::sequence::{Sequence, sequence_match};
use crate::extensions::similarity::DescriptorColumns;
use crate::gates::sequence::of_best_matches;
use crate::input::params::{Options, Params};
use crate::input::{check_nonempty, validate_scores};
use crate::operations::calibration::{Calibration, Wanted};
use crate::operations::chunks::{CHUNK_SCORES, Chunks, Fused};
use crate::operations::source::ScoreSource;
use crate::platform::threads;
use crate::rules::deployment::{deployment_threshold, segments, sorted_columns_threshold, weighted_median};
use crate::rules::ranked_correlation::Ranked;

/// The threshold of one segment of deployment queries.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Segment {
    /// First deployment query (column index of the deployment matrix).
    pub start: usize,
    /// One past the last deployment query.
    pub end: usize,
    /// The weighted-median quantile of the segment's queries.
    pub quantile: f64,
    /// That quantile of the segment's scores: accept a match when `score >= threshold`.
    pub threshold: f64,
}

/// Result of [`Calibration::transfer`].
#[derive(Debug, Clone)]
pub struct Transfer {
    /// One threshold per segment, in order.
    pub segments: Vec<Segment>,
    /// Per deployment query: the quantile `q_j` of its subset threshold.
    pub query_quantiles: Vec<f64>,
    /// Per deployment query: its subset threshold `t_j` (`inf` for reject-all).
    pub query_thresholds: Vec<f64>,
    /// Per deployment query: its weight `w_j`.
    pub query_weights: Vec<f64>,
    /// |Qval| x min(k, |Qcal|): each query's calibration neighbours, most correlated first.
    pub neighbours: Array2<usize>,
    /// With the margin gate (semantics §13): `m*`, the margin a query's best match needs
    /// besides a score at or above its segment's threshold (`inf`: reject-all).
    pub gate: Option<f64>,
    /// With the margin gate: every deployment query's margin.
    pub query_margins: Option<Vec<f64>>,
    /// In single matching (semantics §14): every deployment query's confidence, the
    /// calibration's hit rate at its PA-score (NaN for a calibration without a decision);
    /// `None` in multi matching or with fewer than 2 database images.
    pub query_confidences: Option<Vec<f64>>,
    /// Beside [`Transfer::query_confidences`]: the one-sided 95% Clopper-Pearson lower
    /// bound of each.
    pub query_confidences_lower95: Option<Vec<f64>>,
    /// With the sequence gate (semantics §15): its level, the consistency a query's best
    /// match needs besides a score at or above its segment's threshold.
    pub consistency_level: Option<f64>,
    /// With the sequence gate: every deployment query's consistency with the queries
    /// before it in the stream.
    pub query_consistencies: Option<Vec<f64>>,
}

/// Every field equal, a NaN confidence (a calibration without a decision) equal to a
/// NaN confidence, so that transfers compare as values.
impl PartialEq for Transfer {
    fn eq(&self, other: &Self) -> bool {
        let same = |a: &Option<Vec<f64>>, b: &Option<Vec<f64>>| match (a, b) {
            (Some(a), Some(b)) => {
                a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
            }
            (a, b) => a.is_none() && b.is_none(),
        };
        self.segments == other.segments
            && self.query_quantiles == other.query_quantiles
            && self.query_thresholds == other.query_thresholds
            && self.query_weights == other.query_weights
            && self.neighbours == other.neighbours
            && self.gate == other.gate
            && self.query_margins == other.query_margins
            && same(&self.query_confidences, &other.query_confidences)
            && same(&self.query_confidences_lower95, &other.query_confidences_lower95)
            && self.consistency_level == other.consistency_level
            && self.query_consistencies == other.query_consistencies
    }
}
impl Calibration {
    /// Transfer thresholds to the deployment similarity `scores` (|DB| x |Qval|): a
    /// matrix, or descriptors. Segments and query indices count from the source's
    /// first query. `options` are the [`Params`] (`&params`), and a progress callback
    /// called as `progress(done, total)` as deployment queries are processed
    /// ([`Options::progress`]).
    ///
    /// Descriptors are never held as a |DB| x |Qval| similarity: each chunk of columns
    /// is computed when the transfer needs it, with the kernel of
    /// [`cosine_similarity`](crate::cosine_similarity), so the result is exactly the
    /// transfer of those columns of `cosine_similarity(db, q)`. Each chunk holds whole
    /// segments (one segment when a segment is larger than the base chunk of about
    /// 2^22 scores), computed where it is sorted, so memory beyond the descriptors and
    /// the calibration is one chunk of scores and fewer than a tile of columns (16, the
    /// similarity kernel's) computed ahead.
    ///
    /// # Errors
    /// Invalid parameters, empty or non-finite scores, a |DB| that differs from the
    /// calibration's, a segment size of 0 or above |Qval|, or a range of descriptor
    /// queries that is empty or beyond |Q|.
    pub fn transfer<'s, 'd: 's, 'p>(
        &self,
        scores: impl Into<ScoreSource<'s, 'd>>,
        options: impl Into<Options<'p, Params>>,
    ) -> Result<Transfer> {
        self.transfer_in_chunks(scores.into(), &options.into(), CHUNK_SCORES, 0)
    }

    /// [`Calibration::transfer`] of a block of a larger deployment set: the columns of
    /// `scores` are its queries `first_query..first_query + |Qval|`. Segments (of
    /// `params.segment_size` queries from the block's first) and the column of a
    /// non-finite score count in the larger set, so that a scheduler that cuts the set
    /// into blocks of whole segments has the transfer of the whole by concatenation.
    ///
    /// # Errors
    /// As [`Calibration::transfer`] of the block.
    pub fn transfer_at<'s, 'd: 's, 'p>(
        &self,
        scores: impl Into<ScoreSource<'s, 'd>>,
        options: impl Into<Options<'p, Params>>,
        first_query: usize,
    ) -> Result<Transfer> {
        let mut out = self.transfer(scores, options).map_err(|e| e.shifted(first_query))?;
        for segment in &mut out.segments {
            segment.start += first_query;
            segment.end += first_query;
        }
        Ok(out)
    }

    /// [`Calibration::transfer_at`] of a block of a stream preceded by what its
    /// decisions look back at: the first `before` columns of `scores` are the queries
    /// `first_query - before .. first_query` of the stream, read only for the
    /// consistency of the sequence gate (their best matches) and the causal sequence
    /// matching of a calibration with `L > 1` (their raw scores); the other columns are
    /// the block's queries, `first_query..`, thresholded. With `before` equal to
    /// `min(first_query, self.lookback(...))` ([`Calibration::lookback`]) the block's
    /// result is that of the whole stream's transfer, so that a scheduler can cut a
    /// stream into blocks (or a split traverse's deployment queries can look back into
    /// its calibration queries). Segments count from `first_query`, and the column of a
    /// non-finite score in the stream (from `first_query - before`).
    ///
    /// # Errors
    /// As [`Calibration::transfer`]; `before` larger than `first_query` or than the
    /// columns of `scores` less one ([`Error::InvalidParameter`] named `before`).
    pub fn transfer_block<'s, 'd: 's, 'p>(
        &self,
        scores: impl Into<ScoreSource<'s, 'd>>,
        options: impl Into<Options<'p, Params>>,
        first_query: usize,
        before: usize,
    ) -> Result<Transfer> {
        let scores = scores.into();
        let n = scores.dim().1;
        if before > first_query || before >= n.max(1) {
            return Err(Error::param(
                "before",
                format!(
                    "must be at most the block's first query ({first_query}) and leave a query of the {n} \
                     columns to threshold, got {before}"
                ),
            ));
        }
        let mut out = self
            .transfer_after(scores, options, before)
            .map_err(|e| e.shifted(first_query - before))?;
        for segment in &mut out.segments {
            segment.start += first_query;
            segment.end += first_query;
        }
        Ok(out)
    }

    /// The transfer of the columns of `scores` after its first `before`, which are what
    /// the decisions look back at ([`Calibration::transfer_block`]); segments count from
    /// the first column after them, errors name columns of `scores`.
    pub(crate) fn transfer_after<'s, 'd: 's, 'p>(
        &self,
        scores: impl Into<ScoreSource<'s, 'd>>,
        options: impl Into<Options<'p, Params>>,
        before: usize,
    ) -> Result<Transfer> {
        self.transfer_in_chunks(scores.into(), &options.into(), CHUNK_SCORES, before)
    }

    /// What [`Calibration::transfer`] of a deployment similarity of shape `shape`
    /// (|DB| x |Qval|) refuses before it reads a score, in the same order: invalid
    /// parameters, an empty matrix, a |DB| other than the calibration's, a segment size
    /// of 0 or above |Qval|, a margin gate the calibration cannot have. A scheduler that transfers blocks of the matrix
    /// ([`Calibration::transfer_at`]) checks the whole request with it first.
    ///
    /// # Errors
    /// Those of [`Calibration::transfer`] listed above.
    pub fn check_transfer(&self, shape: (usize, usize), params: &Params) -> Result<()> {
        params.validate()?;
        check_nonempty(Input::DeploymentSimilarity, shape)?;
        if shape.0 != self.db_size() {
            return Err(Error::DatabaseMismatch {
                calibration: self.db_size(),
                deployment: shape.0,
            });
        }
        segments(shape.1, params.segment_size)?;
        self.check_gate(params.gate, &params.sequence_gate)
    }

    /// The transfer, with deployment chunks of about `chunk_scores` scores, of the
    /// columns of `source` after its first `before` (what the decisions look back at).
    /// Errors name columns of `source`.
    fn transfer_in_chunks(
        &self,
        source: ScoreSource<'_, '_>,
        options: &Options<'_, Params>,
        chunk_scores: usize,
        before: usize,
    ) -> Result<Transfer> {
        let params = &options.params;
        params.validate()?;
        let progress = |done, total| options.report(done, total);
        if self.sequence() > 1 {
            // Matched causally over the stream given, as the calibration was: in memory.
            check_nonempty(Input::DeploymentSimilarity, source.dim())?;
            return source.with_matrix(|s| {
                with_scores!(s, |s| {
                    validate_scores(Input::DeploymentSimilarity, s)?;
                    let matched = sequence_match(s, Sequence::causal(self.sequence()))?;
                    self.transfer_from(matched.view(), params, progress, chunk_scores, before)
                })
            });
        }
        match source {
            ScoreSource::Matrix(s) => {
                check_nonempty(Input::DeploymentSimilarity, s.dim())?;
                with_scores!(s, |s| self.transfer_from(s, params, progress, chunk_scores, before))
            }
            ScoreSource::Descriptors(d, queries) => {
                d.check_range(&queries)?;
                let columns = Fused {
                    dim: (d.shape().0, queries.len()),
                    columns: DescriptorColumns::new(d, queries.start),
                };
                self.transfer_from(columns, params, progress, chunk_scores, before)
            }
        }
    }

    /// The transfer, reading deployment scores from `source` in chunks of about
    /// `chunk_scores` scores: its columns after the first `before`, which only give
    /// their best matches to the consistency (semantics §15).
    fn transfer_from<S: Chunks>(
        &self,
        mut source: S,
        params: &Params,
        progress: impl Fn(usize, usize),
        chunk_scores: usize,
        before: usize,
    ) -> Result<Transfer> {
        let (n_db, n_all) = source.dim();
        if n_db != self.db_size() {
            return Err(Error::DatabaseMismatch {
                calibration: self.db_size(),
                deployment: n_db,
            });
        }
        let n_val = n_all - before;
        let ranges = segments(n_val, params.segment_size)?;
        let k = params.k.min(self.len());
        let gates = self.gates(params.gate, &params.sequence_gate, params.precision)?;
        // The best matches of the stream given, for the consistency: those of the
        // columns before the deployment queries first (ranked for them alone).
        let mut best = gates.sequence.map(|_| vec![0; n_all]);
        let mut ranked = Ranked::default();
        if let Some(best) = best.as_mut().filter(|_| before > 0) {
            source.rank(&mut ranked, 0..before, Some(&mut best[..before]))?;
        }
        let mut query_margins = gates.margin.map(|_| vec![0.0; n_val]);
        // Found before the parallel loops, which only read it.
        let confidence = self.confidence_of_decisions();
        let mut query_confidences = confidence.map(|_| (vec![0.0; n_val], vec![0.0; n_val]));
        let wanted = Wanted::of(&gates, self);

        let mut query_quantiles = vec![0.0; n_val];
        let mut query_thresholds = vec![0.0; n_val];
        let mut query_weights = vec![0.0; n_val];
        let mut neighbours = Array2::zeros((n_val, k));
        let mut segments = Vec::with_capacity(ranges.len());
        // Chunks bound the working memory whatever the matrix size. Where segments are
        // smaller, a chunk holds whole segments, whose thresholds are then read off the
        // chunk's sorted columns while they are at hand: one pass over the data. A source
        // without random access (descriptors) always works so, a chunk of one segment
        // when segments are larger.
        let base = (chunk_scores / self.db_size()).clamp(16, 4096);
        let segment_size = ranges[0].len();
        let in_chunks = segment_size <= base || source.whole().is_none();
        let chunk = if segment_size <= base {
            base / segment_size * segment_size
        } else if in_chunks {
            segment_size
        } else {
            base
        };
        for start in (0..n_val).step_by(chunk) {
            let end = (start + chunk).min(n_val);
            let here = best.as_mut().map(|b| &mut b[before + start..before + end]);
            source.rank(&mut ranked, before + start..before + end, here)?;
            for (j, r) in (start..end).zip(self.queries(&ranked, k, params.precision, wanted)) {
                neighbours
                    .row_mut(j)
                    .iter_mut()
                    .zip(r.neighbours)
                    .for_each(|(d, i)| *d = i);
                (query_weights[j], query_thresholds[j], query_quantiles[j]) = (r.weight, r.threshold, r.quantile);
                if let (Some(m), Some(margin)) = (query_margins.as_mut(), r.gates.margin) {
                    m[j] = margin;
                }
                if let (Some((c, lower)), Some(map), Some(r)) = (query_confidences.as_mut(), confidence, r.pa_score) {
                    (c[j], lower[j]) = map.of(r);
                }
            }
            if in_chunks {
                let sorted = ranked.view();
                let here: Vec<&Range<usize>> = ranges.iter().filter(|r| r.start >= start && r.end <= end).collect();
                let local = |r: &Range<usize>| sorted.slice(ndarray::s![.., r.start - start..r.end - start]);
                threads::install(|| {
                    segments.par_extend(here.into_par_iter().map(|r| {
                        segment(r.clone(), &query_quantiles, &query_weights, |q| {
                            sorted_columns_threshold(local(r), q)
                        })
                    }));
                });
            }
            progress(end, n_val);
        }
        if let (false, Some(s)) = (in_chunks, source.whole()) {
            segments = threads::install(|| {
                ranges
                    .into_par_iter()
                    .map(|r| {
                        let scores = s.slice(ndarray::s![.., before + r.start..before + r.end]);
                        segment(r, &query_quantiles, &query_weights, |q| deployment_threshold(scores, q))
                    })
                    .collect()
            });
        }
        let query_consistencies = gates
            .sequence
            .zip(best)
            .map(|(g, best)| of_best_matches(&g.params, &best).split_off(before));
        Ok(Transfer {
            segments,
            query_quantiles,
            query_thresholds,
            query_weights,
            neighbours,
            gate: gates.margin_level(),
            query_margins,
            query_confidences: query_confidences.as_ref().map(|c| c.0.clone()),
            query_confidences_lower95: query_confidences.map(|c| c.1),
            consistency_level: gates.consistency_level(),
            query_consistencies,
        })
    }
}

/// The segment `r` of deployment queries, given the threshold of a quantile of its scores.
fn segment(r: Range<usize>, q: &[f64], w: &[f64], threshold: impl FnOnce(f64) -> f64) -> Segment {
    let quantile = weighted_median(&q[r.clone()], &w[r.clone()]);
    Segment {
        start: r.start,
        end: r.end,
        quantile,
        threshold: threshold(quantile),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::extensions::similarity::Descriptors;
    use crate::input::GroundTruth;
    use crate::input::params::Gate;
    use crate::rules::decisions::Matching;
    use ndarray::array;

    /// |DB| = 3, two calibration and two deployment queries (columns).
    ///
    /// - cal q0 = [3, 1, 2], hard GT rows 0 and 2; profile [3, 2, 1] (centred [1, 0, -1]).
    ///   Multi candidates: 3 T, 2 T, 1 F.
    /// - cal q1 = [1, 4, 1], hard GT rows 0 and 1; profile [4, 1, 1] (centred [2, -1, -1]).
    ///   Multi candidates: 4 T, 1 T, 1 F (rows 0 and 2 tie at 1).
    /// - val v0 = [2, 6, 4]: profile [6, 4, 2], centred [2, 0, -2]: r = 1 with q0,
    ///   6 / sqrt 48 = 0.866 with q1.
    /// - val v1 = [2, 5, 2]: profile [5, 2, 2], centred [2, -1, -1]: r = 1 with q1,
    ///   3 / sqrt 12 = 0.866 with q0.
    fn example() -> (Calibration, Array2<f64>) {
        let s_cal = array![[3.0, 1.0], [1.0, 4.0], [2.0, 1.0]];
        let gt = GroundTruth::new(array![[1, 1], [0, 1], [1, 0]].view()).unwrap();
        let cal = Calibration::new(s_cal.view(), &gt, Matching::Multi).unwrap();
        (cal, array![[2.0, 2.0], [6.0, 5.0], [4.0, 2.0]])
    }

    pub(crate) fn params(k: usize, segment_size: Option<usize>) -> Params {
        Params {
            k,
            precision: 1.0,
            segment_size,
            gate: Gate::None,
            sequence_gate: Default::default(),
        }
    }

    #[test]
    fn one_neighbour_each() {
        let (cal, s_val) = example();
        let out = cal.transfer(s_val.view(), &params(1, None)).unwrap();
        assert_eq!(out.neighbours, array![[0], [1]]);
        // v0 -> q0: tau = 1 threshold 2 (3 T, 2 T, then 1 F). Sample {3, 1, 2}: c(<= 2) = 2,
        //   q = (2 - 1) / (3 - 1) = 0.5.
        // v1 -> q1: 4 T | 1 T, 1 F: the 1-group holds a FP, so t = 4, the sample maximum:
        //   c = 3, q = 1.
        assert_eq!(out.query_thresholds, vec![2.0, 4.0]);
        assert_eq!(out.query_quantiles, vec![0.5, 1.0]);
        assert!(out.query_weights.iter().all(|w| (w - 1.0).abs() < 1e-12));
        // One batch: weights 1, 1; lower median of {0.5, 1} is 0.5. Deployment scores
        // ascending [2, 2, 2, 4, 5, 6], h = 5 * 0.5 = 2.5 -> 2 + 0.5 * (4 - 2) = 3.
        assert_eq!(
            out.segments,
            vec![Segment {
                start: 0,
                end: 2,
                quantile: 0.5,
                threshold: 3.0
            }]
        );
    }

    #[test]
    fn segments_of_one() {
        let (cal, s_val) = example();
        let out = cal.transfer(s_val.view(), &params(1, Some(1))).unwrap();
        // v0 alone: q = 0.5 of [2, 4, 6] -> h = 1 -> 4. v1 alone: q = 1 -> just above its max 5.
        assert_eq!(
            out.segments,
            vec![
                Segment {
                    start: 0,
                    end: 1,
                    quantile: 0.5,
                    threshold: 4.0
                },
                Segment {
                    start: 1,
                    end: 2,
                    quantile: 1.0,
                    threshold: 5.0f64.next_up()
                },
            ]
        );
    }

    #[test]
    fn k_larger_than_the_calibration_is_clipped() {
        let (cal, s_val) = example();
        let out = cal.transfer(s_val.view(), &params(5, None)).unwrap();
        assert_eq!(out.neighbours, array![[0, 1], [1, 0]]);
        // Both queries use both columns: candidates 4 T, 3 T, 2 T, 1 T, 1 F, 1 F -> t = 2.
        // Sample {3, 1, 2, 1, 4, 1}: c(<= 2) = 4, q = 3 / 5. Batch threshold: h = 5 * 0.6 = 3
        // -> the fourth smallest deployment score, 4.
        assert_eq!(out.query_thresholds, vec![2.0, 2.0]);
        assert_eq!(out.query_quantiles, vec![0.6, 0.6]);
        let w = (1.0 + 6.0 / 48f64.sqrt()) / 2.0;
        assert!(
            out.query_weights.iter().all(|x| (x - w).abs() < 1e-12),
            "{:?}",
            out.query_weights
        );
        assert_eq!(out.segments[0].threshold, 4.0);
        assert_eq!(cal.threshold(1.0).unwrap(), 2.0);
    }

    #[test]
    fn lower_precision_target() {
        // tau = 0.6, k = 1: v1 -> q1: the 1-group gives (2, 1), 2 >= 1.8, so t = 1 and
        // c(<= 1) = 2 of 3 -> q = 0.5. v0 unchanged (t = 2, q = 0.5).
        let (cal, s_val) = example();
        let out = cal
            .transfer(
                s_val.view(),
                &Params {
                    k: 1,
                    precision: 0.6,
                    segment_size: None,
                    gate: Gate::None,
                    sequence_gate: Default::default(),
                },
            )
            .unwrap();
        assert_eq!(out.query_thresholds, vec![2.0, 1.0]);
        assert_eq!(out.query_quantiles, vec![0.5, 0.5]);
    }

    #[test]
    fn orientation_and_dtype_do_not_matter() {
        let (cal, s_val) = example();
        let a = cal.transfer(s_val.view(), &params(1, None)).unwrap();
        let f32_val = s_val.mapv(|x| x as f32);
        assert_eq!(cal.transfer(f32_val.view(), &params(1, None)).unwrap(), a);
        let query_major = s_val.t().to_owned();
        assert_eq!(cal.transfer(query_major.t(), &params(1, None)).unwrap(), a);
    }

    #[test]
    fn chunking_does_not_change_results() {
        // 7 x 45 deployment queries scored with a fixed LCG; chunks of at least 16 queries.
        let mut x = 99u64;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 1000) as f64 / 1000.0
        };
        let s_cal = Array2::from_shape_fn((7, 9), |_| next());
        let gt = GroundTruth::new(Array2::from_shape_fn((7, 9), |(i, j)| i == j % 7).view()).unwrap();
        let s_val = Array2::from_shape_fn((7, 45), |_| next());
        for matching in [Matching::Single, Matching::Multi] {
            let cal = Calibration::new(s_cal.view(), &gt, matching).unwrap();
            // Segments of 3 fit in chunks (chunks of 15); 20 and the whole batch do not.
            for segment_size in [Some(3), Some(20), None] {
                let p = Params {
                    k: 4,
                    precision: 0.8,
                    segment_size,
                    gate: Gate::None,
                    sequence_gate: Default::default(),
                };
                let one = cal
                    .transfer_in_chunks(s_val.view().into(), &(&p).into(), usize::MAX, 0)
                    .unwrap();
                let many = cal.transfer_in_chunks(s_val.view().into(), &(&p).into(), 0, 0).unwrap();
                assert_eq!(one, many, "{matching:?} {segment_size:?}");
                let calls = std::cell::Cell::new(0);
                let count = |done, total| {
                    calls.set(calls.get() + 1);
                    assert_eq!(total, 45);
                    assert!(done <= total);
                };
                cal.transfer_in_chunks(s_val.view().into(), &Options::new(p).progress(&count), 0, 0)
                    .unwrap();
                assert_eq!(calls.get(), 3, "45 queries in chunks of 16 (or 15)");
            }
        }
    }

    #[test]
    fn descriptors_give_the_bits_of_their_matrix() {
        // 40 database and 130 query descriptors (3 tiles of 64) of dimension 5 from a
        // fixed LCG; the first 23 queries calibrate, 107 deploy. With base chunks of 16
        // queries (chunk_scores 0), segments of 3 and 7 fit chunks, segments of 20 and
        // the whole batch of 107 do not: the fused transfer then takes one segment per
        // chunk where the matrix path reads each segment again where it lies.
        let mut x = 7u64;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 1000) as f64 / 1000.0 - 0.5
        };
        let db = Array2::from_shape_fn((40, 5), |_| next());
        let q = Array2::from_shape_fn((130, 5), |_| next()).mapv(|v| v as f32);
        let s = crate::extensions::similarity::cosine_similarity(db.view(), q.view()).unwrap();
        let d = Descriptors::new(db.view(), q.view()).unwrap();
        let gt = GroundTruth::new(Array2::from_shape_fn((40, 23), |(i, j)| i % 23 == j).view()).unwrap();
        for matching in [Matching::Single, Matching::Multi] {
            let cal = Calibration::new(s.slice(ndarray::s![.., ..23]), &gt, matching).unwrap();
            let fused_cal = Calibration::new(ScoreSource::Descriptors(&d, 0..23), &gt, matching).unwrap();
            assert_eq!(fused_cal.scores(), cal.scores());
            // Calibrations that keep nothing to save, from the matrix and the descriptors.
            let lean = [
                Calibration::for_transfer(s.slice(ndarray::s![.., ..23]), gt.clone(), matching).unwrap(),
                Calibration::for_transfer(ScoreSource::Descriptors(&d, 0..23), gt.clone(), matching).unwrap(),
            ];
            assert!(lean.iter().all(|c| c.scores().is_none() && c.ground_truth().is_none()));
            for segment_size in [Some(3), Some(7), Some(20), None] {
                let p = Params {
                    k: 4,
                    precision: 0.8,
                    segment_size,
                    gate: Gate::None,
                    sequence_gate: Default::default(),
                };
                let want = cal.transfer(s.slice(ndarray::s![.., 23..]), &p).unwrap();
                for c in &lean {
                    assert_eq!(c.transfer(ScoreSource::Descriptors(&d, 23..130), &p).unwrap(), want);
                    assert_eq!(c.threshold(0.8).unwrap(), cal.threshold(0.8).unwrap());
                }
                for chunk_scores in [0, usize::MAX] {
                    let calls = std::cell::RefCell::new(vec![]);
                    let record = |a, _| calls.borrow_mut().push(a);
                    let got = fused_cal
                        .transfer_in_chunks(
                            ScoreSource::Descriptors(&d, 23..130),
                            &Options::new(p).progress(&record),
                            chunk_scores,
                            0,
                        )
                        .unwrap();
                    assert_eq!(got, want, "{matching:?} {segment_size:?} {chunk_scores}");
                    // Chunks of 16 queries hold 5 segments of 3 (15) or 2 of 7 (14);
                    // segments of 20 are a chunk each; the batch is one chunk.
                    let last = calls.borrow().last().copied();
                    assert_eq!(last, Some(107));
                    if chunk_scores == 0 {
                        let first = calls.borrow()[0];
                        assert_eq!(
                            first,
                            [15, 14, 20, 107][[Some(3), Some(7), Some(20), None]
                                .iter()
                                .position(|&x| x == segment_size)
                                .unwrap()]
                        );
                    }
                }
            }
        }
        // Errors: a range beyond the queries, an empty range, another database.
        let p = params(1, None);
        let cal = Calibration::new(ScoreSource::Descriptors(&d, 0..23), &gt, Matching::Single).unwrap();
        assert_eq!(
            cal.transfer(ScoreSource::Descriptors(&d, 100..131), &p)
                .unwrap_err()
                .to_string(),
            "queries must be a non-empty range of the 130 query descriptors, got 100..131"
        );
        assert!(cal.transfer(ScoreSource::Descriptors(&d, 5..5), &p).is_err());
        assert!(Calibration::new(ScoreSource::Descriptors(&d, 0..22), &gt, Matching::Single).is_err());
        for source in [
            ScoreSource::Descriptors(&d, 0..22),
            s.slice(ndarray::s![.., ..22]).into(),
        ] {
            assert!(matches!(
                Calibration::for_transfer(source, gt.clone(), Matching::Single),
                Err(Error::ShapeMismatch { .. })
            ));
        }
        assert!(
            Calibration::for_transfer(ScoreSource::Descriptors(&d, 120..131), gt.clone(), Matching::Single).is_err()
        );
        let small = Descriptors::new(db.slice(ndarray::s![..39, ..]), q.view()).unwrap();
        assert_eq!(
            cal.transfer(ScoreSource::Descriptors(&small, 23..130), &p).unwrap_err(),
            Error::DatabaseMismatch {
                calibration: 40,
                deployment: 39
            }
        );
    }

    #[test]
    fn bad_parameters_and_input() {
        let (cal, s_val) = example();
        let msg = |p: Params| cal.transfer(s_val.view(), &p).unwrap_err().to_string();
        assert_eq!(msg(params(0, None)), "k must be >= 1, got 0");
        assert_eq!(
            msg(Params {
                precision: 1.5,
                ..params(1, None)
            }),
            "precision must be in (0, 1], got 1.5"
        );
        assert_eq!(
            msg(Params {
                precision: f64::NAN,
                ..params(1, None)
            }),
            "precision must be in (0, 1], got NaN"
        );
        assert!(msg(params(1, Some(0))).starts_with("segment size must be between 1 and"));
        assert!(msg(params(1, Some(3))).ends_with("(2), got 3"));
        let err = cal.transfer(array![[1.0], [2.0]].view(), &params(1, None)).unwrap_err();
        assert_eq!(
            err,
            Error::DatabaseMismatch {
                calibration: 3,
                deployment: 2
            }
        );
        let err = cal
            .transfer(array![[1.0], [f64::INFINITY], [0.0]].view(), &params(1, None))
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "deployment similarity contains inf at row 1, column 0; scores must be finite"
        );
        let gt = GroundTruth::new(array![[true]].view()).unwrap();
        let err = Calibration::new(array![[1.0, 2.0]].view(), &gt, Matching::Single)
            .err()
            .unwrap();
        assert_eq!(
            err.to_string(),
            "ground truth shape 1x1 does not match calibration similarity shape 1x2"
        );
    }
}
