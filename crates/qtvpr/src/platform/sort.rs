//! The ascending sort of a column of scores (`Score::sort_ascending`): a vectorised
//! quicksort where the CPU has AVX-512, `radsort` elsewhere.
//!
//! Every profile is sorted once per query, and once the screen reads only a few
//! profiles the sort is the largest stage of a push. `radsort` (an LSD radix sort of
//! 8-bit passes) took about twice as long at 27,592 scores as this sort, which is the
//! design of Intel's x86-simd-sort (NumPy's `np.sort`) and of Bramas (2017). It is
//! written here because no crate offers it in Rust alone: `vqsort-rs` links Highway
//! from the system (pkg-config), x86-simd-sort is C++, and the radix crates measured no
//! faster than `radsort` (docs/performance.md, *Sort*).
//!
//! Both sorts order the same keys: the bits of a score with every bit flipped for a
//! negative value and the sign bit set for a positive one, IEEE total order (-0.0
//! before +0.0), compared as unsigned integers (`u32` for `f32`, `u64` for `f64`).
//! Equal keys are equal bits, so the two give the same bits whatever their stability.
//!
//! The algorithm, on vectors of `L` keys (16 `u32` or 8 `u64`, 64 bytes):
//! - a range of more than 8 `L` keys is partitioned around the median of `L` keys
//!   sampled evenly across it: one pass of vectors, each compress-stored to the two
//!   ends of the range in the other buffer (the keys go back and forth between the
//!   column and one spare buffer, never copied back);
//! - when nothing is below the pivot (it is the range's minimum), the range is
//!   partitioned again at pivot + 1: every key of the lower part then equals the pivot
//!   and is in place, so a column of one repeated value ends after two passes;
//! - a range of at most 8 `L` keys is sorted in registers by a bitonic network (each
//!   vector, then merges of ever larger blocks; missing lanes hold the largest key)
//!   and stored in the column;
//! - a range still unsorted after 2 log2(n) partitions is given to `radsort`, so no
//!   input costs more than O(n log n).

/// Sort `v` ascending in IEEE total order.
pub(crate) fn sort_f32(v: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V4::try_new() {
        let keys: &mut [u32] = pulp::bytemuck::cast_slice_mut(v);
        return pulp::Simd::vectorize(simd, avx512::Quicksort(simd, keys, depth_limit(keys.len())));
    }
    scalar_f32(v);
}

/// Sort `v` ascending in IEEE total order.
pub(crate) fn sort_f64(v: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V4::try_new() {
        let keys: &mut [u64] = pulp::bytemuck::cast_slice_mut(v);
        return pulp::Simd::vectorize(simd, avx512::Quicksort(simd, keys, depth_limit(keys.len())));
    }
    scalar_f64(v);
}

/// The sort of a CPU without AVX-512 (and of every range past the depth limit).
fn scalar_f32(v: &mut [f32]) {
    radsort::sort(v);
}

/// [`scalar_f32`] for `f64` scores.
fn scalar_f64(v: &mut [f64]) {
    radsort::sort(v);
}

