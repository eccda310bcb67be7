//! The similarity from descriptors on real Nordland HOG descriptors (`../shared/data`):
//! the tiled kernel agrees with the previous one-block implementation to within one
//! ulp of `f32`, and the fused transfer and calibration (descriptors in, no similarity
//! matrix) give the bits of `cosine_similarity` followed by the matrix path, for `f32`
//! and `f64` descriptors, several segment sizes and a calibration split that is not a
//! multiple of the tile width.
#![cfg(feature = "npy")]

use qtvpr_testkit::data;

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use ndarray::{Array2, ArrayView2, s};
use qtvpr::{
    Calibration, Descriptors, Gate, GroundTruth, Matching, Method, Options, Params, Protocol, ScoreSource, Split,
    cosine_similarity,
};

/// The implementation before the tiled kernel: every row normalised into one `f64`
/// copy, one GEMM of all database rows with all queries.
fn old_cosine(db: ArrayView2<'_, f32>, q: ArrayView2<'_, f32>) -> Array2<f32> {
    let unit = |m: ArrayView2<'_, f32>| -> Vec<f64> {
        let mut out = Vec::with_capacity(m.len());
        for row in m.rows() {
            let scale = row.iter().fold(0.0f64, |a, &v| a.max(f64::from(v).abs()));
            let x: Vec<f64> = row.iter().map(|&v| f64::from(v) / scale).collect();
            let norm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
            out.extend(x.iter().map(|v| v / norm));
        }
        out
    };
    let (n_db, n_q, dim) = (db.nrows(), q.nrows(), db.ncols());
    let (a, b) = (unit(db), unit(q));
    let mut prod = vec![0.0f64; n_db * n_q];
    matmul(
        MatMut::from_row_major_slice_mut(&mut prod, n_db, n_q),
        Accum::Replace,
        MatRef::from_row_major_slice(&a, n_db, dim),
        MatRef::from_row_major_slice(&b, n_q, dim).transpose(),
        1.0,
        Par::rayon(0),
    );
    Array2::from_shape_vec((n_db, n_q), prod.into_iter().map(|v| v as f32).collect()).unwrap()
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: the tiled cosine kernel within an ulp of the old, on real descriptors"]
fn tiled_kernel_matches_the_previous_implementation() {
    let Some((db, q)) = data::nordland(1000) else {
        return;
    };
    let new = cosine_similarity(db.view(), q.view()).unwrap();
    let old = old_cosine(db.view(), q.view());
    // Both round an f64 dot product (error ~1e-15) once to f32, so they can differ
    // only where the f64 value lies within ~1e-15 of a rounding boundary: by one ulp.
    let ulps: Vec<u32> = new
        .iter()
        .zip(&old)
        .map(|(a, b)| a.to_bits().abs_diff(b.to_bits()))
        .collect();
    assert!(ulps.iter().all(|&u| u <= 1), "max ulps {:?}", ulps.iter().max());
    let differ = ulps.iter().filter(|&&u| u > 0).count();
    println!(
        "{differ} of {} scores differ from the previous kernel's by one ulp",
        ulps.len()
    );
    // 3576 x 1000 scores; at most a handful may land on a boundary.
    assert!(differ * 10_000 < ulps.len(), "{differ} of {} differ", ulps.len());
    // The scores are real cosines: HOG descriptors are non-negative, R@1 is low.
    assert!(new.iter().all(|&v| (0.0..=1.0).contains(&v)));
}

