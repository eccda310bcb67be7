//! Which way round a similarity matrix was read, and what its ground truth says of that:
//! the orientation of semantics §1.
//!
//! The core computes on |DB| x |Q| views; VPR-Bench stores |Q| x |DB|, and a front end's
//! switch (`--query-major`, `query_major=True`) says which. A matrix read the wrong way
//! round is still a valid matrix, so the switch cannot be checked, only weighed:
//!
//! - **Shapes.** Ground truth or positions that fit only the transpose of the
//!   similarity, or a calibration count beyond |Q| but within |DB|, are errors; [`hint`]
//!   says when such an error is the usual sign of a forgotten (or wrong) switch.
//! - **Content.** Ground truth read from a file is transposed with the similarity, so
//!   its shape fits either way. Its positives still tell: in a VPR traverse nearly every
//!   query has a positive, while database images outside the queries' route have none.
//!   [`Evidence`] counts both; when every database image has a positive and many
//!   queries have none, the transposed layout is the likelier one, and
//!   [`Orientation::warning`] says so.
//! - **What cannot tell.** A square matrix with ground truth that is symmetric in its
//!   counts (an identity, a band `|i - j| <= n`: every VPR-Bench and Nordland matrix of
//!   `../shared/data`), or ground truth made for the matrix as read (a frame tolerance,
//!   positions whose counts fit both ways): then nothing distinguishes the two layouts.
//!
//! Every front end reports the [`Orientation`] it assumed (the `orientation` key of
//! `evaluate` and `threshold`, with its `layout` in words: confirmed by the ground truth,
//! assumed, or contradicted: [`Orientation::layout`]) and prints its messages, naming its
//! own switch.

use crate::error::Error;
use crate::error::names::Input;
use crate::input::{GroundTruth, Truth};

/// The share of queries without a positive from which, every database image having
/// one, the ground truth contradicts the layout read (and the reverse): 1 in 20.
pub const CONTRADICTION_SHARE: f64 = 0.05;

/// What a front end assumed of a similarity matrix's orientation, and what its ground
/// truth says of it.
///
/// Serialised (feature `serde`) as `{"db": 111, "queries": 100, "query_major": false,
/// "layout": "assumed (...)"}` ([`Orientation::layout`]), with `"evidence"` when ground
/// truth read in the matrix's orientation was given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize), serde(into = "serialize::Document"))]
pub struct Orientation {
    /// |DB|: rows of the |DB| x |Q| view computed on.
    pub db: usize,
    /// |Q|: its columns.
    pub queries: usize,
    /// Whether the matrix was stored query-major (|Q| x |DB|) and read transposed.
    pub query_major: bool,
    /// What the ground truth's positives say ([`Evidence::of`]); `None` (left out of
    /// the JSON) without ground truth read in the matrix's orientation.
    pub evidence: Option<Evidence>,
}

/// The positives of ground truth, counted along both axes of the |DB| x |Q| view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Evidence {
    /// The query columns the ground truth labels (all of |Q|, or the calibration
    /// queries of `threshold --cal`).
    pub labelled_queries: usize,
    /// Of them, those without a hard positive.
    pub queries_without_positive: usize,
    /// Database images (rows) without a hard positive among those queries.
    pub db_without_positive: usize,
    /// What the counts say of the layout read.
    pub verdict: Verdict,
}

/// What ground truth's positives say of the layout read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize), serde(rename_all = "kebab-case"))]
pub enum Verdict {
    /// Every query has a positive and at least [`CONTRADICTION_SHARE`] of the
    /// database images have none: a VPR traverse read the right way round.
    Consistent,
    /// Neither pattern: both axes have a positive everywhere (an identity or band
    /// ground truth), or both have gaps.
    CannotTell,
    /// Every database image has a positive and at least [`CONTRADICTION_SHARE`] of the
    /// queries (and at least one) have none: the transposed layout is the likelier.
    Contradicts,
}

