//! A calibration traverse, prepared once (semantics §4 and §5): everything a transfer,
//! an online state and the protocol read of it.
//!
//! [`Calibration::new`] does all the work that depends only on the calibration traverse:
//! ranked profiles, their standardisation and screen (block summaries), and the
//! per-column candidates of semantics §2. [`Calibration::queries`] is then the one place
//! a deployment query's neighbours, weight, subset threshold and quantile are found,
//! for the batch transfer (`transfer.rs`) and [`crate::Online`] alike.

use std::ops::Range;
use std::sync::OnceLock;

use ndarray::{Array2, ArrayView2, ShapeBuilder};
use rayon::prelude::*;

use crate::error::Error;
use crate::error::Result;
use crate::error::names::Input;
use crate::extensions::sequence::{Sequence, sequence_match};
use crate::extensions::similarity::{DescriptorColumns, TILE};
use crate::gates::margin::{self, CalibrationMargins, MarginGate};
use crate::gates::sequence::SequenceGate;
use crate::gates::{self, GateSignals, Gates};
use crate::input::params::Defaults;
use crate::input::params::{Gate, SequenceParams};
use crate::input::{
    GroundTruth, LabelRecord, Score, ScoreMatrix, Truth, check_gt_shape, check_precision, validate_scores,
};
use crate::operations::chunks::{CHUNK_SCORES, column_major};
use crate::operations::source::ScoreSource;
use crate::platform::threads;
use crate::rules::best_threshold::subset_threshold;
use crate::rules::decisions::{Candidates, Matching};
use crate::rules::ranked_correlation::{Ranked, Screen};
use crate::rules::subset_quantile::subset_quantile;
use crate::signals::confidence::{self, ConfidenceMap};
use crate::signals::self_motion;

/// A calibration traverse with ground truth, ready to transfer thresholds.
///
/// Built by [`Calibration::new`], it keeps its input besides what the transfer needs
/// (the raw scores in their own type and the ground truth) so that it can be saved as a
/// calibration file (`Calibration::save`, feature `npy`) and loaded with bit-identical
/// results. That costs one more copy of the calibration matrix (|DB| x |Qcal| scores of
/// 4 or 8 bytes) and one byte per entry for the ground truth, beside the ranked profiles
/// (the same size again) and their screen (2 KiB a profile). Built by
/// [`Calibration::for_transfer`], it keeps only the profiles, the screen and the
/// candidates (see `docs/performance.md`).
pub struct Calibration {
    matching: Matching,
    /// The ranked profiles, ascending, in the input's own type, with their
    /// standardisation (for correlations).
    profiles: Box<dyn Profiles>,
    /// The profiles' block summaries, which bound every correlation.
    screen: Screen,
    candidates: Candidates,
    n_db: usize,
    /// The input, kept to be saved (`None` for [`Calibration::for_transfer`]).
    input: Option<(ScoreMatrix, GroundTruth)>,
    /// The defaults of a calibration file's `params`.
    defaults: Defaults,
    /// Its sequence length `L` (semantics §15): 1, or the causal sequence matching its
    /// scores went through, which every deployment column goes through too.
    sequence: usize,
    /// The single-match decisions with their margins, for the gate's `m*`: found on the
    /// first request for a gate (a pass over every profile that a calibration never
    /// gated should not pay).
    margins: OnceLock<CalibrationMargins>,
    /// The confidence map of semantics §14, fitted to the same decisions (by their
    /// PA-scores) on the first request for a confidence.
    confidence: OnceLock<ConfidenceMap>,
}

/// What the calibration gives one deployment query (semantics §4 and §5).
#[derive(Debug, Clone)]
pub(crate) struct QueryTransfer {
    /// Its calibration neighbours, most correlated first.
    pub(crate) neighbours: Vec<usize>,
    /// Its weight `w_j`.
    pub(crate) weight: f64,
    /// Its subset threshold `t_j` (`inf` for reject-all).
    pub(crate) threshold: f64,
    /// The quantile `q_j` of that threshold.
    pub(crate) quantile: f64,
    /// The signals its gates read (semantics §13), when they are on.
    pub(crate) gates: GateSignals,
    /// Its PA-score (semantics §14), when the confidence asks for it.
    pub(crate) pa_score: Option<f64>,
}

