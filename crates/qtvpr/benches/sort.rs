//! The sort of a profile, the stage that dominates once the screen no longer does:
//! the core's (`Score::sort_ascending`: an AVX-512 quicksort where the CPU has
//! AVX-512, else `radsort`) against `radsort`, another radix sort crate,
//! `voracious_radix_sort`, a hand-written 3-pass LSD radix sort of 11-bit digits (the
//! yardstick of a hand-written kernel), and the standard library's pattern-defeating
//! quicksort, on `f32` and `f64` columns of 27,592 scores (a paper-scale profile) and
//! 1,000,000 (an SF-XL-like one).
//!
//! The columns are synthetic cosine-like scores (a fixed LCG: noise, a match near the
//! diagonal, a drift), each sort on a fresh copy of one of 16 columns so that no run
//! sorts sorted data. Run: `cargo bench -p qtvpr --bench sort`; the figures are in
//! `docs/performance.md` (*Sort*).

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, Throughput, criterion_group, criterion_main};
use qtvpr::Score;
use std::hint::black_box;
use voracious_radix_sort::RadixSort;

/// 16 columns of `n` cosine-like scores.
fn columns(n: usize) -> Vec<Vec<f32>> {
    let mut x = 7u64;
    (0..16)
        .map(|j| {
            (0..n)
                .map(|i| {
                    x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    let noise = (x >> 40) as f32 / (1u64 << 24) as f32;
                    let d = (i as f32 - (j * n / 16) as f32).abs();
                    0.2 * noise + 0.5 * (-d / 3.0).exp() + 0.1 * (i as f32 / n as f32)
                })
                .collect()
        })
        .collect()
}

/// The yardstick: LSD radix sort of `f32` on the keys radsort sorts by (every bit
/// flipped for a negative value, the sign bit for a positive one), 3 passes of 11 bits,
/// the histograms of all passes in one pass, a pass skipped when one bucket holds
/// every key.
fn lsd_f32(v: &mut [f32], keys: &mut Vec<u32>, spare: &mut Vec<u32>) {
    let key = |x: f32| {
        let b = x.to_bits();
        if b >> 31 == 1 { !b } else { b ^ 1 << 31 }
    };
    let n = v.len();
    keys.clear();
    keys.extend(v.iter().map(|&x| key(x)));
    spare.resize(n, 0);
    let mut hist = [[0usize; 2048]; 3];
    for &k in keys.iter() {
        for (p, h) in hist.iter_mut().enumerate() {
            h[(k >> (11 * p)) as usize & 2047] += 1;
        }
    }
    for (p, h) in hist.iter_mut().enumerate() {
        if h.contains(&n) {
            continue;
        }
        let mut sum = 0;
        for c in h.iter_mut() {
            (*c, sum) = (sum, sum + *c);
        }
        for &k in keys.iter() {
            let d = (k >> (11 * p)) as usize & 2047;
            spare[h[d]] = k;
            h[d] += 1;
        }
        std::mem::swap(keys, spare);
    }
    for (o, &k) in v.iter_mut().zip(keys.iter()) {
        *o = f32::from_bits(if k >> 31 == 1 { k ^ 1 << 31 } else { !k });
    }
}

fn sorts(c: &mut Criterion) {
    for n in [27_592, 1_000_000] {
        let f32s = columns(n);
        let f64s: Vec<Vec<f64>> = f32s.iter().map(|c| c.iter().map(|&v| f64::from(v)).collect()).collect();
        // Every sort gives radsort's order, bit for bit.
        let mut want = f32s[3].clone();
        radsort::sort(&mut want);
        let (mut keys, mut spare) = (Vec::new(), Vec::new());
        let mut got = f32s[3].clone();
        lsd_f32(&mut got, &mut keys, &mut spare);
        assert!(got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()));
        let mut got = f32s[3].clone();
        <f32 as Score>::sort_ascending(&mut got);
        assert!(got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()));
        let mut got = f32s[3].clone();
        got.voracious_sort();
        assert!(got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()));

        let mut g = c.benchmark_group(format!("sort/{n}"));
        g.sample_size(if n > 100_000 { 20 } else { 100 });
        g.throughput(Throughput::Elements(n as u64));
        time(&mut g, "f32/core", &f32s, <f32 as Score>::sort_ascending);
        time(&mut g, "f32/radsort", &f32s, radsort::sort);
        time(&mut g, "f32/voracious", &f32s, |v| v.voracious_sort());
        time(&mut g, "f32/lsd-3x11", &f32s, |v| lsd_f32(v, &mut keys, &mut spare));
        time(&mut g, "f32/pdqsort", &f32s, |v| v.sort_unstable_by(f32::total_cmp));
        time(&mut g, "f64/core", &f64s, <f64 as Score>::sort_ascending);
        time(&mut g, "f64/radsort", &f64s, radsort::sort);
        time(&mut g, "f64/voracious", &f64s, |v| v.voracious_sort());
        g.finish();
    }
}

/// Time `sort` on a fresh copy of one of `columns` per iteration, in turn.
fn time<T: Copy>(g: &mut BenchmarkGroup<'_, WallTime>, name: &str, columns: &[Vec<T>], mut sort: impl FnMut(&mut [T])) {
    let mut buf = columns[0].clone();
    let mut i = 0;
    g.bench_function(name, |b| {
        b.iter(|| {
            i = (i + 1) % columns.len();
            buf.copy_from_slice(&columns[i]);
            sort(black_box(&mut buf[..]));
        })
    });
}

criterion_group!(benches, sorts);
criterion_main!(benches);
