//! The ascending sort of a column of `f32` scores ([`Score::sort_ascending`]): a
//! vectorised quicksort where the CPU has AVX-512, `radsort` elsewhere (and for `f64`).
//!
//! Every profile is sorted once per query, and once the screen reads only a few
//! profiles the sort is the largest stage of a push. `radsort` (an LSD radix sort of
//! four 8-bit passes) took twice as long at 27,592 scores as this sort, which is the
//! design of Intel's x86-simd-sort (NumPy's `np.sort`) and of Bramas (2017). It is
//! written here because no crate offers it in Rust alone: `vqsort-rs` links Highway
//! from the system (pkg-config), x86-simd-sort is C++, and the radix crates measured no
//! faster than `radsort` (docs/performance.md, *Sort*).
//!
//! Both sorts order the same keys: the bits of an `f32` with every bit flipped for a
//! negative value and the sign bit set for a positive one, IEEE total order (-0.0
//! before +0.0), compared as unsigned integers. Equal keys are equal bits, so the two
//! give the same bits whatever their stability.
//!
//! The algorithm:
//! - a range of more than 128 keys is partitioned around the median of 16 keys
//!   sampled evenly across it: one pass of 16-key vectors, each compress-stored to the
//!   two ends of the range in the other buffer (the keys go back and forth between the
//!   column and one spare buffer, never copied back);
//! - when nothing is below the pivot (it is the range's minimum), the range is
//!   partitioned again at pivot + 1: every key of the lower part then equals the pivot
//!   and is in place, so a column of one repeated value ends after two passes;
//! - a range of at most 128 keys is sorted in registers by a bitonic network (each
//!   vector, then merges of ever larger blocks; missing lanes hold `u32::MAX`) and
//!   stored in the column;
//! - a range still unsorted after 2 log2(n) partitions is given to `radsort`, so no
//!   input costs more than O(n log n).

#[cfg(doc)]
use crate::input::Score;

/// Sort `v` ascending in IEEE total order.
pub(crate) fn sort_f32(v: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V4::try_new() {
        return pulp::Simd::vectorize(simd, avx512::Quicksort(simd, v, depth_limit(v.len())));
    }
    radsort::sort(v);
}

/// The partitions a range may take before it is given to `radsort`: 2 log2(n).
fn depth_limit(n: usize) -> u32 {
    2 * (usize::BITS - n.leading_zeros())
}

/// The key of an `f32`: unsigned order is IEEE total order.
#[inline(always)]
fn key(bits: u32) -> u32 {
    if bits >> 31 == 1 { !bits } else { bits | 1 << 31 }
}

