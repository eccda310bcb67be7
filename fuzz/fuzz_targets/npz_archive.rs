//! The zip layer of every `.npz` alone (crates/qtvpr/src/files/npy/archive.rs): the central
//! directory, the local headers, the extra fields and the members' deflate streams of
//! arbitrary bytes. Every input must be read to its end or refused with an error, never
//! a panic, an abort or an allocation larger than the bytes justify. `cargo test` runs a
//! fixed budget of structured mutations of the same function
//! (`the_zip_layer_survives_a_fixed_fuzzing_budget`).

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = qtvpr::npy::read_every_member(data);
});
