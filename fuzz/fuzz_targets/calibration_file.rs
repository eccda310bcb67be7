//! The calibration file reader on arbitrary bytes: every input must give a calibration
//! or a typed error, never a panic, an abort or a huge allocation (a decompression bomb
//! or a header claiming more than the bytes hold).

#![no_main]

use std::hint::black_box;

use libfuzzer_sys::fuzz_target;
use qtvpr::Calibration;

fuzz_target!(|data: &[u8]| {
    if let Ok(cal) = Calibration::from_bytes(data, "fuzz.npz") {
        // A loaded calibration must be usable: a threshold at every tau tried.
        for tau in [0.5, 1.0] {
            black_box(cal.threshold(tau).ok());
        }
    }
});