/// Calibrate on the first `n_cal` queries and transfer to the rest, from the matrix
/// and from the descriptors: every result bit for bit the same.
fn fused_equals_matrix(d: &Descriptors<'_>, s: ArrayView2<'_, f32>, n_cal: usize) {
    let (n_db, n_q) = s.dim();
    let gt = GroundTruth::new(Array2::from_shape_fn((n_db, n_cal), |(i, j)| i.abs_diff(j) <= 1).view()).unwrap();
    for matching in [Matching::Single, Matching::Multi] {
        let cal = Calibration::new(s.slice(s![.., ..n_cal]), &gt, matching).unwrap();
        let fused = Calibration::new(ScoreSource::Descriptors(d, 0..n_cal), &gt, matching).unwrap();
        assert_eq!(fused.scores(), cal.scores());
        // A calibration for transfers only: nothing kept to save, the same results.
        let lean = Calibration::for_transfer(ScoreSource::Descriptors(d, 0..n_cal), gt.clone(), matching).unwrap();
        assert!(lean.scores().is_none());
        // Segments of 1, of 10 (dividing neither the tile of 16 nor the chunk), of
        // the tile width (16 queries, the similarity kernel's), of 100, and one batch of
        // every deployment query.
        for segment_size in [Some(1), Some(10), Some(16), Some(100), None] {
            let p = Params {
                k: 10,
                precision: 1.0,
                segment_size,
                gate: Gate::None,
                sequence_gate: Default::default(),
            };
            let want = cal.transfer(s.slice(s![.., n_cal..]), &p).unwrap();
            let got = fused.transfer(ScoreSource::Descriptors(d, n_cal..n_q), &p).unwrap();
            assert_eq!(got, want, "{matching:?} {segment_size:?}");
            let lean = lean.transfer(ScoreSource::Descriptors(d, n_cal..n_q), &p).unwrap();
            assert_eq!(lean, want, "{matching:?} {segment_size:?}");
            let bits = |t: &qtvpr::Transfer| -> Vec<u64> { t.segments.iter().map(|g| g.threshold.to_bits()).collect() };
            assert_eq!(bits(&got), bits(&want));
        }
    }
    // With the margin gate (single matching): the same m* and margins, bit for bit.
    let cal = Calibration::new(s.slice(s![.., ..n_cal]), &gt, Matching::Single).unwrap();
    let fused = Calibration::new(ScoreSource::Descriptors(d, 0..n_cal), &gt, Matching::Single).unwrap();
    let p = Params {
        segment_size: Some(10),
        gate: Gate::Margin,
        ..Params::default()
    };
    let want = cal.transfer(s.slice(s![.., n_cal..]), &p).unwrap();
    let got = fused.transfer(ScoreSource::Descriptors(d, n_cal..n_q), &p).unwrap();
    assert_eq!(got, want);
    assert!(want.gate.is_some());
    let margins = qtvpr::margins(s.slice(s![.., n_cal..])).unwrap();
    assert_eq!(got.query_margins, Some(margins));
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: the fused transfer = the matrix path, bit for bit, across tiles"]
fn fused_transfer_gives_the_bits_of_the_matrix_path() {
    // 600 queries: 137 calibrate (not a multiple of 64, so the deployment queries
    // start inside a tile), 463 deploy.
    let Some((db, q)) = data::nordland(600) else {
        return;
    };
    let s = cosine_similarity(db.view(), q.view()).unwrap();
    fused_equals_matrix(&Descriptors::new(db.view(), q.view()).unwrap(), s.view(), 137);
    // float64 descriptors (the same values widened) give the same f32 scores.
    let (db64, q64) = (db.mapv(f64::from), q.mapv(f64::from));
    assert_eq!(cosine_similarity(db64.view(), q64.view()).unwrap(), s);
    fused_equals_matrix(&Descriptors::new(db64.view(), q64.view()).unwrap(), s.view(), 200);
}

/// Every operation takes a [`ScoreSource`]: a calibration, an evaluation and an
/// ablation of descriptors (a range of their queries) equal those of the matrix, and
/// the progress of `Options` counts the same steps.
#[test]
#[ignore = "needs ../shared/data nordland-hog: every operation on descriptors = on their matrix"]
fn every_operation_reads_descriptors_as_its_matrix() {
    let Some((db, q)) = data::nordland(300) else {
        return;
    };
    let d = Descriptors::new(db.view(), q.view()).unwrap();
    // Queries 50..300 of the descriptors are the columns 50.. of the matrix.
    let s = cosine_similarity(db.view(), q.view()).unwrap();
    let s = s.slice(s![.., 50..]);
    let source = ScoreSource::Descriptors(&d, 50..300);
    assert_eq!(source.dim(), s.dim());
    let gt = GroundTruth::new(Array2::from_shape_fn(s.dim(), |(i, j)| i.abs_diff(j + 50) <= 2).view()).unwrap();
    let protocol = Protocol {
        calibration: Split::Count(40),
        segment: Split::Count(10),
        ..Protocol::default()
    };
    let methods = Method::all_for(Matching::Single);
    let calls = std::cell::RefCell::new(vec![]);
    let record = |done, total| calls.borrow_mut().push((done, total));
    let want = qtvpr::evaluate(s, &gt, &protocol, &methods).unwrap();
    let got = qtvpr::evaluate(source.clone(), &gt, Options::new(protocol).progress(&record), &methods).unwrap();
    assert_eq!(got.methods, want.methods);
    assert!(got.methods.iter().any(|m| m.pooled().tp > 0), "something is accepted");
    let n = methods.len();
    assert_eq!(calls.take(), (1..=n).map(|i| (i, n)).collect::<Vec<_>>());

    let ks = [1, 5];
    let want = qtvpr::ablation(s, &gt, &protocol, &ks, &[], &methods).unwrap();
    let got = qtvpr::ablation(
        source.clone(),
        &gt,
        Options::new(protocol).progress(&record),
        &ks,
        &[],
        &methods,
    )
    .unwrap();
    assert_eq!(got.runs.len(), 2);
    for (got, want) in got.runs.iter().zip(&want.runs) {
        assert_eq!(got.methods, want.methods);
    }
    assert_eq!(calls.take().last(), Some(&(2 * n, 2 * n)));

    // A calibration on the first 40 columns of the source, a transfer to the rest.
    let gt_cal = GroundTruth::from_truth(gt.view().slice(s![.., ..40]).to_owned());
    let cal = Calibration::new(source.columns(0..40), &gt_cal, Matching::Single).unwrap();
    assert_eq!(
        cal.scores(),
        Calibration::new(s.slice(s![.., ..40]), &gt_cal, Matching::Single)
            .unwrap()
            .scores()
    );
    let p = Params {
        segment_size: Some(30),
        ..Params::default()
    };
    let got = cal
        .transfer(source.columns(40..250), Options::new(p).progress(&record))
        .unwrap();
    assert_eq!(got, cal.transfer(s.slice(s![.., 40..]), &p).unwrap());
    assert_eq!(calls.take().last(), Some(&(210, 210)));
    // A range beyond the descriptors is refused by the operation, naming it.
    assert_eq!(
        cal.transfer(ScoreSource::Descriptors(&d, 250..301), &p)
            .unwrap_err()
            .to_string(),
        "queries must be a non-empty range of the 300 query descriptors, got 250..301"
    );
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: real descriptors with a zero row, whose error names it"]
fn errors_name_the_row() {
    let Some((mut db, q)) = data::nordland(10) else {
        return;
    };
    db.row_mut(17).fill(0.0);
    let err = Descriptors::new(db.view(), q.view()).unwrap_err();
    assert_eq!(
        err.to_string(),
        "database descriptor matrix row 17 is all zeros; the cosine similarity of a zero vector is undefined"
    );
    let mut q = q;
    db.row_mut(17).fill(1.0);
    q[[3, 5]] = f32::NAN;
    assert_eq!(
        Descriptors::new(db.view(), q.view()).unwrap_err().to_string(),
        "query descriptor matrix contains NaN at row 3, column 5; every value must be finite"
    );
    assert!(Descriptors::new(db.view(), q.slice(s![.., ..755])).is_err());
}