/// The per-query signals a caller reads: the margin for the gate (semantics §13), the
/// PA-score for the confidence (§14). Neither is computed unless asked for.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Wanted {
    margin: bool,
    pa_score: bool,
}

impl Wanted {
    /// What `gates` read of a query, and its PA-score when `calibration`'s decisions
    /// have a confidence.
    pub(crate) fn of(gates: &Gates, calibration: &Calibration) -> Self {
        Self {
            margin: gates.margin.is_some(),
            pa_score: calibration.confidence_of_decisions().is_some(),
        }
    }
}

/// What the transfer asks of the calibration profiles, whatever their score type.
trait Profiles: Send + Sync {
    /// The quantile of a subset threshold `t` among sorted calibration columns.
    fn quantile(&self, columns: &[usize], t: f64) -> f64;
    /// The `f64` correlations of calibration queries `is` with a standardised profile
    /// `u`, into `out`.
    fn correlations(&self, is: &[usize], u: &[f64], out: &mut [f64]);
    /// The margin (semantics §13) of calibration query `i`.
    fn margin(&self, i: usize) -> f64;
    /// The PA-score (semantics §14) of calibration query `i`.
    fn pa_score(&self, i: usize) -> f64;
}

impl<T: Score> Profiles for Ranked<T> {
    fn quantile(&self, columns: &[usize], t: f64) -> f64 {
        subset_quantile(columns.iter().map(|&i| self.column(i)), t)
    }
    fn correlations(&self, is: &[usize], u: &[f64], out: &mut [f64]) {
        Ranked::correlations(self, is, u, out)
    }
    fn margin(&self, i: usize) -> f64 {
        margin::of_sorted(self.column(i))
    }
    fn pa_score(&self, i: usize) -> f64 {
        confidence::pa_score_of_sorted(self.column(i))
    }
}