impl Evidence {
    /// Count the positives of `gt` (|DB| x |Q| as computed on; soft-only entries are
    /// not positives) and weigh them.
    pub fn of(gt: &GroundTruth) -> Self {
        let view = gt.view();
        let (n_db, n_q) = view.dim();
        let positive = |t: &Truth| *t == Truth::True;
        let queries_without_positive = view.columns().into_iter().filter(|c| !c.iter().any(positive)).count();
        let db_without_positive = view.rows().into_iter().filter(|r| !r.iter().any(positive)).count();
        let many = |without: usize, of: usize| without >= 1 && without as f64 >= CONTRADICTION_SHARE * of as f64;
        let verdict = if db_without_positive == 0 && many(queries_without_positive, n_q) {
            Verdict::Contradicts
        } else if queries_without_positive == 0 && many(db_without_positive, n_db) {
            Verdict::Consistent
        } else {
            Verdict::CannotTell
        };
        Self {
            labelled_queries: n_q,
            queries_without_positive,
            db_without_positive,
            verdict,
        }
    }
}

impl Orientation {
    /// The orientation of a similarity matrix whose |DB| x |Q| view has `shape`, read
    /// query-major when `query_major`, with no evidence.
    pub fn new((db, queries): (usize, usize), query_major: bool) -> Self {
        Self {
            db,
            queries,
            query_major,
            evidence: None,
        }
    }

    /// [`Orientation::new`] with the evidence of `gt`: ground truth read from a file in
    /// the matrix's orientation (transposed with it), labelling the same database
    /// images (all queries, or the first ones). Ground truth made for the matrix as read
    /// (a frame tolerance, positions) says nothing of the orientation: pass `None`. So
    /// does ground truth of another number of database images (an error elsewhere).
    pub fn of(shape: (usize, usize), gt: Option<&GroundTruth>, query_major: bool) -> Self {
        Self {
            evidence: gt.filter(|gt| gt.dim().0 == shape.0).map(Evidence::of),
            ..Self::new(shape, query_major)
        }
    }

    /// One line for a table, naming the front end's `switch`: `|DB| 111 x |Q| 100
    /// (DB-major; pass --query-major for VPR-Bench files), confirmed by the ground truth
    /// (...)`, the layout as [`Orientation::layout`] says it.
    pub fn describe(&self, switch: &str) -> String {
        let how = if self.query_major {
            format!("read transposed: {switch}, VPR-Bench's layout")
        } else {
            format!("DB-major; pass {switch} for VPR-Bench files")
        };
        format!("|DB| {} x |Q| {} ({how}), {}", self.db, self.queries, self.layout())
    }

    /// Whether the layout read was confirmed by the ground truth or assumed, in words a
    /// user reads, with what the ground truth showed: "confirmed by the ground truth
    /// (...)", "assumed (the ground truth cannot tell: ...)", "assumed (no ground truth
    /// was read in the matrix's layout to tell)" or "contradicted by the ground truth
    /// (...)" (the `layout` key of the JSON).
    pub fn layout(&self) -> String {
        let Some(e) = self.evidence else {
            return "assumed (no ground truth was read in the matrix's layout to tell)".to_string();
        };
        let (q, n_q, d, n_db) = (
            e.queries_without_positive,
            e.labelled_queries,
            e.db_without_positive,
            self.db,
        );
        match e.verdict {
            Verdict::Consistent => format!(
                "confirmed by the ground truth (every query has a positive; database images without one: {d} \
                 of {n_db})"
            ),
            Verdict::CannotTell if q == 0 && d == 0 => {
                "assumed (the ground truth cannot tell: every query and every database image has a positive)"
                    .to_string()
            }
            Verdict::CannotTell => format!(
                "assumed (the ground truth cannot tell: queries without a positive: {q} of {n_q}; database \
                 images without one: {d} of {n_db})"
            ),
            Verdict::Contradicts => format!(
                "contradicted by the ground truth (queries without a positive: {q} of {n_q}, while every \
                 database image has one)"
            ),
        }
    }

