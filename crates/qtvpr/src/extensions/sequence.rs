//! Extension (not a section of the semantics): SeqSLAM-style sequence matching of a similarity matrix.
//!
//! The paper thresholds single-frame similarity and names sequence matching as future
//! work; this module provides it so that users of sequential traverses (Nordland, SFU,
//! Oxford) can threshold the much stronger sequence scores the same way. For a sequence
//! length `L` (odd, >= 1):
//!
//! - **centred** (offline): `S_seq[i, j]` is the mean of `S[i + d, j + d]` for
//!   `d` in `-(L-1)/2 ..= (L-1)/2`;
//! - **causal** (online, as a robot sees its past frames only): `d` in `-(L-1) ..= 0`;
//!
//! in both cases over the offsets that keep `(i + d, j + d)` inside the matrix, so the
//! edges average fewer terms (never zero: `d = 0` always counts). This assumes the two
//! traverses run in the same direction at a similar frame rate, as SeqSLAM's constant
//! velocity search does at velocity 1.
//!
//! # Cost
//! O(|DB| |Q|) whatever `L`, by a running sum along the diagonals: the window sums of
//! row `i + 1` are those of row `i` shifted by one column, less the entries that leave
//! and plus the entries that enter. Rows are processed in parallel blocks, each block
//! starting from freshly summed windows, so rounding cannot drift across the matrix:
//! sums are in `f64` and the running error stays below (block length) x 2^-52 x (the
//! largest |score| in the block), under 1e-13 for cosine scores.

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::input::{Score, validate_scores};
use crate::platform::threads;

/// A score type [`sequence_match`] can return: `f32` or `f64`.
pub trait FromF64: Score {
    /// Round an `f64` to this type.
    fn from_f64(v: f64) -> Self;
}

impl FromF64 for f32 {
    #[inline]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl FromF64 for f64 {
    #[inline]
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// The sequence window: its length and whether it looks back only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sequence {
    /// Number of frames in the window: odd, at least 1 (1 leaves the matrix unchanged).
    pub length: usize,
    /// `true`: the window is the current frame and the `length - 1` before it (online);
    /// `false`: it is centred on the current frame (offline).
    pub causal: bool,
}

impl Sequence {
    /// A centred window of `length` frames.
    pub fn centred(length: usize) -> Self {
        Self { length, causal: false }
    }

    /// A causal window: the current frame and the `length - 1` before it.
    pub fn causal(length: usize) -> Self {
        Self { length, causal: true }
    }

    /// Check that the length is odd and at least 1.
    ///
    /// Even lengths are refused for both windows, so that a causal and a centred window
    /// of the same length always average the same number of frames.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `sequence`.
    pub fn validate(&self) -> Result<()> {
        if self.length == 0 || self.length.is_multiple_of(2) {
            return Err(Error::param(
                "sequence",
                format!("length must be odd and >= 1, got {}", self.length),
            ));
        }
        Ok(())
    }

    /// The offsets `d` of the window, as `(first, last)`, both inclusive.
    pub fn offsets(&self) -> (isize, isize) {
        let l = self.length as isize;
        if self.causal {
            (1 - l, 0)
        } else {
            (-(l - 1) / 2, (l - 1) / 2)
        }
    }
}

