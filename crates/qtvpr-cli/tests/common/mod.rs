//! Helpers shared by the CLI integration tests: a hand-written `.npy` writer, so that
//! the tests can also make the files no well-behaved writer would.

#![allow(dead_code)] // each test file uses its own subset

use std::path::Path;

/// Write a `.npy` by hand: any dtype string, shape and raw little-endian payload, so that
/// the tests can also make the files no well-behaved writer would.
pub fn npy_raw(path: &Path, descr: &str, fortran: bool, shape: &[usize], payload: &[u8]) {
    let shape = match shape {
        [n] => format!("({n},)"),
        s => format!("({})", s.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let order = if fortran { "True" } else { "False" };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    bytes.extend(payload);
    std::fs::write(path, bytes).unwrap();
}

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