    /// The warning to print when the evidence contradicts the layout read, naming the
    /// front end's `switch`; `None` otherwise.
    pub fn warning(&self, switch: &str) -> Option<String> {
        let e = self.evidence.filter(|e| e.verdict == Verdict::Contradicts)?;
        let read = if self.query_major { "read query-major, " } else { "" };
        let advice = if self.query_major {
            format!("the matrices may be |DB| x |Q| already; if so, leave out {switch}")
        } else {
            format!("the matrices may be query-major (|Q| x |DB|, as VPR-Bench stores them); if so, pass {switch}")
        };
        Some(format!(
            "{read}the layout is contradicted by the ground truth: {} of the {} queries have no positive in it \
             while every one of the {} database images has one; a VPR traverse is usually the other way round, \
             so {advice}",
            e.queries_without_positive, e.labelled_queries, self.db
        ))
    }
}

/// The serialisation of [`Orientation`]: its fields and its [`Orientation::layout`].
#[cfg(feature = "serde")]
mod serialize {
    use super::{Evidence, Orientation};

    /// What an [`Orientation`] serialises as.
    #[derive(serde::Serialize)]
    pub(super) struct Document {
        db: usize,
        queries: usize,
        query_major: bool,
        layout: String,
        #[serde(skip_serializing_if = "Option::is_none")]
        evidence: Option<Evidence>,
    }

    impl From<Orientation> for Document {
        fn from(o: Orientation) -> Self {
            Self {
                db: o.db,
                queries: o.queries,
                query_major: o.query_major,
                layout: o.layout(),
                evidence: o.evidence,
            }
        }
    }
}

/// Advice for an error that is the usual sign of a matrix read the wrong way round,
/// naming the front end's `switch` (`--query-major`, `query_major=True`); `None` for
/// any other error. Append it to the error's message (`"{err}; {hint}"`). Shapes are
/// compared in either orientation, so `err` may be oriented back or not.
///
/// - calibration and deployment similarity of different |DB|, not read query-major;
/// - ground truth shaped like the transpose of a (non-square) similarity: one of the
///   two is query-major and the other not, and the switch transposes both;
/// - positions whose counts fit the transpose of the similarity;
/// - a calibration count beyond |Q| but within |DB|.
pub fn hint(err: &Error, query_major: bool, switch: &str) -> Option<String> {
    let flip = |what: &str| {
        if query_major {
            format!("read query-major, {what}: if it is |DB| x |Q|, leave out {switch}")
        } else {
            format!("{what}: if it is query-major (|Q| x |DB|, as VPR-Bench stores them), pass {switch}")
        }
    };
    let transposed = |a: (usize, usize), b: (usize, usize)| a.0 != a.1 && a == (b.1, b.0);
    let similarity = |input: Input| {
        matches!(
            input,
            Input::Similarity | Input::CalSimilarity | Input::DeploymentSimilarity
        )
    };
    match err {
        Error::InFile { error, .. } => hint(error, query_major, switch),
        Error::DatabaseMismatch { .. } if !query_major => Some(format!(
            "if the matrices are query-major (|Q| x |DB|, as VPR-Bench stores them), pass {switch}"
        )),
        Error::ShapeMismatch {
            what: Input::GroundTruth | Input::SoftGroundTruth,
            shape,
            other,
            other_shape,
        } if similarity(*other) && transposed(*shape, *other_shape) => Some(transposed_truth(switch)),
        Error::SplitTruthShape {
            shape,
            similarity_shape,
            ..
        } if transposed(*shape, *similarity_shape) => Some(transposed_truth(switch)),
        Error::PositionCount { db, queries, shape } if transposed((*db, *queries), *shape) => Some(flip(&format!(
            "the similarity matrix is the transpose of {db} database x {queries} query positions"
        ))),
        Error::CalibrationSize {
            calibration,
            queries,
            database: Some(database),
        } if calibration >= queries && calibration < database => Some(flip(&format!(
            "the similarity has {database} database images but only {queries} queries"
        ))),
        _ => None,
    }
}

