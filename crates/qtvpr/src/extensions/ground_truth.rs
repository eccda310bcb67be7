//! Extension (not a section of the semantics): ground truth from frame tolerance or from positions.
//!
//! Datasets rarely ship a ground-truth matrix. They ship either frame-aligned traverses
//! (Nordland, SFU, Oxford: query `j` shows the place of database image `j`, give or take
//! a few frames) or positions (UTM east/north, a match within 25 m). These functions make
//! the |DB| x |Q| bool matrix of semantics §1 from either. A soft ground truth
//! (VPR_Tutorial's `GTsoft`) is the same function with a larger tolerance or radius.
//!
//! [`GtSpec::matrices`] is the one place that turns "a tolerance or positions" (hard and
//! optional soft) into ground truth of a given shape; every front end goes through it.
//!
//! - [`within_tolerance`]: `GT[i, j] = |i - j| <= tolerance`.
//! - [`within_radius`]: `GT[i, j] = |db[i] - q[j]|² <= radius²`, inclusive, with the
//!   squared distance computed exactly as NumPy's brute force
//!   `((db[:, None] - q[None]) ** 2).sum(-1) <= radius * radius` computes it on float64
//!   coordinates, so that points at the radius agree to the last bit. A k-d tree over
//!   the queries (exact pruning, see the private `kd_tree` module) finds the candidates in O(log |Q|) per
//!   database position plus the matches; the rows are filled in parallel.

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::extensions::kd_tree::KdTree;
use crate::input::{GroundTruth, Score, ScoresView, check_nonempty};
use crate::platform::threads;

/// Ground truth without a matrix of it: a frame tolerance or positions, each with an
/// optional soft counterpart (VPR_Tutorial's `GTsoft`) that must include the hard.
#[derive(Debug, Clone, Copy)]
pub enum GtSpec<'a> {
    /// Frame-aligned traverses: `|i - j| <= hard` (soft: `<= soft`), see [`within_tolerance`].
    Tolerance {
        /// Hard tolerance, in frames.
        hard: usize,
        /// Soft tolerance, `>= hard`.
        soft: Option<usize>,
    },
    /// Positions within a radius, see [`within_radius`].
    Positions {
        /// Database positions, |DB| x 2 or x 3.
        db: ScoresView<'a>,
        /// Query positions, |Q| x the same.
        queries: ScoresView<'a>,
        /// Hard radius.
        radius: f64,
        /// Soft radius, `>= radius`.
        soft_radius: Option<f64>,
    },
}

/// Hard ground truth and, if asked for, soft ground truth, as bool matrices
/// (what [`GtSpec::matrices`] makes, and what a `.npz` in the VPR_Tutorial convention
/// holds as `GThard` and `GTsoft`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HardSoft {
    /// Hard ground truth, |DB| x |Q|.
    pub hard: Array2<bool>,
    /// Soft ground truth (a superset of `hard`), if asked for.
    pub soft: Option<Array2<bool>>,
}

impl HardSoft {
    /// The core's [`GroundTruth`] of these labels.
    ///
    /// # Errors
    /// [`Error::Empty`] for empty matrices (which [`GtSpec::matrices`] never makes).
    pub fn into_ground_truth(self) -> Result<GroundTruth> {
        let gt = GroundTruth::new(self.hard.view())?;
        match &self.soft {
            Some(soft) => gt.with_soft(soft.view()),
            None => Ok(gt),
        }
    }
}

