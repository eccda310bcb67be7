//! The machine the core runs on: the sort of a profile (an AVX-512 quicksort where the
//! CPU has it, else a radix sort) and the library's own thread pool, rebuilt in a
//! process forked after using it (§10).

pub(crate) mod sort;
pub(crate) mod threads;
