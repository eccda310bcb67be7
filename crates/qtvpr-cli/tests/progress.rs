//! Progress bars go to a terminal only: with stderr a pipe (a log, a CI job), the
//! commands that draw one (`evaluate`, `similarity`, `threshold`) write nothing there.

use std::process::Command;

mod common;
use common::npy_f32;

fn quiet_stderr(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8_lossy(&out.stderr), "", "{args:?}");
}

#[test]
fn no_bar_on_a_pipe() {
    let dir = tempfile::tempdir().unwrap();
    let (db, q, s) = (
        dir.path().join("db.npy"),
        dir.path().join("q.npy"),
        dir.path().join("S.npy"),
    );
    npy_f32(&db, &[&[1.0, 0.0], &[0.0, 1.0], &[1.0, 1.0]]);
    npy_f32(&q, &[&[1.0, 2.0], &[3.0, 1.0]]);
    let path = |p: &std::path::Path| p.to_str().unwrap().to_string();
    quiet_stderr(&[
        "similarity",
        "--db",
        &path(&db),
        "--queries",
        &path(&q),
        "-o",
        &path(&s),
    ]);
    // The embedded data: one run of all five methods, then an ablation of three runs.
    let out = path(&dir.path().join("out.md"));
    quiet_stderr(&["evaluate", "-o", &out]);
    quiet_stderr(&["evaluate", "--k", "1,2,3", "-o", &out]);
    quiet_stderr(&["--quiet", "evaluate", "-o", &out]);
}