/// The advice for ground truth shaped like the similarity's transpose.
fn transposed_truth(switch: &str) -> String {
    format!(
        "the ground truth is the similarity's transpose (|Q| x |DB| against |DB| x |Q|): one of the two is \
         stored query-major and the other not, and {switch} reads both query-major; transpose the one that is"
    )
}

#[cfg(test)]
mod tests {
    use ndarray::{Array2, array};

    use super::*;

    /// Ground truth of `n_db` x `n_q` where query j matches database images j-1..=j+1
    /// (a band, as a frame tolerance of 1 makes it).
    fn band(n_db: usize, n_q: usize) -> GroundTruth {
        GroundTruth::new(Array2::from_shape_fn((n_db, n_q), |(i, j)| i.abs_diff(j) <= 1).view()).unwrap()
    }

    #[test]
    fn a_traverse_read_the_right_way_round_is_consistent() {
        // 30 database images, 20 queries, query j matches j-1..=j+1: every query has a
        // positive; database images 21..29 (9 of 30 = 30% >= 5%) have none.
        let e = Evidence::of(&band(30, 20));
        assert_eq!(
            e,
            Evidence {
                labelled_queries: 20,
                queries_without_positive: 0,
                db_without_positive: 9,
                verdict: Verdict::Consistent
            }
        );
        let o = Orientation::of((30, 20), Some(&band(30, 20)), false);
        assert_eq!(o.warning("--query-major"), None);
        assert_eq!(
            o.describe("--query-major"),
            "|DB| 30 x |Q| 20 (DB-major; pass --query-major for VPR-Bench files), confirmed by the ground truth \
             (every query has a positive; database images without one: 9 of 30)"
        );
    }

    #[test]
    fn the_same_traverse_transposed_contradicts() {
        // Read transposed: 20 "database images" (the queries) all have a positive, and
        // 9 of the 30 "queries" have none: 9 >= 0.05 * 30 = 1.5.
        let gt = GroundTruth::from_truth(band(30, 20).view().t().to_owned());
        let o = Orientation::of((20, 30), Some(&gt), false);
        assert_eq!(
            o.evidence,
            Some(Evidence {
                labelled_queries: 30,
                queries_without_positive: 9,
                db_without_positive: 0,
                verdict: Verdict::Contradicts
            })
        );
        assert_eq!(
            o.warning("--query-major").unwrap(),
            "the layout is contradicted by the ground truth: 9 of the 30 queries have no positive in it while \
             every one of the 20 database images has one; a VPR traverse is usually the other way round, so the \
             matrices may be query-major (|Q| x |DB|, as VPR-Bench stores them); if so, pass --query-major"
        );
        assert_eq!(
            o.layout(),
            "contradicted by the ground truth (queries without a positive: 9 of 30, while every database image \
             has one)"
        );
        // The same layout reached by a wrong switch: the advice is to leave it out.
        let o = Orientation::of((20, 30), Some(&gt), true);
        assert!(
            o.warning("query_major=True")
                .unwrap()
                .ends_with("the matrices may be |DB| x |Q| already; if so, leave out query_major=True")
        );
        assert!(
            o.describe("query_major=True")
                .starts_with("|DB| 20 x |Q| 30 (read transposed: query_major=True, VPR-Bench's layout), contradicted")
        );
    }

