//! The core's sort (`Score::sort_ascending`: an AVX-512 quicksort with unsafe masked
//! loads and compress-stores where the CPU has AVX-512) on arbitrary bits of either
//! type: it never reads or writes outside the column (the sanitizer), and gives the
//! IEEE total order bit for bit (`total_cmp`, the order of its keys).

#![no_main]

use libfuzzer_sys::fuzz_target;
use qtvpr::Score;

/// `v` sorted by the core and by the standard library: the same bits.
fn check<T: Score>(mut v: Vec<T>, bits: impl Fn(&T) -> u64, total_cmp: impl Fn(&T, &T) -> std::cmp::Ordering) {
    let mut want = v.clone();
    want.sort_unstable_by(&total_cmp);
    T::sort_ascending(&mut v);
    assert!(v.iter().map(&bits).eq(want.iter().map(&bits)), "{} scores", v.len());
}

fuzz_target!(|data: &[u8]| {
    // The first byte picks the type; a column of few distinct values when it is odd
    // (the pivot's repartition), of any bits otherwise.
    let Some((&mode, rest)) = data.split_first() else { return };
    let few = |b: u8| [0.0, -0.0, 0.5, 1.0][usize::from(b % 4)];
    if mode & 2 == 0 {
        let v: Vec<f32> = if mode & 1 == 1 {
            rest.iter().map(|&b| few(b) as f32).collect()
        } else {
            rest.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
        };
        check(v, |x| u64::from(x.to_bits()), f32::total_cmp);
    } else {
        let v: Vec<f64> = if mode & 1 == 1 {
            rest.iter().map(|&b| few(b)).collect()
        } else {
            rest.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect()
        };
        check(v, |x| x.to_bits(), f64::total_cmp);
    }
});
