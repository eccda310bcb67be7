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
//! Centred: O(|DB| |Q|) whatever `L`, by a running sum along the diagonals: the window
//! sums of row `i + 1` are those of row `i` shifted by one column, less the entries that
//! leave and plus the entries that enter. Rows are processed in parallel blocks, each
//! block starting from freshly summed windows, so rounding cannot drift across the
//! matrix: sums are in `f64` and the running error stays below (block length) x 2^-52 x
//! (the largest |score| in the block), under 1e-13 for cosine scores.
//!
//! Causal: O(L |DB| |Q|), every entry summed afresh from its own terms, oldest first, by
//! one function ([`causal_mean`]). So a causal column depends on its `L` raw columns
//! alone, bit for bit: a stream that keeps only the last `L - 1` raw columns
//! ([`CausalStream`], semantics §15's online sequence matching) and a block of columns
//! preceded by its `L - 1` raw columns give exactly the matrix's values. (A running sum
//! would tie each entry's bits to every column back to the start of its row block.)

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use ndarray::ArrayView1;

use crate::error::names::Input;
use crate::error::{Error, Result};
use crate::input::{Score, validate_scores};
use crate::platform::threads;

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
pub fn sequence_match<T: Score>(s: ArrayView2<'_, T>, sequence: Sequence) -> Result<Array2<T>> {
    threads::install(|| {
        sequence.validate()?;
        validate_scores(Input::Similarity, s)?;
        if sequence.causal {
            return Ok(causal_match(s, sequence.length));
        }
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

/// The causal mean of one entry from its terms `S[i - d, j - d]`, oldest first
/// (`d = n - 1, ..., 0`, those inside the stream and the database): summed in `f64` from
/// `0.0` in that order and divided by their number. The one computation of a causal
/// sequence-matched score, for a matrix ([`sequence_match`]) and a stream
/// ([`CausalStream`]), so that both give the same bits.
#[inline]
pub(crate) fn causal_mean(terms: impl Iterator<Item = f64>) -> f64 {
    let (mut sum, mut n) = (0.0, 0u32);
    for t in terms {
        sum += t;
        n += 1;
    }
    sum / f64::from(n)
}

/// The causal sequence matching of a checked matrix: every entry its [`causal_mean`],
/// rows in parallel blocks (each row reads `L` rows of `s`, along its diagonals).
fn causal_match<T: Score>(s: ArrayView2<'_, T>, length: usize) -> Array2<T> {
    let (n, m) = s.dim();
    let mut out = vec![T::default(); n * m];
    out.par_chunks_mut(64 * m.max(1)).enumerate().for_each(|(b, rows)| {
        for (r, row) in rows.chunks_mut(m).enumerate() {
            let i = b * 64 + r;
            for (j, o) in row.iter_mut().enumerate() {
                let back = (length - 1).min(i).min(j);
                *o = T::from_f64(causal_mean((0..=back).rev().map(|d| s[[i - d, j - d]].to_f64())));
            }
        }
    });
    Array2::from_shape_vec((n, m), out).expect("shape matches length")
}

/// The causal sequence matching of a stream, one column at a time (semantics §15): the
/// last `L - 1` raw columns (as `f64`, a widening that changes no value), and each
/// arriving column's matched column, bit for bit the column of [`sequence_match`] with
/// [`Sequence::causal`] over the whole stream. Memory: `8 (L - 1) |DB|` bytes.
#[derive(Debug, Clone)]
pub(crate) struct CausalStream {
    length: usize,
    n_db: usize,
    /// The raw columns kept, slot after slot (|DB| scores each); the most recent in
    /// slot `(next + L - 2) % (L - 1)`.
    ring: Vec<f64>,
    /// How many are kept: up to `L - 1`.
    held: usize,
    /// The slot the next column goes into.
    next: usize,
}

impl CausalStream {
    /// A stream of columns of `n_db` scores, matched over `length` (odd, >= 1) of them;
    /// it takes its memory as columns arrive.
    pub(crate) fn new(length: usize, n_db: usize) -> Self {
        Self {
            length,
            n_db,
            ring: Vec::new(),
            held: 0,
            next: 0,
        }
    }

    /// The sequence length `L`.
    pub(crate) fn length(&self) -> usize {
        self.length
    }

    /// The raw column `d` queries back (`1..=held`).
    fn back(&self, d: usize) -> &[f64] {
        let slots = self.length - 1;
        let slot = (self.next + slots - d) % slots;
        &self.ring[slot * self.n_db..(slot + 1) * self.n_db]
    }

    /// The matched column of `column`, the stream's next (finite, |DB| scores), into
    /// `out` (|DB| long). The stream is not changed ([`CausalStream::keep`] does).
    pub(crate) fn matched<T: Score>(&self, column: ArrayView1<'_, T>, out: &mut [T]) {
        for (i, o) in out.iter_mut().enumerate() {
            let back = self.held.min(i);
            let term = |d: usize| {
                if d == 0 {
                    column[i].to_f64()
                } else {
                    self.back(d)[i - d]
                }
            };
            *o = T::from_f64(causal_mean((0..=back).rev().map(term)));
        }
    }

    /// Make room for one more raw column (fallibly: running out of memory is an error,
    /// not an abort), so that [`CausalStream::keep`] cannot fail.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `sequence` when the memory cannot be had.
    pub(crate) fn reserve(&mut self) -> Result<()> {
        let full = (self.length - 1) * self.n_db;
        if self.ring.len() >= full {
            return Ok(());
        }
        self.ring.try_reserve_exact(self.n_db).map_err(|_| {
            Error::param(
                "sequence",
                format!(
                    "length {} needs memory for {} x {} raw scores, which cannot be allocated",
                    self.length,
                    self.length - 1,
                    self.n_db
                ),
            )
        })
    }

    /// Keep `column` as the most recent raw column (the oldest leaves once `L - 1` are
    /// kept); [`CausalStream::reserve`] has made room for it.
    pub(crate) fn keep<T: Score>(&mut self, column: ArrayView1<'_, T>) {
        let slots = self.length - 1;
        if slots == 0 {
            return;
        }
        let values = column.iter().map(|v| v.to_f64());
        if self.ring.len() < slots * self.n_db {
            self.ring.extend(values);
        } else {
            let slot = &mut self.ring[self.next * self.n_db..(self.next + 1) * self.n_db];
            slot.iter_mut().zip(values).for_each(|(s, v)| *s = v);
        }
        self.next = (self.next + 1) % slots;
        self.held = (self.held + 1).min(slots);
    }
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

    #[test]
    fn a_stream_of_columns_gives_the_bits_of_the_matrix() {
        // 150 rows (three blocks of 64 rows, the last partial), 40 columns, L = 1, 3, 11
        // and 151 (longer than the stream and the database), f32 and f64, a C-order and
        // a transposed view: pushed one column at a time, each matched column is the
        // matrix's, bit for bit.
        let s = Array2::from_shape_fn((150, 40), |(i, j)| {
            (((i * 7919 + j * 104729) % 1009) as f64) / 1009.0 - 0.3
        });
        for length in [1, 3, 11, 151] {
            let want = sequence_match(s.view(), Sequence::causal(length)).unwrap();
            let want_t = sequence_match(s.t(), Sequence::causal(length)).unwrap();
            // The definition: each entry the mean of its terms.
            let err = (&want - &naive(&s, Sequence::causal(length)))
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(err < 1e-15, "{length}: {err}");
            let mut stream = CausalStream::new(length, 150);
            let mut out = vec![0.0; 150];
            for (j, column) in s.columns().into_iter().enumerate() {
                stream.matched(column, &mut out);
                assert!(
                    out.iter().zip(want.column(j)).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "L = {length}, column {j}"
                );
                stream.reserve().unwrap();
                stream.keep(column);
            }
            // The transpose as a stream of its 150 columns of 40 scores.
            let mut stream = CausalStream::new(length, 40);
            let mut out = vec![0.0; 40];
            for (j, column) in s.t().columns().into_iter().enumerate() {
                stream.matched(column, &mut out);
                assert!(
                    out.iter()
                        .zip(want_t.column(j))
                        .all(|(a, b)| a.to_bits() == b.to_bits())
                );
                stream.reserve().unwrap();
                stream.keep(column);
            }
            let s32 = s.mapv(|v| v as f32);
            let want32 = sequence_match(s32.view(), Sequence::causal(length)).unwrap();
            let mut stream = CausalStream::new(length, 150);
            let mut out = vec![0.0f32; 150];
            for (j, column) in s32.columns().into_iter().enumerate() {
                stream.matched(column, &mut out);
                assert!(
                    out.iter()
                        .zip(want32.column(j))
                        .all(|(a, b)| a.to_bits() == b.to_bits())
                );
                stream.reserve().unwrap();
                stream.keep(column);
            }
        }
        // A block preceded by its L - 1 raw columns gives the whole matrix's columns.
        let whole = sequence_match(s.view(), Sequence::causal(11)).unwrap();
        let block = sequence_match(s.slice(ndarray::s![.., 20..]), Sequence::causal(11)).unwrap();
        assert_eq!(block.slice(ndarray::s![.., 10..]), whole.slice(ndarray::s![.., 30..]));
    }

    #[test]
    fn causal_means_by_hand() {
        // L = 3, two terms at (1, 1) (d = 1: S[0, 0] = 1, d = 0: S[1, 1] = 5), oldest first.
        assert_eq!(causal_mean([1.0, 5.0].into_iter()), 3.0);
        // Summed in order from 0.0: 0.1 + 0.2 + 0.3 = 0.6000000000000001, / 3.
        assert_eq!(causal_mean([0.1, 0.2, 0.3].into_iter()), (0.1 + 0.2 + 0.3) / 3.0);
        // A stream keeps L - 1 = 2 columns: after 1, 2, 3 it holds 2 and 3, so the
        // fourth column's row 2 is (S[0, 1] + S[1, 2] + S[2, 3]) / 3 with rows 0..2.
        let mut stream = CausalStream::new(3, 3);
        for v in [1.0, 2.0, 3.0] {
            stream.reserve().unwrap();
            stream.keep(ndarray::array![v, 10.0 * v, 100.0 * v].view());
        }
        let mut out = [0.0; 3];
        stream.matched(ndarray::array![4.0, 40.0, 400.0].view(), &mut out);
        // Row 0: 4 alone; row 1: (3 + 40) / 2; row 2: (2 + 30 + 400) / 3.
        assert_eq!(out, [4.0, 21.5, 144.0]);
        assert_eq!(stream.length(), 3);
    }
}