    #[test]
    fn symmetric_ground_truth_cannot_tell() {
        // A square band and an identity: every row and column has a positive. The layout
        // read is then assumed, and every output says so and why (the same words for
        // the transposed copy, which the ground truth cannot tell apart either).
        assert_eq!(Evidence::of(&band(5, 5)).verdict, Verdict::CannotTell);
        for query_major in [false, true] {
            let o = Orientation::of((5, 5), Some(&band(5, 5)), query_major);
            assert_eq!(
                o.layout(),
                "assumed (the ground truth cannot tell: every query and every database image has a positive)"
            );
            assert!(o.describe("--query-major").ends_with(&format!("), {}", o.layout())));
        }
        // Without ground truth read in the matrix's layout (a frame tolerance, none).
        assert_eq!(
            Orientation::new((5, 5), false).layout(),
            "assumed (no ground truth was read in the matrix's layout to tell)"
        );
        let identity = GroundTruth::new(Array2::from_shape_fn((4, 4), |(i, j)| i == j).view()).unwrap();
        assert_eq!(Evidence::of(&identity).verdict, Verdict::CannotTell);
        // Gaps on both axes: query 2 and database image 0 have no positive.
        let gt = GroundTruth::new(array![[0u8, 0, 0], [1, 0, 0], [0, 1, 0]].view()).unwrap();
        let e = Evidence::of(&gt);
        assert_eq!((e.queries_without_positive, e.db_without_positive), (1, 1));
        assert_eq!(e.verdict, Verdict::CannotTell);
        assert_eq!(
            Orientation::of((3, 3), Some(&gt), false).layout(),
            "assumed (the ground truth cannot tell: queries without a positive: 1 of 3; database images \
             without one: 1 of 3)"
        );
    }

    #[test]
    fn a_few_queries_without_a_positive_are_not_enough() {
        // 1 of 40 queries without, every database image with one: 1 < 0.05 * 40 = 2.
        let gt = GroundTruth::new(Array2::from_shape_fn((39, 40), |(i, j)| i == j).view()).unwrap();
        let e = Evidence::of(&gt);
        assert_eq!((e.queries_without_positive, e.db_without_positive), (1, 0));
        assert_eq!(e.verdict, Verdict::CannotTell);
        // 2 of 40: 2 >= 2, it contradicts.
        let gt = GroundTruth::new(Array2::from_shape_fn((38, 40), |(i, j)| i == j).view()).unwrap();
        assert_eq!(Evidence::of(&gt).verdict, Verdict::Contradicts);
    }

    #[test]
    fn soft_only_entries_are_not_positives() {
        // Query 1's only label is soft: it has no positive. 1 of 2 queries without, every
        // database image (just image 0, a positive of query 0) with one: contradicts.
        let gt = GroundTruth::new(array![[1u8, 0]].view())
            .unwrap()
            .with_soft(array![[1u8, 1]].view())
            .unwrap();
        let e = Evidence::of(&gt);
        assert_eq!((e.queries_without_positive, e.db_without_positive), (1, 0));
        assert_eq!(e.verdict, Verdict::Contradicts);
    }

    #[test]
    fn ground_truth_of_other_database_images_gives_no_evidence() {
        assert_eq!(Orientation::of((31, 20), Some(&band(30, 20)), false).evidence, None);
        assert_eq!(
            Orientation::of((30, 20), None, false),
            Orientation::new((30, 20), false)
        );
    }

