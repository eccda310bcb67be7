//! Progress bars go to a terminal only: with stderr a pipe (a log, a CI job), the
//! commands that draw one (`evaluate`, `similarity`, `threshold`) write nothing there;
//! on a terminal they draw, unless `--quiet`.

use std::process::Command;

use crate::common::npy_f32;

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
}

/// What a command writes to its standard error when that is a terminal (a
/// pseudo-terminal made here).
#[cfg(unix)]
fn stderr_on_a_terminal(args: &[&str]) -> String {
    use std::io::Read;
    use std::os::fd::{FromRawFd, OwnedFd};
    use std::process::Stdio;

    let (mut master, mut slave) = (-1, -1);
    // SAFETY: openpty writes two descriptors, which are owned from here on.
    let rc = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(rc, 0, "openpty: {}", std::io::Error::last_os_error());
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    let mut command = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"));
    command.args(args).stdout(Stdio::null()).stderr(Stdio::from(slave));
    let mut child = command.spawn().unwrap();
    drop(command); // the parent's end of the terminal: the reads below end with the child
    let mut terminal = std::fs::File::from(master);
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    // Linux reports the other end's close as EIO, other systems as end of file.
    while let Ok(n @ 1..) = terminal.read(&mut buf) {
        out.extend_from_slice(&buf[..n]);
    }
    assert!(child.wait().unwrap().success());
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(unix)]
#[test]
fn a_bar_on_a_terminal_and_none_under_quiet() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.md");
    let out = out.to_str().unwrap();
    let drawn = stderr_on_a_terminal(&["evaluate", "-o", out]);
    assert!(drawn.contains("method evaluations"), "no bar on a terminal: {drawn:?}");
    assert_eq!(stderr_on_a_terminal(&["--quiet", "evaluate", "-o", out]), "");
}
