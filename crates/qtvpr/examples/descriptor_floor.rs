//! The floor of the fused transfer from descriptors on this machine (benches/descriptors.py):
//! the speed faer's parallel `f32` GEMM reaches on a large product, and the time of the
//! core's sort per score (`Score::sort_ascending`). Prints one JSON line.
//!
//!     cargo run --release -p qtvpr --example descriptor_floor -- [ROWS] [COLS] [DIM]

use std::time::Instant;

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use qtvpr::Score;

fn main() {
    let arg = |i: usize, default: usize| {
        std::env::args()
            .nth(i)
            .map_or(default, |a| a.parse().expect("sizes are integers"))
    };
    let (rows, cols, dim) = (arg(1, 100_000), arg(2, 512), arg(3, 512));
    // A fixed LCG fills the operands: the speed of a GEMM does not depend on the values.
    let mut x = 1u64;
    let mut next = move || {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((x >> 40) as f32) / (1u64 << 24) as f32 - 0.5
    };
    let a = Mat::<f32>::from_fn(rows, dim, |_, _| next());
    let b = Mat::<f32>::from_fn(dim, cols, |_, _| next());
    let mut c = Mat::<f32>::zeros(rows, cols);
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        matmul(c.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, Par::rayon(0));
        best = best.min(t.elapsed().as_secs_f64());
    }
    let gflops = 2.0 * (rows * cols * dim) as f64 / best / 1e9;
    // One sort of columns of `rows` scores each, as the transfer sorts them.
    let mut scores: Vec<f32> = (0..rows * cols.min(64)).map(|_| next()).collect();
    let t = Instant::now();
    for column in scores.chunks_mut(rows) {
        f32::sort_ascending(column);
    }
    let sort_ns = t.elapsed().as_secs_f64() * 1e9 / scores.len() as f64;
    println!(
        "{{\"gemm_f32_gflops\": {gflops:.2}, \"gemm_shape\": [{rows}, {dim}, {cols}], \"sort_ns_per_score\": {sort_ns:.3}}}"
    );
}