    #[test]
    fn hints_for_the_errors_of_a_forgotten_switch() {
        let switch = "--query-major";
        let mismatch = Error::DatabaseMismatch {
            calibration: 2,
            deployment: 3,
        };
        assert_eq!(
            hint(&mismatch, false, switch).unwrap(),
            "if the matrices are query-major (|Q| x |DB|, as VPR-Bench stores them), pass --query-major"
        );
        // Given the switch, the hint would be wrong.
        assert_eq!(hint(&mismatch, true, switch), None);

        let truth = Error::ShapeMismatch {
            what: Input::GroundTruth,
            shape: (100, 111),
            other: Input::Similarity,
            other_shape: (111, 100),
        };
        let advice = "the ground truth is the similarity's transpose (|Q| x |DB| against |DB| x |Q|): one of the \
                      two is stored query-major and the other not, and --query-major reads both query-major; \
                      transpose the one that is";
        assert_eq!(hint(&truth, false, switch).unwrap(), advice);
        assert_eq!(hint(&truth.clone().transposed(), true, switch).unwrap(), advice);
        // A square matrix, or shapes that are not transposes: no hint.
        let square = Error::ShapeMismatch {
            what: Input::GroundTruth,
            shape: (3, 3),
            other: Input::Similarity,
            other_shape: (3, 3),
        };
        assert_eq!(hint(&square, false, switch), None);
        let other = Error::ShapeMismatch {
            what: Input::GroundTruth,
            shape: (100, 112),
            other: Input::Similarity,
            other_shape: (111, 100),
        };
        assert_eq!(hint(&other, false, switch), None);
        // Soft against hard ground truth is not about orientation.
        let soft = Error::ShapeMismatch {
            what: Input::SoftGroundTruth,
            shape: (2, 1),
            other: Input::GroundTruth,
            other_shape: (1, 2),
        };
        assert_eq!(hint(&soft, false, switch), None);
        let split = Error::SplitTruthShape {
            shape: (4, 2),
            similarity_shape: (2, 4),
            calibration: 1,
        };
        assert_eq!(hint(&split, false, switch).unwrap(), advice);
        let inside = Error::InFile {
            path: "GT.npy".into(),
            error: Box::new(split),
        };
        assert_eq!(hint(&inside, false, switch).unwrap(), advice);

        let positions = Error::PositionCount {
            db: 111,
            queries: 100,
            shape: (100, 111),
        };
        assert_eq!(
            hint(&positions, false, switch).unwrap(),
            "the similarity matrix is the transpose of 111 database x 100 query positions: if it is query-major \
             (|Q| x |DB|, as VPR-Bench stores them), pass --query-major"
        );
        assert_eq!(
            hint(&positions, true, "query_major=True").unwrap(),
            "read query-major, the similarity matrix is the transpose of 111 database x 100 query positions: if \
             it is |DB| x |Q|, leave out query_major=True"
        );
    }

    #[test]
    fn a_calibration_count_beyond_the_queries_but_within_the_database() {
        // 111 database images x 11 queries (a query-major 11 x 111 read as is):
        // --cal-queries 50 is beyond |Q| = 11 but within |DB| = 111.
        let err = |calibration| Error::CalibrationSize {
            calibration,
            queries: 11,
            database: Some(111),
        };
        assert_eq!(
            err(50).to_string(),
            "the calibration set must have between 1 and 10 of the 11 queries, got 50"
        );
        assert_eq!(
            hint(&err(50), false, "--query-major").unwrap(),
            "the similarity has 111 database images but only 11 queries: if it is query-major (|Q| x |DB|, as \
             VPR-Bench stores them), pass --query-major"
        );
        // 11 is beyond |Q| - 1 and within |DB|: hinted. Beyond |DB| too, or no |DB|
        // known: no hint.
        assert!(hint(&err(11), false, "--query-major").is_some());
        assert_eq!(hint(&err(111), false, "--query-major"), None);
        let unknown = Error::CalibrationSize {
            calibration: 50,
            queries: 11,
            database: None,
        };
        assert_eq!(hint(&unknown, false, "--query-major"), None);
    }