impl GtSpec<'_> {
    /// The hard and soft ground truth of the spec, |DB| x |Q|.
    ///
    /// `shape` is the shape the ground truth must have (that of the similarity matrix it
    /// labels, |DB| x |Q|): required for a tolerance, and checked against the number
    /// of positions when given.
    ///
    /// # Errors
    /// - [`Error::InvalidParameter`] for a soft tolerance or radius below the hard one
    ///   (`soft tolerance` / `soft radius`), a bad radius ([`check_radius`]), or a
    ///   tolerance without a `shape`;
    /// - [`Error::PositionCount`] when the positions do not make `shape`;
    /// - the errors of [`within_tolerance`] and [`within_radius`].
    pub fn matrices(&self, shape: Option<(usize, usize)>) -> Result<HardSoft> {
        match *self {
            GtSpec::Tolerance { hard, soft } => {
                let Some((n_db, n_q)) = shape else {
                    return Err(Error::param(
                        "tolerance",
                        "needs the shape |DB| x |Q| of the ground truth",
                    ));
                };
                if let Some(soft) = soft
                    && soft < hard
                {
                    return Err(Error::param(
                        "soft tolerance",
                        format!("{soft} is smaller than the tolerance {hard}; soft ground truth must include the hard"),
                    ));
                }
                Ok(HardSoft {
                    hard: within_tolerance(n_db, n_q, hard)?,
                    soft: soft.map(|t| within_tolerance(n_db, n_q, t)).transpose()?,
                })
            }
            GtSpec::Positions {
                db,
                queries,
                radius,
                soft_radius,
            } => {
                check_radius("radius", radius)?;
                if let Some(soft) = soft_radius {
                    check_radius("soft radius", soft)?;
                    if soft < radius {
                        return Err(Error::param(
                            "soft radius",
                            format!(
                                "{soft} is smaller than the radius {radius}; soft ground truth must include the hard"
                            ),
                        ));
                    }
                }
                let counts = (db.dim().0, queries.dim().0);
                if let Some(shape) = shape
                    && counts != shape
                {
                    return Err(Error::PositionCount {
                        db: counts.0,
                        queries: counts.1,
                        shape,
                    });
                }
                let within = |r: f64| with_scores!(db, |d| with_scores!(queries, |q| within_radius(d, q, r)));
                Ok(HardSoft {
                    hard: within(radius)?,
                    soft: soft_radius.map(within).transpose()?,
                })
            }
        }
    }

    /// [`GtSpec::matrices`] of a similarity matrix of shape `shape`, as the core's
    /// [`GroundTruth`].
    ///
    /// # Errors
    /// As [`GtSpec::matrices`].
    pub fn ground_truth(&self, shape: (usize, usize)) -> Result<GroundTruth> {
        self.matrices(Some(shape))?.into_ground_truth()
    }
}

/// Ground truth of frame-aligned traverses: `GT[i, j] = |i - j| <= tolerance`, shape
/// `n_db` x `n_queries`.
///
/// # Errors
/// [`Error::Empty`] when either count is 0.
pub fn within_tolerance(n_db: usize, n_queries: usize, tolerance: usize) -> Result<Array2<bool>> {
    threads::install(|| {
        check_nonempty(Input::GroundTruth, (n_db, n_queries))?;
        let mut gt = vec![false; n_db * n_queries];
        gt.par_chunks_mut(n_queries).enumerate().for_each(|(i, row)| {
            let first = i.saturating_sub(tolerance);
            let last = i.saturating_add(tolerance).min(n_queries - 1);
            if first <= last {
                row[first..=last].fill(true);
            }
        });
        Ok(Array2::from_shape_vec((n_db, n_queries), gt).expect("shape matches length"))
    })
}

/// Ground truth from positions: `GT[i, j]` is true when database position `i` is within
/// `radius` of query position `j` (distance `<= radius`, inclusive).
///
/// `db` (|DB| x K) and `queries` (|Q| x K) hold one position per row, K = 2 (x, y: e.g.
/// UTM east, north) or 3 (x, y, z), `f32` or `f64` (widened to `f64`), any strides.
/// See the module docs of `extensions/ground_truth.rs` for the exact arithmetic.
///
/// # Errors
/// - [`Error::InvalidParameter`] when `radius` is negative or not finite;
/// - [`Error::Empty`] for a matrix without rows or columns;
/// - [`Error::PositionColumns`] when K is not 2 or 3;
/// - [`Error::ColumnMismatch`] when the two matrices have a different K;
/// - [`Error::NotFinite`] for a NaN or infinite coordinate.
pub fn within_radius<T: Score, U: Score>(
    db: ArrayView2<'_, T>,
    queries: ArrayView2<'_, U>,
    radius: f64,
) -> Result<Array2<bool>> {
    check_radius("radius", radius)?;
    check_positions(Input::DbPositions, db.view())?;
    check_positions(Input::QueryPositions, queries.view())?;
    if queries.ncols() != db.ncols() {
        return Err(Error::ColumnMismatch {
            what: Input::QueryPositions,
            cols: queries.ncols(),
            other: Input::DbPositions,
            other_cols: db.ncols(),
        });
    }
    let r2 = radius * radius;
    Ok(match db.ncols() {
        2 => fill::<2, T, U>(db, queries, r2),
        _ => fill::<3, T, U>(db, queries, r2),
    })
}

