//! Helpers shared by the CLI integration tests: running the binary in a directory,
//! `.npy` files written by hand, and the check that a command failed cleanly.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::Path;
use std::process::{Command, Output};

/// Zip archives, hostile ones among them: the writer of every crate's tests.
pub use qtvpr_testkit::zip;

/// The members of the `.npz` at `path`, by name.
pub fn npz_member(path: &Path, name: &str) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    zip::unzip(&bytes).into_iter().find(|(n, _)| n == name).unwrap().1
}

/// The bool values of `.npz` member `name` (a `.npy` of `|b1`), in C order.
pub fn npz_bools(path: &Path, name: &str) -> Vec<bool> {
    let npy = npz_member(path, &format!("{name}.npy"));
    let header = 10 + usize::from(u16::from_le_bytes([npy[8], npy[9]]));
    npy[header..].iter().map(|&b| b == 1).collect()
}

/// Run `qtvpr-cli` with `args` inside `dir` (a bare file name in `args` is a file
/// there), with backtraces on so that a panic could not pass for a clean error.
pub fn run_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .current_dir(dir)
        .env("RUST_BACKTRACE", "1")
        .args(args)
        .output()
        .unwrap()
}

/// `ulimit -v 1000000`: 1 GB of address space, for [`run_in_shell`].
pub const CAP: &str = "ulimit -v 1000000; ";

/// Run `qtvpr-cli` with `args` inside `dir` from `sh`, after the shell commands `before`
/// (e.g. [`CAP`]) and with `redirect` after the command (e.g. `>&-`).
pub fn run_in_shell(dir: &Path, before: &str, redirect: &str, args: &[&str]) -> Output {
    Command::new("sh")
        .current_dir(dir)
        .env("RUST_BACKTRACE", "1")
        .arg("-c")
        .arg(format!("{before}exec \"$0\" \"$@\" {redirect}"))
        .arg(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .args(args)
        .output()
        .unwrap()
}

/// Run `qtvpr-cli` with `args` inside `dir`, assert that it succeeded, and return its
/// standard output.
pub fn ok_in(dir: &Path, args: &[&str]) -> String {
    let out = run_in(dir, args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Write a `.npy` by hand: any dtype string, shape and raw little-endian payload, so that
/// the tests can also make the files no well-behaved writer would.
pub fn npy_raw(path: &Path, descr: &str, fortran: bool, shape: &[usize], payload: &[u8]) {
    let shape = match shape {
        [n] => format!("({n},)"),
        s => format!("({})", s.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let order = if fortran { "True" } else { "False" };
    let mut bytes = npy_header(&format!(
        "{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape}, }}"
    ));
    bytes.extend(payload);
    std::fs::write(path, bytes).unwrap();
}

/// The magic, version, length and space-padded text of a version 1.0 `.npy` header,
/// whatever `dict` says (so tests can also write malformed headers).
pub fn npy_header(dict: &str) -> Vec<u8> {
    let mut header = dict.to_string();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    bytes
}

/// Little-endian bytes of f64 values.
pub fn f64s(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A C-order float64 matrix from rows.
pub fn npy_f64(path: &Path, rows: &[&[f64]]) {
    let flat: Vec<f64> = rows.iter().flat_map(|r| r.iter().copied()).collect();
    npy_raw(path, "<f8", false, &[rows.len(), rows[0].len()], &f64s(&flat));
}

/// A C-order bool matrix from rows of 0/1.
pub fn npy_bool(path: &Path, rows: &[&[u8]]) {
    let flat: Vec<u8> = rows.iter().flat_map(|r| r.iter().copied()).collect();
    npy_raw(path, "|b1", false, &[rows.len(), rows[0].len()], &flat);
}

/// A C-order float32 matrix from rows.
pub fn npy_f32(path: &Path, rows: &[&[f32]]) {
    let flat: Vec<u8> = rows
        .iter()
        .flat_map(|r| r.iter())
        .flat_map(|x| x.to_le_bytes())
        .collect();
    npy_raw(path, "<f4", false, &[rows.len(), rows[0].len()], &flat);
}

/// Assert a clean failure: exit status 2, one `error: ` line containing every `needle`,
/// no panic, none of `outputs` written, and no temporary file left in `dir`.
pub fn assert_clean_failure(out: &Output, dir: &Path, outputs: &[&Path], needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(stderr.starts_with("error: "), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(
        !stderr.contains("panicked") && !stderr.contains("backtrace"),
        "{stderr}"
    );
    for needle in needles {
        assert!(stderr.contains(needle), "{needle:?} not in {stderr}");
    }
    for output in outputs {
        assert!(!output.exists(), "{} was written", output.display());
    }
    let stray = std::fs::read_dir(dir)
        .unwrap()
        .any(|e| e.unwrap().file_name().to_string_lossy().starts_with(".tmp"));
    assert!(!stray, "a temporary output file was left behind");
}
