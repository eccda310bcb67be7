//! The core's integration tests, one test binary: each file of `tests/` is a module
//! (`cargo test -p qtvpr --test core screen::` runs one). One binary, not one per file:
//! each of those linked the core and its dependencies again. `fork.rs` stays a binary
//! of its own: it forks, and a child must not inherit other tests' threads mid-run.

mod blocks;
mod calibration_file;
mod confidence;
mod descriptors;
mod margin_gate;
mod online;
mod properties;
mod regressions;
mod screen;
mod self_motion;
mod semantics;
mod sequence_gate;