impl Calibration {
    /// Prepare calibration similarity `scores` (|DB| x |Qcal|) with its ground truth:
    /// a matrix, or descriptors, whose similarity is computed in memory (the
    /// calibration keeps it anyway), bit for bit as
    /// [`cosine_similarity`](crate::cosine_similarity) computes those columns.
    ///
    /// # Errors
    /// Empty or non-finite scores, a range of descriptor queries that is empty or
    /// beyond |Q|, ground truth of another shape, or self-motion labels (semantics §16:
    /// ground truth with a [`GroundTruth::record`]) with multi matching.
    pub fn new<'s, 'd: 's>(
        scores: impl Into<ScoreSource<'s, 'd>>,
        gt: &GroundTruth,
        matching: Matching,
    ) -> Result<Self> {
        self_motion::check_matching(gt, matching)?;
        match scores.into() {
            ScoreSource::Matrix(s) => with_scores!(s, |s| threads::install(|| {
                let ranked = Ranked::new(Input::CalSimilarity, s, 0)?;
                check_gt_shape(gt, Input::CalSimilarity, s.dim())?;
                Ok(Self::from_ranked(ranked, Score::to_matrix(s), gt.clone(), matching))
            })),
            ScoreSource::Descriptors(d, queries) => {
                d.check_range(&queries)?;
                check_gt_shape(gt, Input::CalSimilarity, (d.shape().0, queries.len()))?;
                // The computed matrix becomes the calibration's own copy: no second one.
                let s = d.similarity(queries)?;
                let ranked = Ranked::new(Input::CalSimilarity, s.view(), 0)?;
                Ok(Self::from_ranked(ranked, ScoreMatrix::F32(s), gt.clone(), matching))
            }
        }
    }

    /// A calibration that decides each query on its causal sequence-matched column
    /// (semantics §15, online sequence matching): [`Calibration::new`] of the scores
    /// matched by [`sequence_match`] with [`Sequence::causal`]`(length)` over the
    /// calibration traverse (its columns in order), with sequence length `length`. Every
    /// transfer and online state that uses it matches its deployment columns the same
    /// way; a calibration file keeps the matched scores and `length`. A length of 1 is
    /// [`Calibration::new`].
    ///
    /// # Errors
    /// As [`Calibration::new`]; a length that is even or 0
    /// ([`Error::InvalidParameter`] named `sequence`).
    pub fn new_sequence<'s, 'd: 's>(
        scores: impl Into<ScoreSource<'s, 'd>>,
        gt: &GroundTruth,
        matching: Matching,
        length: usize,
    ) -> Result<Self> {
        let sequence = Sequence::causal(length);
        sequence.validate()?;
        if length == 1 {
            return Self::new(scores, gt, matching);
        }
        let source = scores.into();
        let calibration = source.with_matrix(|s| {
            with_scores!(s, |s| {
                validate_scores(Input::CalSimilarity, s)?;
                let matched = sequence_match(s, sequence)?;
                Self::new(matched.view(), gt, matching)
            })
        })?;
        Ok(calibration.with_sequence(length))
    }

    /// The same calibration, its scores taken as matched over `length` (a calibration
    /// file's `params.sequence`, whose `s` is already matched).
    pub(crate) fn with_sequence(mut self, length: usize) -> Self {
        self.sequence = length;
        self
    }

    /// Its sequence length `L` (semantics §15): 1 (each query decided on its own
    /// column), or the causal sequence matching of [`Calibration::new_sequence`].
    pub fn sequence(&self) -> usize {
        self.sequence
    }

    /// Check a sequence length asked for against this calibration's: `None` (take the
    /// calibration's) or the same length. `L` belongs to the calibration (semantics §15):
    /// another one would decide on columns matched otherwise than the calibration's.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `sequence`, naming both lengths.
    pub fn check_sequence(&self, sequence: Option<usize>) -> Result<()> {
        match sequence {
            Some(length) if length != self.sequence => Err(Error::param(
                "sequence",
                format!(
                    "{length} is not the calibration's sequence length {}: the length belongs to the \
                     calibration, whose scores were matched over it (calibrate with that length instead)",
                    self.sequence
                ),
            )),
            _ => Ok(()),
        }
    }

    /// A calibration that only transfers: the same thresholds, neighbours and records as
    /// [`Calibration::new`] of the same input, bit for bit, but it keeps neither its
    /// scores nor its ground truth, so it cannot be saved. It takes the ground truth by
    /// value and drops it as soon as the candidates of semantics §2 are found.
    ///
    /// From descriptors, the |DB| x |Qcal| similarity is never held beside the ranked
    /// profiles: it is computed twice, a few columns at a time, once for the candidates
    /// (under the ground truth) and once straight into the profiles, where it is
    /// sorted. What such a calibration holds is then its profiles (4 bytes a score),
    /// their screen and its candidates; while it is built, the ground truth or the
    /// profiles, and a few columns.
    ///
    /// # Errors
    /// As [`Calibration::new`].
    pub fn for_transfer<'s, 'd: 's>(
        scores: impl Into<ScoreSource<'s, 'd>>,
        gt: GroundTruth,
        matching: Matching,
    ) -> Result<Self> {
        self_motion::check_matching(&gt, matching)?;
        match scores.into() {
            ScoreSource::Matrix(s) => with_scores!(s, |s| threads::install(|| {
                let ranked = Ranked::new(Input::CalSimilarity, s, 0)?;
                check_gt_shape(&gt, Input::CalSimilarity, s.dim())?;
                let candidates = Candidates::new(s, gt.view(), matching);
                Ok(Self::from_parts(ranked, candidates, matching, None))
            })),
            ScoreSource::Descriptors(d, queries) => {
                d.check_range(&queries)?;
                let n_db = d.shape().0;
                check_gt_shape(&gt, Input::CalSimilarity, (n_db, queries.len()))?;
                // Groups of about a chunk of scores, at least a tile of columns. Two
                // passes, so that the ground truth and the profiles are never held at
                // once: the candidates under the ground truth, then the profiles.
                let (n, width) = (queries.len(), (CHUNK_SCORES / n_db).max(TILE));
                let groups: Vec<Range<usize>> = (0..n).step_by(width).map(|a| a..(a + width).min(n)).collect();
                let mut columns = DescriptorColumns::new(d, queries.start);
                let mut candidates = Candidates::none();
                for r in &groups {
                    let mut group = Array2::zeros((n_db, r.len()).f());
                    columns.fill(r.clone(), group.view_mut());
                    let labels = gt.view().slice_move(ndarray::s![.., r.clone()]);
                    candidates.append(Candidates::new(group.view(), labels, matching));
                }
                drop(gt);
                let mut ranked = Ranked::with_capacity(Input::CalSimilarity, n_db, queries.len())?;
                let mut columns = DescriptorColumns::new(d, queries.start);
                for r in groups {
                    let (n, first) = (r.len(), r.start);
                    ranked.extend_with(Input::CalSimilarity, n, first, |out| {
                        columns.fill(r, column_major((n_db, n), out));
                    })?;
                }
                Ok(Self::from_parts(ranked, candidates, matching, None))
            }
        }
    }

    /// [`Calibration::for_transfer`] of a matrix, on labels already known to have the
    /// shape of `s` (the evaluation protocol's, never saved).
    pub(crate) fn with_labels<T: Score>(
        s: ArrayView2<'_, T>,
        gt: ArrayView2<'_, Truth>,
        matching: Matching,
    ) -> Result<Self> {
        let ranked = Ranked::new(Input::CalSimilarity, s, 0)?;
        Ok(Self::from_parts(
            ranked,
            Candidates::new(s, gt, matching),
            matching,
            None,
        ))
    }

    /// The calibration of profiles `ranked`; `scores` is the calibration similarity they
    /// were ranked from, kept to be saved with `gt`.
    fn from_ranked<T: Score>(ranked: Ranked<T>, scores: ScoreMatrix, gt: GroundTruth, matching: Matching) -> Self {
        let candidates = with_scores!(scores.view(), |s| Candidates::new(s, gt.view(), matching));
        Self::from_parts(ranked, candidates, matching, Some((scores, gt)))
    }

    /// The calibration of profiles `ranked` with their screen.
    fn from_parts<T: Score>(
        ranked: Ranked<T>,
        candidates: Candidates,
        matching: Matching,
        input: Option<(ScoreMatrix, GroundTruth)>,
    ) -> Self {
        Self {
            matching,
            screen: Screen::new(&ranked),
            n_db: ranked.view().nrows(),
            profiles: Box::new(ranked),
            candidates,
            input,
            defaults: Defaults::default(),
            sequence: 1,
            margins: OnceLock::new(),
            confidence: OnceLock::new(),
        }
    }

    /// The same calibration with the defaults a calibration file stores in its
    /// `params` (what `Calibration::load` gives a loaded one).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for `k` 0, a precision outside (0, 1], a window of 0,
    /// bad sequence gate parameters, or a gate the calibration cannot have
    /// ([`Calibration::check_gate`]).
    pub fn with_defaults(mut self, defaults: Defaults) -> Result<Self> {
        self.check_defaults(&defaults)?;
        self.defaults = defaults;
        Ok(self)
    }

    /// Check `defaults` for this calibration: [`Defaults::validate`], and a margin gate
    /// only where it applies (`margin::check`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the parameter.
    pub fn check_defaults(&self, defaults: &Defaults) -> Result<()> {
        defaults.validate()?;
        self.check_gate(defaults.gate, &defaults.sequence_gate)
    }

    /// Check that decisions on this calibration can be gated with `gate`, the sequence
    /// gate with `sequence` ([`check_gate`](crate::check_gate)).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the gate when one it enables does not apply
    /// (multi matching; the margin gate with |DB| < 2, the sequence gate on a database
    /// its widest tolerance covers).
    pub fn check_gate(&self, gate: Gate, sequence: &SequenceParams) -> Result<()> {
        gates::check(gate, sequence, self.matching, self.n_db)
    }

    /// How many queries before a deployment query its decision reads besides its own
    /// column (semantics §15), when `gate` has the sequence gate with `sequence`: its
    /// window (the previous best matches its consistency reads), and with a sequence
    /// length `L > 1` the `L - 1` raw columns before each matched one. What a block of a
    /// stream must be preceded by ([`Calibration::transfer_block`]); an online state adds
    /// its threshold window ([`crate::Online::lookback`]).
    pub fn lookback(&self, gate: Gate, sequence: &SequenceParams) -> usize {
        let consistency = if gate.sequence() { sequence.lookback() } else { 0 };
        consistency + (self.sequence - 1)
    }

    /// The defaults this calibration was loaded with ([`Defaults::default`] for one built
    /// by [`Calibration::new`]).
    pub fn defaults(&self) -> &Defaults {
        &self.defaults
    }

    /// |DB|: the number of database images (rows) of the calibration.
    pub fn db_size(&self) -> usize {
        self.n_db
    }

    /// The calibration similarity as given, |DB| x |Qcal|, in its own type (`None` for
    /// [`Calibration::for_transfer`], which does not keep it).
    pub fn scores(&self) -> Option<&ScoreMatrix> {
        self.input.as_ref().map(|(s, _)| s)
    }

    /// The calibration ground truth as given, hard with soft entries as ignored (`None`
    /// for [`Calibration::for_transfer`], which does not keep it).
    pub fn ground_truth(&self) -> Option<&GroundTruth> {
        self.input.as_ref().map(|(_, gt)| gt)
    }

    /// How the calibration's labels were made, when they are self-motion labels
    /// (semantics §16: a calibration file's `meta.labels`); `None` for other ground truth
    /// and for [`Calibration::for_transfer`], which does not keep it.
    pub fn labels(&self) -> Option<&LabelRecord> {
        self.ground_truth().and_then(GroundTruth::record)
    }

    /// Gather, check, sort and standardise the deployment columns `s` into `ranked`.
    /// `first_col` is the deployment index of `s`'s first column, for errors.
    pub(crate) fn rank<T: Score>(&self, ranked: &mut Ranked<T>, s: ArrayView2<'_, T>, first_col: usize) -> Result<()> {
        ranked.refill(Input::DeploymentSimilarity, s, first_col)
    }

    /// semantics §4 and §5 for every column of a block ranked by
    /// [`Calibration::rank`]: each query's `k` neighbours (their correlations computed
    /// in `f64` where the screen's bounds leave doubt) and weight, their
    /// subset threshold at `precision`, and its quantile (and its margin and PA-score
    /// as `wanted`, for the gate and the confidence). The one place a deployment
    /// query's `q_j` and `w_j` are computed, for the batch transfer and for
    /// [`crate::Online`] alike; in parallel over the block.
    pub(crate) fn queries<T: Score>(
        &self,
        ranked: &Ranked<T>,
        k: usize,
        precision: f64,
        wanted: Wanted,
    ) -> Vec<QueryTransfer> {
        threads::install(|| {
            (0..ranked.ncols())
                .into_par_iter()
                .map_init(
                    || vec![0.0; self.n_db],
                    |u, j| self.query(ranked, j, k, precision, wanted, u),
                )
                .collect()
        })
    }

    /// [`Calibration::queries`] for column `j` alone, with `u` (|DB| long) to hold its
    /// standardised profile.
    pub(crate) fn query<T: Score>(
        &self,
        ranked: &Ranked<T>,
        j: usize,
        k: usize,
        precision: f64,
        wanted: Wanted,
        u: &mut [f64],
    ) -> QueryTransfer {
        ranked.profile(j, u);
        let (neighbours, weight) = self
            .screen
            .top_k(u, k, |is, out| self.profiles.correlations(is, u, out));
        let threshold = subset_threshold(&self.candidates, &neighbours, precision);
        let quantile = self.profiles.quantile(&neighbours, threshold);
        QueryTransfer {
            neighbours,
            weight,
            threshold,
            quantile,
            gates: GateSignals {
                margin: wanted.margin.then(|| margin::of_sorted(ranked.column(j))),
                // Read from the stream, not the column: set where the stream is known.
                consistency: None,
            },
            pa_score: wanted
                .pa_score
                .then(|| confidence::pa_score_of_sorted(ranked.column(j))),
        }
    }

    /// Number of calibration queries.
    pub fn len(&self) -> usize {
        self.candidates.ncols()
    }

    /// Always false: a calibration has at least one query.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The matching mode the calibration was built for.
    pub fn matching(&self) -> Matching {
        self.matching
    }

    /// The semantics §3 threshold of the whole calibration set (today's practice of a
    /// threshold tuned once offline).
    ///
    /// # Errors
    /// tau outside (0, 1].
    pub fn threshold(&self, precision: f64) -> Result<f64> {
        check_precision(precision)?;
        let all: Vec<usize> = (0..self.len()).collect();
        Ok(subset_threshold(&self.candidates, &all, precision))
    }

    /// The margin gate `m*` of semantics §13 at precision target `precision`: the
    /// semantics §3 threshold of the calibration's single-match decisions with their
    /// margins in place of their scores (`+inf`: reject-all).
    ///
    /// # Errors
    /// A multi-match calibration or one of fewer than 2 database images
    /// (`margin::check`); tau outside (0, 1].
    pub fn gate(&self, precision: f64) -> Result<f64> {
        margin::check(self.matching, self.n_db)?;
        check_precision(precision)?;
        Ok(self.calibration_margins().gate(precision))
    }

    /// The calibration's single-match decisions with their margins, found on the first
    /// request for the gate. Single matching with |DB| >= 2 only.
    fn calibration_margins(&self) -> &CalibrationMargins {
        self.margins.get_or_init(|| {
            let of_columns: Vec<f64> = threads::install(|| {
                (0..self.len())
                    .into_par_iter()
                    .map(|i| self.profiles.margin(i))
                    .collect()
            });
            CalibrationMargins::new(&of_columns, &self.candidates)
        })
    }

    /// The confidence map of semantics §14: the centred isotonic fit of the
    /// calibration's single-match decisions (soft-only best matches left out) on their
    /// PA-scores, found on the first request. Without a decision it has no blocks, and
    /// gives NaN.
    ///
    /// # Errors
    /// A multi-match calibration or one of fewer than 2 database images
    /// (`confidence::check`).
    pub fn confidence_map(&self) -> Result<&ConfidenceMap> {
        confidence::check(self.matching, self.n_db)?;
        Ok(self.confidence.get_or_init(|| {
            let pa_scores: Vec<f64> = (0..self.len()).map(|i| self.profiles.pa_score(i)).collect();
            ConfidenceMap::fit(confidence::pairs(&pa_scores, &self.candidates))
        }))
    }

    /// The map when this calibration's decisions have a confidence (single matching,
    /// |DB| >= 2), else `None`: what a decision record reads.
    pub(crate) fn confidence_of_decisions(&self) -> Option<&ConfidenceMap> {
        self.confidence_map().ok()
    }

    /// The gates `gate` enables, each at its level on this calibration at precision
    /// target `precision` (the sequence gate's, `sequence`, fixed): what every decision
    /// of a transfer, an online state or the protocol is taken through ([`Gates`]).
    ///
    /// # Errors
    /// As [`Calibration::check_gate`]; tau outside (0, 1].
    pub(crate) fn gates(&self, gate: Gate, sequence: &SequenceParams, precision: f64) -> Result<Gates> {
        self.check_gate(gate, sequence)?;
        Ok(Gates {
            margin: gate
                .margin()
                .then(|| self.gate(precision).map(|level| MarginGate { level }))
                .transpose()?,
            sequence: gate.sequence().then_some(SequenceGate { params: *sequence }),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extensions::similarity::Descriptors;
    use crate::operations::transfer::tests::params;

    #[test]
    fn a_calibration_for_transfer_from_descriptors_is_built_a_group_at_a_time() {
        // |DB| = CHUNK_SCORES / TILE rows, so that a group is one tile of queries: 33
        // calibration queries are ranked in groups of 16, 16 and 1 (each group's
        // candidates first, under the ground truth), and transfer as the matrix path.
        let n_db = CHUNK_SCORES / TILE;
        let mut x = 11u64;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 1000) as f32 / 1000.0 - 0.5
        };
        let db = Array2::from_shape_fn((n_db, 3), |_| next());
        let q = Array2::from_shape_fn((50, 3), |_| next());
        let s = crate::extensions::similarity::cosine_similarity(db.view(), q.view()).unwrap();
        let d = Descriptors::new(db.view(), q.view()).unwrap();
        let gt = GroundTruth::new(Array2::from_shape_fn((n_db, 33), |(i, j)| i % 1000 == j).view()).unwrap();
        let p = params(5, Some(6));
        for matching in [Matching::Single, Matching::Multi] {
            let cal = Calibration::new(s.slice(ndarray::s![.., ..33]), &gt, matching).unwrap();
            let lean = Calibration::for_transfer(ScoreSource::Descriptors(&d, 0..33), gt.clone(), matching).unwrap();
            assert_eq!(lean.len(), 33);
            assert_eq!(lean.db_size(), n_db);
            let want = cal.transfer(s.slice(ndarray::s![.., 33..]), &p).unwrap();
            assert_eq!(lean.transfer(ScoreSource::Descriptors(&d, 33..50), &p).unwrap(), want);
            assert_eq!(lean.threshold(1.0).unwrap(), cal.threshold(1.0).unwrap());
        }
    }
}
