//! Reading `.npy` / `.npz` files (feature `npy`): the I/O the CLI and the Python binding
//! share, so that both accept exactly the same files with exactly the same errors.
//!
//! Not a section of the semantics. Similarity matrices (float32/float64, little-endian, C or Fortran
//! order) are **memory-mapped** and viewed in place, so a matrix near the size of RAM
//! costs no copy and only the pages the computation touches; anything else (big-endian,
//! misaligned data, a file that cannot be mapped) is read into memory by npyz. Ground
//! truth (bool or integer 0/1) is read by npyz and turned into a [`GroundTruth`] at once;
//! an `.npz` in the VPR_Tutorial convention (`GThard`, optional `GTsoft`) is accepted.
//!
//! Writing ([`write_npy`], [`write_npz`], [`write_atomically`]) is atomic: a temporary
//! file next to the target is filled and renamed over it, so an error never leaves a
//! half-written file, and the file gets the mode a plain create would give it under the
//! user's umask (0644 under umask 022), not a temporary file's 0600.
//!
//! Every error names the file and says what is wrong with it. A header is checked before
//! npyz parses it (at most 10000 bytes, as NumPy's `max_header_size`, and brackets at
//! most 6 deep), and a shape is checked against the largest possible array, so that a
//! corrupt or hostile file can neither hang the parser nor make the reader panic.
//!
//! [`GroundTruth`]: crate::input::GroundTruth

mod archive;
mod ground_truth;
mod guard;
mod header;
mod npz;
mod open;
mod read;
mod write;

pub use ground_truth::{
    add_soft_ground_truth, ground_truth_from_bytes, read_ground_truth, read_hard_ground_truth, write_ground_truth,
};
pub use header::{Header, inspect, matrix_shape};
pub use open::{is_zip_archive, open_input};
pub use read::{FloatMatrix, Matrix, MatrixFile, read_float_matrix, read_scores, scores_from_bytes};
pub use write::{NpyArray, write_atomically, write_npy, write_npz};

#[doc(hidden)]
pub use archive::read_every_member;
pub(crate) use archive::{Archive, open_npz_file};
pub(crate) use guard::guarded;
pub(crate) use npz::{Kind, npz_array, read_bool_matrix, read_owned_scores, read_string};
pub(crate) use write::write_npz_to;