/// The partitions a range may take before it is given to `radsort`: 2 log2(n).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn depth_limit(n: usize) -> u32 {
    2 * (usize::BITS - n.leading_zeros())
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use core::arch::x86_64::__m512i;
    use std::ops::{Add, BitAnd, BitOr, Not};

    use pulp::x86::V4;

    /// The keys of one score type, in 64-byte vectors of `L` lanes (a mask's bit i is
    /// lane i). Each type gives its vector instructions; the key transform and the
    /// bounds of every load and store are written once, here.
    pub(super) trait Key:
        Copy
        + PartialEq
        + Default
        + radsort::Key
        + pulp::bytemuck::Pod
        + Not<Output = Self>
        + BitOr<Output = Self>
        + BitAnd<Output = Self>
        + Add<Output = Self>
    {
        /// Keys a vector.
        const L: usize;
        /// The largest key: the padding of a partial vector, sorted last.
        const MAX: Self;
        /// The sign bit of the score's bits.
        const SIGN: Self;
        /// One.
        const ONE: Self;
        fn splat(simd: V4, k: Self) -> __m512i;
        fn lanes_min(simd: V4, a: __m512i, b: __m512i) -> __m512i;
        fn lanes_max(simd: V4, a: __m512i, b: __m512i) -> __m512i;
        /// Lane i from `b` where bit i of `m` is set, else from `a`.
        fn blend(simd: V4, m: u16, a: __m512i, b: __m512i) -> __m512i;
        /// The lanes of `m` whose key is below `p`'s.
        fn below(simd: V4, m: u16, x: __m512i, p: __m512i) -> u16;
        /// Lane i of `x` moved to lane i ^ j.
        fn swap(simd: V4, x: __m512i, j: usize) -> __m512i;
        /// The lanes of `x` in reverse order.
        fn reverse(simd: V4, x: __m512i) -> __m512i;
        /// The lanes of `x` sorted.
        fn sort_vector(simd: V4, x: __m512i) -> __m512i;
        /// A bitonic vector sorted.
        fn clean_vector(simd: V4, x: __m512i) -> __m512i;
        /// The lanes of `m` read at `at`, `fill`'s elsewhere.
        ///
        /// # Safety
        /// `at` is valid for reads of the lanes of `m`.
        unsafe fn masked_load(simd: V4, fill: __m512i, m: u16, at: *const Self) -> __m512i;
        /// The lanes of `m` written at `at`.
        ///
        /// # Safety
        /// `at` is valid for writes of the lanes of `m`.
        unsafe fn masked_store(simd: V4, at: *mut Self, m: u16, x: __m512i);
        /// The lanes of `m`, in order, written at `at`.
        ///
        /// # Safety
        /// `at` is valid for writes of popcount(m) keys.
        unsafe fn compress_store_at(simd: V4, at: *mut Self, m: u16, x: __m512i);

        /// The key of a score's bits: unsigned order is IEEE total order.
        #[inline(always)]
        fn key(self) -> Self {
            if self & Self::SIGN == Self::default() {
                self | Self::SIGN
            } else {
                !self
            }
        }
        /// The score's bits back from its key.
        #[inline(always)]
        fn unkey(self) -> Self {
            if self & Self::SIGN == Self::default() {
                !self
            } else {
                self & !Self::SIGN
            }
        }
        /// The next key (`self` is not `MAX`).
        #[inline(always)]
        fn next(self) -> Self {
            self + Self::ONE
        }
        /// `v` (at most `L` keys) in the first lanes, `MAX` in the others.
        #[inline(always)]
        fn load(simd: V4, v: &[Self]) -> __m512i {
            if v.len() == Self::L {
                // A whole vector, without a mask (the partitions' loop).
                return pulp::bytemuck::pod_read_unaligned(pulp::bytemuck::cast_slice(v));
            }
            assert!(v.len() < Self::L);
            // SAFETY: reads the first v.len() lanes only.
            unsafe { Self::masked_load(simd, Self::splat(simd, Self::MAX), live(v.len()), v.as_ptr()) }
        }
        /// The first `out.len()` (at most `L`) lanes of `x` into `out`.
        #[inline(always)]
        fn store(simd: V4, x: __m512i, out: &mut [Self]) {
            if out.len() == Self::L {
                pulp::bytemuck::cast_slice_mut(out).copy_from_slice(pulp::bytemuck::bytes_of(&x));
                return;
            }
            assert!(out.len() < Self::L);
            // SAFETY: writes the first out.len() lanes only.
            unsafe { Self::masked_store(simd, out.as_mut_ptr(), live(out.len()), x) }
        }
        /// The lanes of `m`, in order, into `out` (as long as `m` has lanes).
        #[inline(always)]
        fn compress_store(simd: V4, m: u16, x: __m512i, out: &mut [Self]) {
            assert_eq!(out.len(), m.count_ones() as usize);
            // SAFETY: writes popcount(m) = out.len() keys at its start.
            unsafe { Self::compress_store_at(simd, out.as_mut_ptr(), m, x) }
        }
    }

    /// The lanes (of `n`) that keep the larger key in step (j, k) of an ascending bitonic
    /// sort: those where bit j and bit k of the lane differ.
    const fn larger(n: usize, j: usize, k: usize) -> u16 {
        let mut m = 0;
        let mut i = 0;
        while i < n {
            if (i & j != 0) != (i & k != 0) {
                m |= 1 << i;
            }
            i += 1;
        }
        m
    }

    /// The first `n` (at most 16) lanes.
    #[inline(always)]
    fn live(n: usize) -> u16 {
        ((1u32 << n) - 1) as u16
    }

    /// One compare-exchange step: each lane against lane i ^ j; the lanes of
    /// `keep_larger` keep the larger key.
    #[inline(always)]
    fn exchange<K: Key>(simd: V4, x: __m512i, j: usize, keep_larger: u16) -> __m512i {
        let partner = K::swap(simd, x, j);
        K::blend(
            simd,
            keep_larger,
            K::lanes_min(simd, x, partner),
            K::lanes_max(simd, x, partner),
        )
    }

    /// `i ^ j` for every lane `i` of `n`, in lanes of type `T`.
    const fn partners<T: Copy, const N: usize>(j: usize, lane: [T; 16]) -> [T; N] {
        let mut p = [lane[0]; N];
        let mut i = 0;
        while i < N {
            p[i] = lane[i ^ j];
            i += 1;
        }
        p
    }

    /// 0..16, as `u32` lanes.
    const U32_LANES: [u32; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15];
    /// 0..8 (then padding), as `u64` lanes.
    const U64_LANES: [u64; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 0, 0, 0, 0, 0, 0, 0, 0];

    impl Key for u32 {
        const L: usize = 16;
        const MAX: Self = u32::MAX;
        const SIGN: Self = 1 << 31;
        const ONE: Self = 1;
        #[inline(always)]
        fn splat(simd: V4, k: Self) -> __m512i {
            simd.avx512f._mm512_set1_epi32(k as i32)
        }
        #[inline(always)]
        fn lanes_min(simd: V4, a: __m512i, b: __m512i) -> __m512i {
            simd.avx512f._mm512_min_epu32(a, b)
        }
        #[inline(always)]
        fn lanes_max(simd: V4, a: __m512i, b: __m512i) -> __m512i {
            simd.avx512f._mm512_max_epu32(a, b)
        }
        #[inline(always)]
        fn blend(simd: V4, m: u16, a: __m512i, b: __m512i) -> __m512i {
            simd.avx512f._mm512_mask_blend_epi32(m, a, b)
        }
        #[inline(always)]
        fn below(simd: V4, m: u16, x: __m512i, p: __m512i) -> u16 {
            simd.avx512f._mm512_mask_cmplt_epu32_mask(m, x, p)
        }
        #[inline(always)]
        fn swap(simd: V4, x: __m512i, j: usize) -> __m512i {
            let idx: [u32; 16] = match j {
                1 => const { partners(1, U32_LANES) },
                2 => const { partners(2, U32_LANES) },
                4 => const { partners(4, U32_LANES) },
                _ => const { partners(8, U32_LANES) },
            };
            simd.avx512f._mm512_permutexvar_epi32(pulp::bytemuck::cast(idx), x)
        }
        #[inline(always)]
        fn reverse(simd: V4, x: __m512i) -> __m512i {
            simd.avx512f
                ._mm512_permutexvar_epi32(pulp::bytemuck::cast(const { partners::<u32, 16>(15, U32_LANES) }), x)
        }
        #[inline(always)]
        unsafe fn masked_load(simd: V4, fill: __m512i, m: u16, at: *const Self) -> __m512i {
            // SAFETY: the caller's.
            unsafe { simd.avx512f._mm512_mask_loadu_epi32(fill, m, at.cast()) }
        }
        #[inline(always)]
        unsafe fn masked_store(simd: V4, at: *mut Self, m: u16, x: __m512i) {
            // SAFETY: the caller's.
            unsafe { simd.avx512f._mm512_mask_storeu_epi32(at.cast(), m, x) }
        }
        #[inline(always)]
        unsafe fn compress_store_at(simd: V4, at: *mut Self, m: u16, x: __m512i) {
            // SAFETY: the caller's.
            unsafe { simd.avx512f._mm512_mask_compressstoreu_epi32(at.cast(), m, x) }
        }
        #[inline(always)]
        fn sort_vector(simd: V4, x: __m512i) -> __m512i {
            let x = exchange::<Self>(simd, x, 1, const { larger(16, 1, 2) });
            let x = exchange::<Self>(simd, x, 2, const { larger(16, 2, 4) });
            let x = exchange::<Self>(simd, x, 1, const { larger(16, 1, 4) });
            let x = exchange::<Self>(simd, x, 4, const { larger(16, 4, 8) });
            let x = exchange::<Self>(simd, x, 2, const { larger(16, 2, 8) });
            let x = exchange::<Self>(simd, x, 1, const { larger(16, 1, 8) });
            Self::clean_vector(simd, x)
        }
        #[inline(always)]
        fn clean_vector(simd: V4, x: __m512i) -> __m512i {
            let x = exchange::<Self>(simd, x, 8, const { larger(16, 8, 16) });
            let x = exchange::<Self>(simd, x, 4, const { larger(16, 4, 16) });
            let x = exchange::<Self>(simd, x, 2, const { larger(16, 2, 16) });
            exchange::<Self>(simd, x, 1, const { larger(16, 1, 16) })
        }
    }

    impl Key for u64 {
        const L: usize = 8;
        const MAX: Self = u64::MAX;
        const SIGN: Self = 1 << 63;
        const ONE: Self = 1;
        #[inline(always)]
        fn splat(simd: V4, k: Self) -> __m512i {
            simd.avx512f._mm512_set1_epi64(k as i64)
        }
        #[inline(always)]
        fn lanes_min(simd: V4, a: __m512i, b: __m512i) -> __m512i {
            simd.avx512f._mm512_min_epu64(a, b)
        }
        #[inline(always)]
        fn lanes_max(simd: V4, a: __m512i, b: __m512i) -> __m512i {
            simd.avx512f._mm512_max_epu64(a, b)
        }
        #[inline(always)]
        fn blend(simd: V4, m: u16, a: __m512i, b: __m512i) -> __m512i {
            simd.avx512f._mm512_mask_blend_epi64(m as u8, a, b)
        }
        #[inline(always)]
        fn below(simd: V4, m: u16, x: __m512i, p: __m512i) -> u16 {
            simd.avx512f._mm512_mask_cmplt_epu64_mask(m as u8, x, p).into()
        }
        #[inline(always)]
        fn swap(simd: V4, x: __m512i, j: usize) -> __m512i {
            let idx: [u64; 8] = match j {
                1 => const { partners(1, U64_LANES) },
                2 => const { partners(2, U64_LANES) },
                _ => const { partners(4, U64_LANES) },
            };
            simd.avx512f._mm512_permutexvar_epi64(pulp::bytemuck::cast(idx), x)
        }
        #[inline(always)]
        fn reverse(simd: V4, x: __m512i) -> __m512i {
            simd.avx512f
                ._mm512_permutexvar_epi64(pulp::bytemuck::cast(const { partners::<u64, 8>(7, U64_LANES) }), x)
        }
        #[inline(always)]
        unsafe fn masked_load(simd: V4, fill: __m512i, m: u16, at: *const Self) -> __m512i {
            // SAFETY: the caller's.
            unsafe { simd.avx512f._mm512_mask_loadu_epi64(fill, m as u8, at.cast()) }
        }
        #[inline(always)]
        unsafe fn masked_store(simd: V4, at: *mut Self, m: u16, x: __m512i) {
            // SAFETY: the caller's.
            unsafe { simd.avx512f._mm512_mask_storeu_epi64(at.cast(), m as u8, x) }
        }
        #[inline(always)]
        unsafe fn compress_store_at(simd: V4, at: *mut Self, m: u16, x: __m512i) {
            // SAFETY: the caller's.
            unsafe { simd.avx512f._mm512_mask_compressstoreu_epi64(at.cast(), m as u8, x) }
        }
        #[inline(always)]
        fn sort_vector(simd: V4, x: __m512i) -> __m512i {
            let x = exchange::<Self>(simd, x, 1, const { larger(8, 1, 2) });
            let x = exchange::<Self>(simd, x, 2, const { larger(8, 2, 4) });
            let x = exchange::<Self>(simd, x, 1, const { larger(8, 1, 4) });
            Self::clean_vector(simd, x)
        }
        #[inline(always)]
        fn clean_vector(simd: V4, x: __m512i) -> __m512i {
            let x = exchange::<Self>(simd, x, 4, const { larger(8, 4, 8) });
            let x = exchange::<Self>(simd, x, 2, const { larger(8, 2, 8) });
            exchange::<Self>(simd, x, 1, const { larger(8, 1, 8) })
        }
    }

    /// The keys (of scores' bits) sorted with `V4`; ranges still unsorted after the
    /// given number of partitions go to `radsort`.
    pub(super) struct Quicksort<'a, K>(pub V4, pub &'a mut [K], pub u32);

    impl<K: Key> pulp::WithSimd for Quicksort<'_, K> {
        type Output = ();

        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) {
            let Self(simd, keys, depth) = self;
            keys.iter_mut().for_each(|k| *k = k.key());
            sort_keys(simd, keys, depth);
            keys.iter_mut().for_each(|k| *k = k.unkey());
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
    fn sort_keys<K: Key>(simd: V4, keys: &mut [K], depth: u32) {
        if keys.len() <= 8 * K::L {
            // Sorted in registers: no spare buffer.
            return small(simd, None, keys);
        }
        let mut spare = vec![K::default(); keys.len()];
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
                if r.len <= 8 * K::L {
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
                    if pivot == K::MAX {
                        // Every key is the largest.
                        if !r.in_column {
                            keys[span.clone()].copy_from_slice(&spare[span]);
                        }
                        break;
                    }
                    below = partition(simd, src, dst, pivot.next());
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
    fn partition<K: Key>(simd: V4, src: &[K], dst: &mut [K], pivot: K) -> usize {
        let p = K::splat(simd, pivot);
        let (mut below, mut above) = (0, src.len());
        for chunk in src.chunks(K::L) {
            let x = K::load(simd, chunk);
            let lt = K::below(simd, live(chunk.len()), x, p);
            let ge = live(chunk.len()) & !lt;
            let (c_lt, c_ge) = (lt.count_ones() as usize, ge.count_ones() as usize);
            K::compress_store(simd, lt, x, &mut dst[below..below + c_lt]);
            below += c_lt;
            above -= c_ge;
            K::compress_store(simd, ge, x, &mut dst[above..above + c_ge]);
        }
        debug_assert_eq!(below, above);
        below
    }

    /// The median of `L` keys sampled evenly across `v` (more than `L` long).
    #[inline(always)]
    fn pivot<K: Key>(simd: V4, v: &[K]) -> K {
        let (n, l) = (v.len(), K::L);
        let mut sample = [K::MAX; 16];
        for (i, s) in sample[..l].iter_mut().enumerate() {
            *s = v[(2 * i + 1) * n / (2 * l)];
        }
        K::store(
            simd,
            K::sort_vector(simd, K::load(simd, &sample[..l])),
            &mut sample[..l],
        );
        sample[l / 2]
    }

    /// The keys of `src` (at most 8 vectors; `None`: those of `dst`) sorted into `dst`.
    #[inline(always)]
    fn small<K: Key>(simd: V4, src: Option<&[K]>, dst: &mut [K]) {
        let vectors = dst.len().div_ceil(K::L);
        match vectors {
            0..=1 => small_m::<K, 1>(simd, src, dst),
            2 => small_m::<K, 2>(simd, src, dst),
            3..=4 => small_m::<K, 4>(simd, src, dst),
            _ => small_m::<K, 8>(simd, src, dst),
        }
    }

    /// [`small`] for at most `M` vectors of keys.
    #[inline(always)]
    fn small_m<K: Key, const M: usize>(simd: V4, src: Option<&[K]>, dst: &mut [K]) {
        let block = sorted::<K, M>(simd, src.unwrap_or(dst));
        for (x, out) in block.iter().zip(dst.chunks_mut(K::L)) {
            K::store(simd, *x, out);
        }
    }

    /// The keys of `v` (at most `M` vectors) sorted, padded with `MAX`.
    #[inline(always)]
    fn sorted<K: Key, const M: usize>(simd: V4, v: &[K]) -> [__m512i; M] {
        let mut chunks = v.chunks(K::L);
        let mut block = [0; M].map(|_: u8| K::load(simd, chunks.next().unwrap_or(&[])));
        for x in &mut block {
            *x = K::sort_vector(simd, *x);
        }
        // Bitonic merges of sorted blocks of h vectors into blocks of 2h.
        let mut h = 1;
        while h < M {
            for b in (0..M).step_by(2 * h) {
                // The lower block against the upper one reversed: the smaller halves
                // are the merged block's first h vectors, the larger its last h, and
                // each half is bitonic.
                for i in 0..h {
                    let (a, c) = (block[b + i], K::reverse(simd, block[b + 2 * h - 1 - i]));
                    block[b + i] = K::lanes_min(simd, a, c);
                    block[b + 2 * h - 1 - i] = K::lanes_max(simd, a, c);
                }
                block[b + h..b + 2 * h].reverse();
                // Half-cleaners across vectors, then within each.
                let mut t = h / 2;
                while t >= 1 {
                    for g in (b..b + 2 * h).step_by(2 * t) {
                        for i in g..g + t {
                            let (a, c) = (block[i], block[i + t]);
                            block[i] = K::lanes_min(simd, a, c);
                            block[i + t] = K::lanes_max(simd, a, c);
                        }
                    }
                    t /= 2;
                }
                for x in &mut block[b..b + 2 * h] {
                    *x = K::clean_vector(simd, *x);
                }
            }
            h *= 2;
        }
        block
    }

    #[cfg(test)]
    pub(super) fn sort_with_depth<K: Key>(keys: &mut [K], depth: u32) -> bool {
        match V4::try_new() {
            Some(simd) => {
                pulp::Simd::vectorize(simd, Quicksort(simd, keys, depth));
                true
            }
            None => false,
        }
    }
}

#[cfg(test)]
mod tests {
    //! The vectorised sort is compared with the scalar one, and the scalar one with the
    //! standard library's `total_cmp` order. The first needs AVX-512: on a CPU without
    //! it, its tests are reported ignored (`build.rs` sets `qtvpr_no_avx512`), and if
    //! run all the same (`--include-ignored`) each says it skipped; the scalar tests
    //! run everywhere.
    use proptest::prelude::*;

    /// Whether the vectorised sort runs here; if not, says why on stderr.
    fn vector_sort_runs(why_not: &str) -> bool {
        #[cfg(target_arch = "x86_64")]
        if pulp::x86::V4::try_new().is_some() {
            return true;
        }
        eprintln!("skipped: {why_not}");
        false
    }

    /// Tests of the vectorised sort: each reported ignored, for `$why_not`, where
    /// `build.rs` found no AVX-512, and a skip saying so if run there all the same.
    macro_rules! vector_sort_tests {
        ($why_not:literal; $(fn $name:ident() $body:block)*) => {$(
            #[test]
            #[cfg_attr(qtvpr_no_avx512, ignore = $why_not)]
            fn $name() {
                if vector_sort_runs($why_not) $body
            }
        )*};
    }

    /// `v` sorted by the vectorised sort with the given depth limit and by
    /// [`super::scalar_f32`]: the same bits. False without AVX-512 (nothing compared).
    fn agrees_f32(v: &[f32], depth: u32) -> bool {
        let mut want = v.to_vec();
        super::scalar_f32(&mut want);
        let mut got: Vec<u32> = v.iter().map(|x| x.to_bits()).collect();
        #[cfg(target_arch = "x86_64")]
        if super::avx512::sort_with_depth(&mut got, depth) {
            let want: Vec<u32> = want.iter().map(|x| x.to_bits()).collect();
            assert_eq!(got, want, "{} f32 scores, depth {depth}", v.len());
            return true;
        }
        false
    }

    /// [`agrees_f32`] for `f64` scores.
    fn agrees_f64(v: &[f64], depth: u32) -> bool {
        let mut want = v.to_vec();
        super::scalar_f64(&mut want);
        let mut got: Vec<u64> = v.iter().map(|x| x.to_bits()).collect();
        #[cfg(target_arch = "x86_64")]
        if super::avx512::sort_with_depth(&mut got, depth) {
            let want: Vec<u64> = want.iter().map(|x| x.to_bits()).collect();
            assert_eq!(got, want, "{} f64 scores, depth {depth}", v.len());
            return true;
        }
        false
    }

    /// Both types, the depth limit of the core.
    fn agrees(v: &[f32]) -> bool {
        let wide: Vec<f64> = v.iter().map(|&x| f64::from(x)).collect();
        agrees_f32(v, depth(v.len())) & agrees_f64(&wide, depth(v.len()))
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

    /// The scalar sort of `v` is the standard library's `total_cmp` order, bit for bit,
    /// in both widths; and so is [`super::sort_f32`] / [`super::sort_f64`], whichever
    /// path this CPU takes.
    fn in_total_order(v: &[f32]) {
        let mut want = v.to_vec();
        want.sort_by(f32::total_cmp);
        let want: Vec<u32> = want.iter().map(|x| x.to_bits()).collect();
        let mut wide_want: Vec<f64> = v.iter().map(|&x| f64::from(x)).collect();
        wide_want.sort_by(f64::total_cmp);
        let wide_want: Vec<u64> = wide_want.iter().map(|x| x.to_bits()).collect();
        for sort in [super::scalar_f32 as fn(&mut [f32]), super::sort_f32] {
            let mut got = v.to_vec();
            sort(&mut got);
            assert_eq!(
                got.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                want,
                "{} f32 scores",
                v.len()
            );
        }
        for sort in [super::scalar_f64 as fn(&mut [f64]), super::sort_f64] {
            let mut got: Vec<f64> = v.iter().map(|&x| f64::from(x)).collect();
            sort(&mut got);
            assert_eq!(
                got.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                wide_want,
                "{} f64 scores",
                v.len()
            );
        }
    }

    #[test]
    fn the_scalar_sort_is_total_order_at_every_length() {
        for (seed, n) in (0..=300).chain([1000, 4097, 27_592]).enumerate() {
            in_total_order(&scores(n, seed as u64));
        }
        // Its order, written out: -NaN, -inf, negatives, -0, +0, subnormals, positives,
        // +inf, NaN.
        let mut v = [
            f32::NAN,
            1.0,
            -0.0,
            f32::INFINITY,
            0.0,
            -f32::NAN,
            -2.0,
            f32::MIN_POSITIVE / 2.0,
            f32::NEG_INFINITY,
        ];
        super::scalar_f32(&mut v);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let want = [
            -f32::NAN,
            f32::NEG_INFINITY,
            -2.0,
            -0.0,
            0.0,
            f32::MIN_POSITIVE / 2.0,
            1.0,
            f32::INFINITY,
            f32::NAN,
        ];
        assert_eq!(bits(&v), bits(&want));
    }

    /// Columns of few values and ordered columns, the vectorised sort's hard cases.
    fn hard_columns() -> Vec<Vec<f32>> {
        let n = 5000;
        vec![
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
            // Keys at the top of the range (-NaN's key is the largest).
            vec![-f32::NAN; n],
        ]
    }

    #[test]
    fn the_scalar_sort_orders_columns_of_few_values_and_ordered_columns() {
        for v in &hard_columns() {
            in_total_order(v);
        }
    }

    vector_sort_tests! {
        "this CPU has no AVX-512: the vectorised sort cannot run (the scalar sort's tests do)";

        fn every_length_gives_the_scalar_sorts_bits() {
            let lengths = (0..=700).chain([1000, 4097, 27_592, 100_003]);
            for (seed, n) in lengths.enumerate() {
                assert!(agrees(&scores(n, seed as u64)));
            }
        }

        fn float64_bits_beyond_float32_sort_as_the_scalar_sort_sorts_them() {
            let mut x = 3u64;
            let v: Vec<f64> = (0..20_000)
                .map(|i| {
                    x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    // Neighbours that differ only in the low bits, and arbitrary bits.
                    if i % 2 == 0 {
                        0.5 + (x >> 40) as f64 * f64::EPSILON
                    } else {
                        f64::from_bits(x)
                    }
                })
                .collect();
            assert!(agrees_f64(&v, depth(v.len())));
        }

        fn columns_of_few_values_and_ordered_columns() {
            for v in &hard_columns() {
                assert!(agrees(v));
            }
        }

        fn ranges_past_the_depth_limit_go_to_the_scalar_sort() {
            for d in 0..4 {
                for v in [scores(3000, 9), (0..3000).map(|i| (i % 5) as f32).collect()] {
                    let wide: Vec<f64> = v.iter().map(|&x| f64::from(x)).collect();
                    assert!(agrees_f32(&v, d));
                    assert!(agrees_f64(&wide, d));
                }
            }
        }
    }

    proptest! {
        #[test]
        fn any_bits_sort_in_total_order(bits in proptest::collection::vec(any::<u64>(), 0..2000)) {
            let v: Vec<f32> = bits.iter().map(|&b| f32::from_bits(b as u32)).collect();
            in_total_order(&v);
            // The vectorised sort where it runs (these cases run on every CPU).
            agrees_f32(&v, depth(v.len()));
            let v: Vec<f64> = bits.into_iter().map(f64::from_bits).collect();
            agrees_f64(&v, depth(v.len()));
        }

        #[test]
        fn few_distinct_scores_sort_in_total_order(ix in proptest::collection::vec(0usize..4, 0..3000)) {
            let v: Vec<f32> = ix.into_iter().map(|i| [-0.0, 0.0, 0.5, 0.5000001][i]).collect();
            in_total_order(&v);
            agrees(&v);
        }
    }
}
