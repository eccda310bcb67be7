//! Reading and writing: the calibration file (§12), the machine-readable documents of a
//! run (§9, feature `serde`), and [`npy`](mod@npy), the one checked `.npy`/`.npz`
//! reader and the atomic writers (feature `npy`).

pub(crate) mod calibration_file;
#[cfg(feature = "npy")]
pub mod npy;
pub(crate) mod report;
