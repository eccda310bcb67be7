//! The CLI's integration tests, one test binary: each file of `tests/` is a module
//! (`cargo test -p qtvpr-cli --test cli evaluate::` runs one). One binary, not one per
//! file: each of those linked the core and every dependency again, most of a cold
//! `cargo test`'s link time.

mod common;

mod cli;
mod descriptors;
mod docs;
mod evaluate;
mod extensions;
mod help;
mod image_names;
mod inputs;
mod npz;
mod online;
mod outputs;
mod progress;
mod readme;
mod self_motion;
mod split;