/// Check that a radius is finite and `>= 0`; `name` is the parameter as a user spells it.
///
/// # Errors
/// [`Error::InvalidParameter`] named `name`.
pub fn check_radius(name: &'static str, radius: f64) -> Result<()> {
    if !(radius.is_finite() && radius >= 0.0) {
        return Err(Error::param(
            name,
            format!("must be a finite number >= 0, got {radius}"),
        ));
    }
    Ok(())
}

fn check_positions<T: Score>(what: Input, m: ArrayView2<'_, T>) -> Result<()> {
    check_nonempty(what, m.dim())?;
    if !matches!(m.ncols(), 2 | 3) {
        return Err(Error::PositionColumns { what, cols: m.ncols() });
    }
    match m.indexed_iter().find(|(_, v)| !v.to_f64().is_finite()) {
        Some(((row, col), v)) => Err(Error::NotFinite {
            what,
            row,
            col,
            value: v.to_f64(),
        }),
        None => Ok(()),
    }
}

fn point<const K: usize, T: Score>(m: ArrayView2<'_, T>, row: usize) -> [f64; K] {
    std::array::from_fn(|k| m[[row, k]].to_f64())
}

fn fill<const K: usize, T: Score, U: Score>(
    db: ArrayView2<'_, T>,
    queries: ArrayView2<'_, U>,
    r2: f64,
) -> Array2<bool> {
    threads::install(|| {
        let tree = KdTree::<K>::new((0..queries.nrows()).map(|j| point(queries, j)).collect());
        let n_q = queries.nrows();
        let mut gt = vec![false; db.nrows() * n_q];
        gt.par_chunks_mut(n_q).enumerate().for_each(|(i, row)| {
            tree.within(&point(db, i), r2, &mut |j| row[j] = true);
        });
        Array2::from_shape_vec((db.nrows(), n_q), gt).expect("shape matches length")
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn hand_computed_tolerance() {
        // 4 x 3, tolerance 1: row i is true at columns i-1, i, i+1 inside 0..3.
        let gt = within_tolerance(4, 3, 1).unwrap();
        let want = array![
            [true, true, false],
            [true, true, true],
            [false, true, true],
            [false, false, true]
        ];
        assert_eq!(gt, want);
        // Tolerance 0 is the identity (padded); a huge tolerance is all true.
        assert_eq!(
            within_tolerance(2, 3, 0).unwrap(),
            array![[true, false, false], [false, true, false]]
        );
        assert!(within_tolerance(3, 2, usize::MAX).unwrap().iter().all(|&v| v));
        assert_eq!(
            within_tolerance(0, 3, 1).unwrap_err().to_string(),
            "ground truth is empty (shape 0x3)"
        );
    }

    #[test]
    fn hand_computed_positions() {
        // Queries at (0, 0) and (10, 0); radius 5.
        // db (3, 4): distances 5 (= radius: inside) and sqrt(49 + 16) = 8.06 (outside).
        // db (7, 0): 7 (outside) and 3 (inside).
        // db (5, 0.001): sqrt(25.000001) > 5 (outside) and the same (outside).
        // db (10, -5): sqrt(125) (outside) and 5 (inside, again exactly at the radius).
        let q = array![[0.0, 0.0], [10.0, 0.0]];
        let db = array![[3.0f32, 4.0], [7.0, 0.0], [5.0, 0.001], [10.0, -5.0]];
        let gt = within_radius(db.view(), q.view(), 5.0).unwrap();
        assert_eq!(gt, array![[true, false], [false, true], [false, false], [false, true]]);
        // Radius 0 matches identical positions only; 3-D uses z too:
        // (1, 2, 3) vs (1, 2, 3): 0; vs (1, 2, 4): 1.
        let q3 = array![[1.0, 2.0, 3.0], [1.0, 2.0, 4.0]];
        let db3 = array![[1.0, 2.0, 3.0]];
        assert_eq!(
            within_radius(db3.view(), q3.view(), 0.0).unwrap(),
            array![[true, false]]
        );
        assert_eq!(within_radius(db3.view(), q3.view(), 1.0).unwrap(), array![[true, true]]);
    }

    #[test]
    fn specs_make_hard_and_soft_ground_truth() {
        // Tolerance 0 (hard) and 1 (soft) on 2 x 3: hard is the padded identity, soft
        // adds |i - j| = 1: (0, 1), (1, 0), (1, 2).
        let spec = GtSpec::Tolerance { hard: 0, soft: Some(1) };
        let m = spec.matrices(Some((2, 3))).unwrap();
        assert_eq!(m.hard, array![[true, false, false], [false, true, false]]);
        assert_eq!(m.soft, Some(array![[true, true, false], [true, true, true]]));
        let gt = spec.ground_truth((2, 3)).unwrap();
        use crate::input::Truth::{False as F, Ignored as I, True as T};
        assert_eq!(gt.view(), array![[T, I, F], [I, T, I]]);
        // Positions on a line 10 apart, queries at the first two: radius 0 is the
        // identity, soft radius 10 adds the neighbours at distance exactly 10.
        let db = array![[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]];
        let q = array![[0.0f32, 0.0], [10.0, 0.0]];
        let spec = GtSpec::Positions {
            db: db.view().into(),
            queries: q.view().into(),
            radius: 0.0,
            soft_radius: Some(10.0),
        };
        let m = spec.matrices(None).unwrap();
        assert_eq!(m.hard, array![[true, false], [false, true], [false, false]]);
        assert_eq!(m.soft, Some(array![[true, true], [true, true], [false, true]]));
        assert_eq!(
            spec.matrices(Some((3, 3))).unwrap_err().to_string(),
            "3 database and 2 query positions, but the similarity matrix has shape 3x3"
        );
    }

    #[test]
    fn specs_check_soft_against_hard() {
        let spec = GtSpec::Tolerance { hard: 2, soft: Some(1) };
        assert_eq!(
            spec.matrices(Some((2, 2))).unwrap_err().to_string(),
            "soft tolerance 1 is smaller than the tolerance 2; soft ground truth must include the hard"
        );
        assert_eq!(
            GtSpec::Tolerance { hard: 0, soft: None }
                .matrices(None)
                .unwrap_err()
                .to_string(),
            "tolerance needs the shape |DB| x |Q| of the ground truth"
        );
        let p = array![[0.0, 0.0]];
        let spec = |radius, soft_radius| GtSpec::Positions {
            db: p.view().into(),
            queries: p.view().into(),
            radius,
            soft_radius,
        };
        assert_eq!(
            spec(1.0, Some(0.5)).matrices(None).unwrap_err().to_string(),
            "soft radius 0.5 is smaller than the radius 1; soft ground truth must include the hard"
        );
        assert_eq!(
            spec(1.0, Some(-1.0)).matrices(None).unwrap_err().to_string(),
            "soft radius must be a finite number >= 0, got -1"
        );
        assert_eq!(
            spec(f64::NAN, None).matrices(None).unwrap_err().to_string(),
            "radius must be a finite number >= 0, got NaN"
        );
    }

    #[test]
    fn many_identical_positions() {
        // A robot standing still: 1000 queries at one position (more than any leaf holds).
        let q = Array2::from_elem((1000, 2), 2.5);
        let db = array![[2.5, 2.5], [2.5, 3.5], [2.5, 3.6]];
        let gt = within_radius(db.view(), q.view(), 1.0).unwrap();
        assert!(gt.row(0).iter().all(|&v| v));
        assert!(gt.row(1).iter().all(|&v| v));
        assert!(gt.row(2).iter().all(|&v| !v));
    }

    #[test]
    fn bad_positions_and_radii() {
        let p = array![[0.0, 0.0], [1.0, 1.0]];
        for r in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(
                within_radius(p.view(), p.view(), r)
                    .unwrap_err()
                    .to_string()
                    .starts_with("radius must be a finite number >= 0, got "),
            );
        }
        let wide = array![[0.0, 0.0, 0.0, 0.0]];
        assert_eq!(
            within_radius(wide.view(), p.view(), 1.0).unwrap_err().to_string(),
            "database position matrix has 4 columns; positions must be x, y (2 columns) or x, y, z (3 columns)"
        );
        let three = array![[0.0, 0.0, 0.0]];
        assert_eq!(
            within_radius(p.view(), three.view(), 1.0).unwrap_err().to_string(),
            "query position matrix has 3 columns but database position matrix has 2; both must have the same dimension"
        );
        let nan = array![[0.0f32, 0.0], [f32::NAN, 1.0]];
        assert_eq!(
            within_radius(p.view(), nan.view(), 1.0).unwrap_err().to_string(),
            "query position matrix contains NaN at row 1, column 0; every value must be finite"
        );
        assert!(matches!(
            within_radius(Array2::<f64>::zeros((0, 2)).view(), p.view(), 1.0),
            Err(Error::Empty {
                what: crate::error::names::Input::DbPositions,
                ..
            })
        ));
    }
}