/// Sequence-matched similarity: every entry replaced by the mean of the window of
/// entries along its diagonal (see the module docs of `extensions/sequence.rs`).
///
/// `s` is any |DB| x |Q| matrix of `f32` or `f64` with any strides; the result has the
/// same shape and type, in standard (C) order. The operation commutes with
/// transposition, so query-major matrices need no special treatment.
///
/// # Errors
/// [`Error::InvalidParameter`] for an even or zero length, [`Error::Empty`] or
/// [`Error::NotFinite`] for an empty or non-finite `s`.
pub fn sequence_match<T: FromF64>(s: ArrayView2<'_, T>, sequence: Sequence) -> Result<Array2<T>> {
    threads::install(|| {
        sequence.validate()?;
        validate_scores(Input::Similarity, s)?;
        let (n, m) = s.dim();
        let (lo, hi) = sequence.offsets();
        // Rows per block: at least the window length, so that the O(L |Q|) start of each
        // block costs no more than sliding through it.
        let block = sequence.length.max(64);
        let window = Window { s, lo, hi };
        // Row-major |DB| x |Q|.
        let mut out = vec![T::from_f64(0.0); n * m];
        out.par_chunks_mut(block * m).enumerate().for_each(|(b, rows)| {
            let first = b * block;
            let mut sums: Vec<f64> = (0..m).map(|j| window.sum(first, j)).collect();
            for (r, row) in rows.chunks_mut(m).enumerate() {
                let i = first + r;
                if r > 0 {
                    window.slide(i - 1, &mut sums);
                }
                let (last, first) = window.row_bounds(i);
                for (j, (o, &sum)) in row.iter_mut().zip(&sums).enumerate() {
                    // The offsets inside the matrix: max(lo, -i, -j) ..= min(hi, n-1-i, m-1-j).
                    let j = j as isize;
                    let count = last.min(m as isize - 1 - j) - first.max(-j) + 1;
                    *o = T::from_f64(sum / count as f64);
                }
            }
        });
        Ok(Array2::from_shape_vec((n, m), out).expect("shape matches length"))
    })
}

/// The window sums of one matrix, with zero padding outside it.
struct Window<'a, T> {
    s: ArrayView2<'a, T>,
    lo: isize,
    hi: isize,
}