    /// Whether [`hint`] must advise on `err`, read the wrong way round. The match has
    /// no `_` arm: a new variant does not compile here until it is classified, and a
    /// variant classified as advised fails the test below if [`hint`] has no advice.
    fn advised(err: &Error) -> bool {
        match err {
            // The shape errors an orientation explains.
            Error::ShapeMismatch { .. }
            | Error::DatabaseMismatch { .. }
            | Error::SplitTruthShape { .. }
            | Error::CalibrationSize { .. }
            | Error::PositionCount { .. } => true,
            Error::InFile { error, .. } => advised(error),
            // Shape errors no switch of orientation explains: one pushed column (no
            // matrix), descriptor dimensions and coordinates per position (columns of
            // the extensions' inputs, read the same way whatever the switch), an empty
            // matrix (empty either way round).
            Error::ColumnLength { .. }
            | Error::ColumnMismatch { .. }
            | Error::PositionColumns { .. }
            | Error::Empty { .. }
            // Not about shapes.
            | Error::NotFinite { .. }
            | Error::BadLabel { .. }
            | Error::Io { .. }
            | Error::Write { .. }
            | Error::File { .. }
            | Error::Allocation { .. }
            | Error::Dtype { .. }
            | Error::UnknownMethod { .. }
            | Error::Protocol(_)
            | Error::InvalidParameter { .. }
            | Error::ZeroNorm { .. }
            | Error::ImageName { .. } => false,
        }
    }

    #[test]
    fn every_shape_error_an_orientation_explains_has_advice() {
        let errors = [
            Error::ShapeMismatch {
                what: Input::GroundTruth,
                shape: (111, 100),
                other: Input::CalSimilarity,
                other_shape: (100, 111),
            },
            Error::DatabaseMismatch {
                calibration: 111,
                deployment: 120,
            },
            Error::SplitTruthShape {
                shape: (4, 2),
                similarity_shape: (2, 4),
                calibration: 1,
            },
            Error::CalibrationSize {
                calibration: 50,
                queries: 11,
                database: Some(111),
            },
            Error::PositionCount {
                db: 111,
                queries: 100,
                shape: (100, 111),
            },
            Error::ColumnLength {
                query: 0,
                len: 3,
                db: 4,
            },
            Error::ColumnMismatch {
                what: Input::QueryDescriptors,
                cols: 3,
                other: Input::DbDescriptors,
                other_cols: 4,
            },
            Error::PositionColumns {
                what: Input::DbPositions,
                cols: 5,
            },
            Error::Empty {
                what: Input::Similarity,
                rows: 0,
                cols: 3,
            },
            Error::NotFinite {
                what: Input::Similarity,
                row: 0,
                col: 0,
                value: f64::NAN,
            },
            Error::BadLabel {
                what: Input::GroundTruth,
                row: 0,
                col: 0,
                value: 2,
            },
            Error::Io {
                path: "s.npy".into(),
                kind: std::io::ErrorKind::NotFound,
                message: "not found".into(),
            },
            Error::Write {
                path: "out.json".into(),
                kind: std::io::ErrorKind::PermissionDenied,
                message: "denied".into(),
            },
            Error::File {
                path: "s.npy".into(),
                message: "is truncated".into(),
            },
            Error::Allocation {
                bytes: 1 << 40,
                what: "s.npy".into(),
            },
            Error::Dtype {
                path: "s.npy".into(),
                dtype: "<c16".into(),
                expected: "expected float32 or float64 scores",
            },
            Error::UnknownMethod {
                name: "x".into(),
                expected: vec!["qt"],
            },
            Error::Protocol("no full segment".into()),
            Error::InvalidParameter {
                name: "k",
                message: "must be >= 1, got 0".into(),
            },
            Error::ZeroNorm {
                what: Input::DbDescriptors,
                row: 0,
            },
            Error::ImageName {
                at: crate::error::NameAt::Index(0),
                name: "a.jpg".into(),
                problem: "has fewer than two '@'".into(),
            },
        ];
        let mut with_advice = 0;
        for err in errors {
            let nested = Error::InFile {
                path: "GT.npz".into(),
                error: Box::new(err.clone()),
            };
            for err in [err, nested] {
                // Each example is what a forgotten switch gives: advice to pass it.
                let given = hint(&err, false, "--query-major");
                assert_eq!(given.is_some(), advised(&err), "{err:?}: {given:?}");
                if let Some(advice) = given {
                    assert!(advice.contains("--query-major"), "{advice}");
                    with_advice += 1;
                }
            }
        }
        // Five variants, alone and inside a file.
        assert_eq!(with_advice, 10);
    }
}