/// The bits of the `f32` whose key is `k`.
#[inline(always)]
fn unkey(k: u32) -> u32 {
    if k >> 31 == 1 { k & !(1 << 31) } else { !k }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use core::arch::x86_64::__m512i;
    use pulp::x86::V4;

    use super::{key, unkey};

    /// Keys a vector.
    const L: usize = 16;
    /// The longest range sorted in registers (8 vectors).
    const SMALL: usize = 8 * L;

    /// `v` sorted with `V4`; ranges still unsorted after the given number of
    /// partitions go to `radsort`.
    pub(super) struct Quicksort<'a>(pub V4, pub &'a mut [f32], pub u32);

    impl pulp::WithSimd for Quicksort<'_> {
        type Output = ();

        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) {
            let Self(simd, v, depth) = self;
            let keys: &mut [u32] = pulp::bytemuck::cast_slice_mut(v);
            keys.iter_mut().for_each(|k| *k = key(*k));
            sort_keys(simd, keys, depth);
            keys.iter_mut().for_each(|k| *k = unkey(*k));
        }
    }

    /// A range of the column still to sort: where it starts, how long it is, whether
    /// its keys are in the column (else in the spare buffer), and how many partitions
    /// it may still take.
    #[derive(Clone, Copy)]
    struct Range {
        start: usize,
        len: usize,
        in_column: bool,
        depth: u32,
    }

    /// Sort `keys` ascending.
    #[inline(always)]
    fn sort_keys(simd: V4, keys: &mut [u32], depth: u32) {
        let mut spare = vec![0u32; keys.len()];
        // The larger part of each partition waits here while the smaller is sorted, so
        // at most log2(n) ranges wait.
        let mut waiting = vec![Range {
            start: 0,
            len: keys.len(),
            in_column: true,
            depth,
        }];
        while let Some(mut r) = waiting.pop() {
            loop {
                let span = r.start..r.start + r.len;
                if r.len <= SMALL {
                    let src = (!r.in_column).then(|| &spare[span.clone()]);
                    small(simd, src, &mut keys[span]);
                    break;
                }
                if r.depth == 0 {
                    if !r.in_column {
                        keys[span.clone()].copy_from_slice(&spare[span.clone()]);
                    }
                    radsort::sort(&mut keys[span]);
                    break;
                }
                let (src, dst) = if r.in_column {
                    (&keys[span.clone()], &mut spare[span.clone()])
                } else {
                    (&spare[span.clone()], &mut keys[span.clone()])
                };
                let pivot = pivot(simd, src);
                let mut below = partition(simd, src, dst, pivot);
                if below == 0 {
                    // The pivot is the minimum: below pivot + 1 are its copies.
                    let Some(next) = pivot.checked_add(1) else {
                        // Every key is u32::MAX.
                        if !r.in_column {
                            keys[span.clone()].copy_from_slice(&spare[span]);
                        }
                        break;
                    };
                    below = partition(simd, src, dst, next);
                    if r.in_column {
                        keys[r.start..r.start + below].fill(pivot);
                    }
                    r = Range {
                        start: r.start + below,
                        len: r.len - below,
                        in_column: !r.in_column,
                        depth: r.depth - 1,
                    };
                    if r.len == 0 {
                        break;
                    }
                    continue;
                }
                let lower = Range {
                    start: r.start,
                    len: below,
                    in_column: !r.in_column,
                    depth: r.depth - 1,
                };
                let upper = Range {
                    start: r.start + below,
                    len: r.len - below,
                    ..lower
                };
                let (smaller, larger) = if lower.len < upper.len {
                    (lower, upper)
                } else {
                    (upper, lower)
                };
                waiting.push(larger);
                r = smaller;
            }
        }
    }

    /// Write the keys of `src` below `pivot` to the front of `dst` and the others to
    /// its back; returns how many are below.
    #[inline(always)]
    fn partition(simd: V4, src: &[u32], dst: &mut [u32], pivot: u32) -> usize {
        let n = src.len();
        let p = simd.avx512f._mm512_set1_epi32(pivot as i32);
        let (mut below, mut above) = (0, n);
        let (body, tail) = src.as_chunks::<L>();
        let mut write = |mask: u16, x: __m512i| {
            let lt = simd.avx512f._mm512_mask_cmplt_epu32_mask(mask, x, p);
            let ge = mask & !lt;
            let (c_lt, c_ge) = (lt.count_ones() as usize, ge.count_ones() as usize);
            let front = &mut dst[below..below + c_lt];
            // SAFETY: writes popcount(lt) = front.len() keys at its start.
            unsafe {
                simd.avx512f
                    ._mm512_mask_compressstoreu_epi32(front.as_mut_ptr().cast(), lt, x)
            };
            below += c_lt;
            above -= c_ge;
            let back = &mut dst[above..above + c_ge];
            // SAFETY: as above, popcount(ge) = back.len() keys.
            unsafe {
                simd.avx512f
                    ._mm512_mask_compressstoreu_epi32(back.as_mut_ptr().cast(), ge, x)
            };
        };
        for chunk in body {
            write(u16::MAX, pulp::bytemuck::cast(*chunk));
        }
        if !tail.is_empty() {
            write(live(tail.len()), load_partial(simd, tail));
        }
        debug_assert_eq!(below, above);
        below
    }

    /// The median of 16 keys sampled evenly across `v` (more than 16 long).
    #[inline(always)]
    fn pivot(simd: V4, v: &[u32]) -> u32 {
        let n = v.len();
        let sample: [u32; L] = std::array::from_fn(|i| v[(2 * i + 1) * n / (2 * L)]);
        let sorted: [u32; L] = pulp::bytemuck::cast(sort16(simd, pulp::bytemuck::cast(sample)));
        sorted[L / 2]
    }

    /// The first `n` (under 16) lanes.
    #[inline(always)]
    fn live(n: usize) -> u16 {
        ((1u32 << n) - 1) as u16
    }

    /// The keys of `v` (under 16) in the first lanes, `u32::MAX` in the others.
    #[inline(always)]
    fn load_partial(simd: V4, v: &[u32]) -> __m512i {
        let fill = simd.avx512f._mm512_set1_epi32(-1);
        // SAFETY: reads the first v.len() lanes only.
        unsafe {
            simd.avx512f
                ._mm512_mask_loadu_epi32(fill, live(v.len()), v.as_ptr().cast())
        }
    }

    /// The keys of `src` (at most 128; `None`: those of `dst`) sorted into `dst`.
    #[inline(always)]
    fn small(simd: V4, src: Option<&[u32]>, dst: &mut [u32]) {
        match dst.len() {
            0..=16 => small_m::<1>(simd, src, dst),
            17..=32 => small_m::<2>(simd, src, dst),
            33..=64 => small_m::<4>(simd, src, dst),
            _ => small_m::<8>(simd, src, dst),
        }
    }

    /// [`small`] for at most `M` vectors of keys.
    #[inline(always)]
    fn small_m<const M: usize>(simd: V4, src: Option<&[u32]>, dst: &mut [u32]) {
        let block = sorted::<M>(simd, src.unwrap_or(dst));
        for (x, out) in block.iter().zip(dst.chunks_mut(L)) {
            // SAFETY: writes the first out.len() lanes only.
            unsafe {
                simd.avx512f
                    ._mm512_mask_storeu_epi32(out.as_mut_ptr().cast(), live_or_all(out.len()), *x)
            };
        }
    }

    /// `live(n)`, or every lane for 16.
    #[inline(always)]
    fn live_or_all(n: usize) -> u16 {
        if n == L { u16::MAX } else { live(n) }
    }

    /// The keys of `v` (at most 16 M) sorted, padded with `u32::MAX`.
    #[inline(always)]
    fn sorted<const M: usize>(simd: V4, v: &[u32]) -> [__m512i; M] {
        let mut chunks = v.chunks(L);
        let mut block = [0; M].map(|_: u8| match chunks.next() {
            Some(c) if c.len() == L => pulp::bytemuck::cast(*c.first_chunk::<L>().expect("16 keys")),
            Some(c) => load_partial(simd, c),
            None => simd.avx512f._mm512_set1_epi32(-1),
        });
        for x in &mut block {
            *x = sort16(simd, *x);
        }
        // Bitonic merges of sorted blocks of h vectors into blocks of 2h.
        let mut h = 1;
        while h < M {
            for b in (0..M).step_by(2 * h) {
                // The lower block against the upper one reversed: the smaller halves
                // are the merged block's first h vectors, the larger its last h, and
                // each half is bitonic.
                for i in 0..h {
                    let (a, c) = (block[b + i], reverse(simd, block[b + 2 * h - 1 - i]));
                    block[b + i] = simd.avx512f._mm512_min_epu32(a, c);
                    block[b + 2 * h - 1 - i] = simd.avx512f._mm512_max_epu32(a, c);
                }
                block[b + h..b + 2 * h].reverse();
                // Half-cleaners across vectors, then within each.
                let mut t = h / 2;
                while t >= 1 {
                    for g in (b..b + 2 * h).step_by(2 * t) {
                        for i in g..g + t {
                            let (a, c) = (block[i], block[i + t]);
                            block[i] = simd.avx512f._mm512_min_epu32(a, c);
                            block[i + t] = simd.avx512f._mm512_max_epu32(a, c);
                        }
                    }
                    t /= 2;
                }
                for x in &mut block[b..b + 2 * h] {
                    *x = clean16(simd, *x);
                }
            }
            h *= 2;
        }
        block
    }

    /// Lane i's partner in the compare-exchanges of stride j: i ^ j.
    const fn partners(j: u32) -> [u32; L] {
        let mut p = [0; L];
        let mut i = 0;
        while i < L {
            p[i] = i as u32 ^ j;
            i += 1;
        }
        p
    }

    /// The lanes that keep the larger key in step (j, k) of an ascending bitonic sort.
    const fn larger(j: usize, k: usize) -> u16 {
        let mut m = 0;
        let mut i = 0;
        while i < L {
            if (i & j != 0) != (i & k != 0) {
                m |= 1 << i;
            }
            i += 1;
        }
        m
    }

    /// One compare-exchange step: each lane against lane i ^ j.
    #[inline(always)]
    fn exchange(simd: V4, x: __m512i, j: u32, keep_larger: u16) -> __m512i {
        let partner = simd
            .avx512f
            ._mm512_permutexvar_epi32(pulp::bytemuck::cast(partners(j)), x);
        let lo = simd.avx512f._mm512_min_epu32(x, partner);
        let hi = simd.avx512f._mm512_max_epu32(x, partner);
        simd.avx512f._mm512_mask_blend_epi32(keep_larger, lo, hi)
    }

    /// The 16 lanes of `x` sorted.
    #[inline(always)]
    fn sort16(simd: V4, x: __m512i) -> __m512i {
        let x = exchange(simd, x, 1, const { larger(1, 2) });
        let x = exchange(simd, x, 2, const { larger(2, 4) });
        let x = exchange(simd, x, 1, const { larger(1, 4) });
        let x = exchange(simd, x, 4, const { larger(4, 8) });
        let x = exchange(simd, x, 2, const { larger(2, 8) });
        let x = exchange(simd, x, 1, const { larger(1, 8) });
        clean16(simd, x)
    }

    /// A bitonic vector sorted.
    #[inline(always)]
    fn clean16(simd: V4, x: __m512i) -> __m512i {
        let x = exchange(simd, x, 8, const { larger(8, 16) });
        let x = exchange(simd, x, 4, const { larger(4, 16) });
        let x = exchange(simd, x, 2, const { larger(2, 16) });
        exchange(simd, x, 1, const { larger(1, 16) })
    }

    /// The lanes of `x` in reverse order.
    #[inline(always)]
    fn reverse(simd: V4, x: __m512i) -> __m512i {
        simd.avx512f
            ._mm512_permutexvar_epi32(pulp::bytemuck::cast(partners(15)), x)
    }

    #[cfg(test)]
    pub(super) fn sort_with_depth(v: &mut [f32], depth: u32) -> bool {
        match V4::try_new() {
            Some(simd) => {
                pulp::Simd::vectorize(simd, Quicksort(simd, v, depth));
                true
            }
            None => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    /// `v` sorted by the vectorised sort with the given depth limit and by `radsort`:
    /// the same bits. False without AVX-512 (nothing to compare).
    fn agrees(v: &[f32], depth: u32) -> bool {
        let mut want = v.to_vec();
        radsort::sort(&mut want);
        let mut got = v.to_vec();
        #[cfg(target_arch = "x86_64")]
        if super::avx512::sort_with_depth(&mut got, depth) {
            let (want, got): (Vec<u32>, Vec<u32>) = (
                want.iter().map(|x| x.to_bits()).collect(),
                got.iter().map(|x| x.to_bits()).collect(),
            );
            assert_eq!(got, want, "{} scores, depth {depth}", v.len());
            return true;
        }
        false
    }

    /// `n` scores from `seed`: duplicates, both zeros, infinities, subnormals, NaNs of
    /// both signs and arbitrary bits.
    fn scores(n: usize, seed: u64) -> Vec<f32> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let r = (x >> 32) as u32;
                match r % 8 {
                    0 => 0.0,
                    1 => -0.0,
                    2 => (r % 7) as f32 - 3.0,
                    3 => [
                        f32::INFINITY,
                        f32::NEG_INFINITY,
                        f32::NAN,
                        -f32::NAN,
                        f32::MIN_POSITIVE / 3.0,
                    ][(r >> 8) as usize % 5],
                    4 => 0.5 + (r >> 12) as f32 * 1e-7,
                    _ => f32::from_bits(r.wrapping_mul(2654435761)),
                }
            })
            .collect()
    }

    fn depth(n: usize) -> u32 {
        super::depth_limit(n)
    }

    #[test]
    fn every_length_gives_radsorts_bits() {
        let lengths = (0..=700).chain([1000, 4097, 27_592, 100_003]);
        let mut ran = false;
        for (seed, n) in lengths.enumerate() {
            ran |= agrees(&scores(n, seed as u64), depth(n));
        }
        if !ran {
            eprintln!("skipped: this CPU has no AVX-512, and sort_f32 is radsort itself");
        }
    }

    #[test]
    fn columns_of_few_values_and_ordered_columns() {
        let n = 5000;
        let cases: Vec<Vec<f32>> = vec![
            vec![0.25; n],
            vec![-0.0; n],
            (0..n).map(|i| if i % 3 == 0 { -0.0 } else { 0.0 }).collect(),
            (0..n).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect(),
            (0..n).map(|i| if i < 10 { 2.0 } else { 1.0 }).collect(),
            (0..n).map(|i| if i == 77 { 0.0 } else { 1.0 }).collect(),
            (0..n).map(|i| i as f32).collect(),
            (0..n).rev().map(|i| i as f32).collect(),
            (0..n).map(|i| (i % 100) as f32).collect(),
            (0..n).map(|i| (i.min(n - i)) as f32).collect(),
            vec![f32::NAN; n],
        ];
        for v in &cases {
            agrees(v, depth(n));
        }
    }

    #[test]
    fn ranges_past_the_depth_limit_go_to_radsort() {
        for d in 0..4 {
            agrees(&scores(3000, 9), d);
            agrees(&(0..3000).map(|i| (i % 5) as f32).collect::<Vec<_>>(), d);
        }
    }

    proptest! {
        #[test]
        fn any_bits_sort_as_radsort_sorts_them(bits in proptest::collection::vec(any::<u32>(), 0..2000)) {
            let v: Vec<f32> = bits.into_iter().map(f32::from_bits).collect();
            agrees(&v, depth(v.len()));
        }

        #[test]
        fn few_distinct_scores_sort_as_radsort_sorts_them(ix in proptest::collection::vec(0usize..4, 0..3000)) {
            let v: Vec<f32> = ix.into_iter().map(|i| [-0.0, 0.0, 0.5, 0.5000001][i]).collect();
            agrees(&v, depth(v.len()));
        }
    }
}