impl<T: Score> Window<'_, T> {
    /// `S[i, j]`, or 0 outside the matrix.
    #[inline]
    fn at(&self, i: isize, j: isize) -> f64 {
        let (n, m) = self.s.dim();
        if i < 0 || j < 0 || i >= n as isize || j >= m as isize {
            return 0.0;
        }
        self.s[[i as usize, j as usize]].to_f64()
    }

    /// The window sum at `(i, j)`, summed afresh.
    fn sum(&self, i: usize, j: usize) -> f64 {
        (self.lo..=self.hi)
            .map(|d| self.at(i as isize + d, j as isize + d))
            .sum()
    }

    /// For row `i`, the bounds of the offsets that keep the row inside the matrix:
    /// `(min(hi, n-1-i), max(lo, -i))`; the column bounds are applied per entry.
    fn row_bounds(&self, i: usize) -> (isize, isize) {
        let (n, i) = (self.s.nrows() as isize, i as isize);
        (self.hi.min(n - 1 - i), self.lo.max(-i))
    }

    /// Turn the window sums of row `i` into those of row `i + 1`:
    /// `W[i+1, j] = W[i, j-1] - S[i+lo, j-1+lo] + S[i+1+hi, j+hi]`, zero outside.
    fn slide(&self, i: usize, sums: &mut [f64]) {
        let (n, m) = self.s.dim();
        let (lo, hi) = (self.lo.unsigned_abs(), self.hi as usize);
        // Shift right by one column: sums[j] = W[i, j-1].
        sums.copy_within(0..m - 1, 1);
        // Leaving row i + lo (lo <= 0), column j - 1 + lo: inside for j in 1 + |lo| .. m.
        if i >= lo && 1 + lo < m {
            let leave = self.s.row(i - lo);
            for (w, v) in sums[1 + lo..].iter_mut().zip(leave.iter()) {
                *w -= v.to_f64();
            }
        }
        // Entering row i + 1 + hi, column j + hi: inside for j in 1 .. m - hi.
        if i + 1 + hi < n && 1 + hi < m {
            let enter = self.s.row(i + 1 + hi);
            for (w, v) in sums[1..m - hi].iter_mut().zip(enter.iter().skip(1 + hi)) {
                *w += v.to_f64();
            }
        }
        sums[0] = self.sum(i + 1, 0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    /// The definition, entry by entry: O(L |DB| |Q|).
    fn naive(s: &Array2<f64>, seq: Sequence) -> Array2<f64> {
        let (lo, hi) = seq.offsets();
        let (n, m) = s.dim();
        Array2::from_shape_fn((n, m), |(i, j)| {
            let terms: Vec<f64> = (lo..=hi)
                .map(|d| (i as isize + d, j as isize + d))
                .filter(|&(a, b)| a >= 0 && b >= 0 && a < n as isize && b < m as isize)
                .map(|(a, b)| s[[a as usize, b as usize]])
                .collect();
            terms.iter().sum::<f64>() / terms.len() as f64
        })
    }

    #[test]
    fn hand_computed_centred_window() {
        // L = 3, d in -1..=1.
        // S = [[1, 2, 3],
        //      [4, 5, 6]]
        // (0,0): S[0,0], S[1,1] = (1 + 5) / 2 = 3      (d = -1 is outside)
        // (0,1): S[0,1], S[1,2] = (2 + 6) / 2 = 4
        // (0,2): S[0,2] alone = 3                      (d = 1 would be column 3)
        // (1,0): S[1,0] alone = 4                      (d = -1 is column -1, d = 1 row 2)
        // (1,1): S[0,0], S[1,1] = (1 + 5) / 2 = 3
        // (1,2): S[0,1], S[1,2] = (2 + 6) / 2 = 4
        let s = array![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let got = sequence_match(s.view(), Sequence::centred(3)).unwrap();
        assert_eq!(got, array![[3.0, 4.0, 3.0], [4.0, 3.0, 4.0]]);
    }

    #[test]
    fn hand_computed_causal_window() {
        // L = 3 causal, d in -2..=0, on the same S:
        // (0,j): only d = 0 -> S[0,j] = 1, 2, 3
        // (1,0): d = 0 only -> 4;  (1,1): S[0,0] + S[1,1] = 6 / 2 = 3;
        // (1,2): S[0,1] + S[1,2] = 8 / 2 = 4.
        let s = array![[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let got = sequence_match(s.view(), Sequence::causal(3)).unwrap();
        assert_eq!(got, array![[1.0f32, 2.0, 3.0], [4.0, 3.0, 4.0]]);
    }

    #[test]
    fn length_one_is_the_identity() {
        let s = array![[0.25, -1.5], [3.0, 0.125], [7.0, 8.0]];
        assert_eq!(sequence_match(s.view(), Sequence::centred(1)).unwrap(), s);
        assert_eq!(sequence_match(s.view(), Sequence::causal(1)).unwrap(), s);
    }

    #[test]
    fn running_sum_equals_the_definition() {
        // Several blocks (200 rows > 64), windows longer than the matrix is wide, a
        // transposed view: the running sum must agree with the naive mean.
        let s = Array2::from_shape_fn((200, 37), |(i, j)| {
            (((i * 7919 + j * 104729) % 1009) as f64) / 1009.0 - 0.3
        });
        for seq in [
            Sequence::centred(1),
            Sequence::centred(3),
            Sequence::centred(11),
            Sequence::causal(11),
            Sequence::centred(99),
            Sequence::causal(401),
        ] {
            let want = naive(&s, seq);
            let got = sequence_match(s.view(), seq).unwrap();
            let err = (&got - &want).iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(err < 1e-12, "{seq:?}: {err}");
            // Transposition commutes with sequence matching.
            let got_t = sequence_match(s.t(), seq).unwrap();
            let err = (&got_t - &want.t()).iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(err < 1e-12, "{seq:?} transposed: {err}");
        }
    }

    #[test]
    fn bad_lengths_and_scores() {
        let s = array![[1.0, 2.0], [3.0, 4.0]];
        for length in [0, 2, 10] {
            for seq in [Sequence::centred(length), Sequence::causal(length)] {
                assert_eq!(
                    sequence_match(s.view(), seq).unwrap_err().to_string(),
                    format!("sequence length must be odd and >= 1, got {length}")
                );
            }
        }
        let nan = array![[1.0, f64::NAN]];
        assert!(matches!(
            sequence_match(nan.view(), Sequence::centred(3)),
            Err(Error::NotFinite { row: 0, col: 1, .. })
        ));
        assert!(matches!(
            sequence_match(Array2::<f32>::zeros((0, 3)).view(), Sequence::centred(3)),
            Err(Error::Empty { .. })
        ));
    }
}
