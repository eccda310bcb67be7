//! The `.npy` / `.npz` readers on arbitrary bytes: every file must give a matrix or a
//! typed error, never a panic, an abort or an out-of-bounds read.
//!
//! The first byte chooses the reader (and the file's extension); the rest is the file.
//! On success every value is read, so a view that promised more data than the file or
//! the map holds would be caught (by the sanitizer, or by a panic in ndarray).

#![no_main]

use std::hint::black_box;
use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use qtvpr::ScoresView;
use qtvpr::npy::{MatrixFile, add_soft_ground_truth, read_ground_truth, read_hard_ground_truth, read_scores};
use qtvpr::{GroundTruth, Truth};

/// A directory of this process's own, for the file under test.
fn dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // Memory-backed if possible: the file is rewritten on every run.
        let shm = std::path::Path::new("/dev/shm");
        let base = if shm.is_dir() {
            shm.to_path_buf()
        } else {
            std::env::temp_dir()
        };
        let d = base.join(format!("qtvpr-fuzz-npy-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    })
}

fn touch_scores(s: &MatrixFile) {
    let sum = match s.view() {
        ScoresView::F32(v) => v.iter().map(|&x| f64::from(x)).sum::<f64>(),
        ScoresView::F64(v) => v.iter().sum::<f64>(),
    };
    black_box(sum);
    // The transpose is a view of the same data.
    let t = s.view().t();
    assert_eq!(t.dim(), (s.view().dim().1, s.view().dim().0));
}

fn touch_gt(gt: &GroundTruth) {
    let (rows, cols) = gt.dim();
    let n = gt.view().iter().filter(|&&t| t != Truth::False).count();
    assert!(n <= rows * cols);
    black_box(n);
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, bytes)) = data.split_first() else {
        return;
    };
    let ext = if matches!(mode % 5, 2 | 3) { "npz" } else { "npy" };
    let path = dir().join(format!("input.{ext}"));
    std::fs::write(&path, bytes).unwrap();
    // Errors must format too: their messages are built from the file's content.
    match mode % 5 {
        0 => match read_scores(&path) {
            Ok(s) => touch_scores(&s),
            Err(e) => drop(black_box(e.to_string())),
        },
        1 | 2 => match read_ground_truth(&path, None) {
            Ok(gt) => touch_gt(&gt),
            Err(e) => drop(black_box(e.to_string())),
        },
        3 => match read_hard_ground_truth(&path) {
            Ok(gt) => touch_gt(&gt),
            Err(e) => drop(black_box(e.to_string())),
        },
        _ => {
            // As soft ground truth of a 2 x 3 hard ground truth.
            let hard = GroundTruth::new(ndarray::array![[1u8, 0, 0], [0, 1, 0]].view()).unwrap();
            match add_soft_ground_truth(hard, &path) {
                Ok(gt) => touch_gt(&gt),
                Err(e) => drop(black_box(e.to_string())),
            }
        }
    }
});
