//! The real data of `../shared/data` for the Rust tests.
//!
//! One module for the core's and the CLI's tests (the CLI's include it by path). A test
//! that needs the data is `#[ignore = "needs ../shared/data DATASET: why"]` (the folder
//! it reads, and what it checks there), so that `cargo test` reports it ignored, with
//! that reason, not passed, where the data may be absent; `scripts/test.sh` runs
//! them with `--include-ignored` when `../shared/data` is there. Run by hand without the
//! data, such a test returns at once after a note on standard error naming it (written
//! to the stream itself, which the harness does not capture).
#![allow(dead_code)] // each test crate uses what it needs

use std::io::Write as _;
use std::path::{Path, PathBuf};

use ndarray::{Array2, s};
use qtvpr::ScoresView;
use qtvpr::npy::{FloatMatrix, read_float_matrix};

/// `../shared/data/rel`, or `None` (with the note) when `../shared/data` is absent.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if dir.is_dir() {
        return Some(dir.join(rel));
    }
    let thread = std::thread::current();
    let test = thread.name().unwrap_or("a test");
    let _ = writeln!(std::io::stderr(), "skipped {test}: ../shared/data is absent");
    None
}

/// Nordland HOG: the database (winter) and the first `n_q` query (summer)
/// descriptors, 756-D float32; `None` without `../shared/data`.
pub fn nordland(n_q: usize) -> Option<(Array2<f32>, Array2<f32>)> {
    let read = |name: &str| -> Option<Array2<f32>> {
        let m = read_float_matrix(&shared(name)?, FloatMatrix::Descriptors).unwrap();
        match m.view() {
            ScoresView::F32(v) => Some(v.to_owned()),
            ScoresView::F64(_) => panic!("{name} is float32"),
        }
    };
    let (db, q) = (
        read("nordland-hog/db_winter.npy")?,
        read("nordland-hog/query_summer.npy")?,
    );
    assert_eq!((db.dim(), q.dim()), ((3576, 756), (3576, 756)));
    Some((db, q.slice(s![..n_q, ..]).to_owned()))
}
