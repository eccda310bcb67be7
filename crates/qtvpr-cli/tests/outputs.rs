//! Standard output as a supervisor sees it (docs/semantics.md §10, files and processes): a
//! closed pipe ends every command that writes to standard output quietly with status 0,
//! and any other write error names the output ("standard output" or the `--output`
//! path), never an input. On the embedded VPR-Bench Corridor data.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use tempfile::TempDir;

/// The embedded VPR-Bench Corridor matrices of the repository.
fn corridor(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/corridor")
        .join(name)
        .display()
        .to_string()
}

/// A calibration file of the Corridor calibration half, in `dir`.
fn calibration(dir: &Path) -> PathBuf {
    let cal = dir.join("cal.npz");
    let out = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .args([
            "calibrate",
            "--cal",
            &corridor("cal_S.npy"),
            "--cal-gt",
            &corridor("cal_GT.npy"),
        ])
        .args(["--window", "28", "--output"])
        .arg(&cal)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    cal
}

/// Every command that writes its result to standard output, with its arguments.
fn commands(cal: &Path) -> Vec<Vec<String>> {
    let cal = cal.display().to_string();
    let val = corridor("deploy_S.npy");
    let strings = |args: &[&str]| args.iter().map(|a| a.to_string()).collect::<Vec<_>>();
    vec![
        strings(&["stream", "--calibration", &cal, "--val", &val]),
        strings(&["stream", "--calibration", &cal, "--val", &val, "--format", "csv"]),
        strings(&["threshold", "--cal", &cal, "--val", &val, "--segment-size", "1"]),
        strings(&["threshold", "--cal", &cal, "--val", &val, "--format", "csv"]),
        strings(&["evaluate"]),
        strings(&["evaluate", "--format", "json"]),
    ]
}

/// Run `qtvpr-cli --quiet args` with standard output `stdout`.
fn run(args: &[String], stdout: impl Into<Stdio>) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .arg("--quiet")
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .stdout(stdout)
        .stderr(Stdio::piped())
        .output()
        .unwrap()
}

#[test]
fn a_closed_pipe_ends_quietly_with_status_0() {
    // Regression: `stream ... | head -1` exited 2 with "--val ...: Broken pipe": the JSON
    // writer's error hid the io::Error that main looks for. The pipe's reading end is
    // closed before the command starts, so every run meets it on its first write.
    let dir = TempDir::new().unwrap();
    let cal = calibration(dir.path());
    for args in commands(&cal) {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = run(&args, writer);
        assert_eq!(
            (out.status.code(), String::from_utf8_lossy(&out.stderr).as_ref()),
            (Some(0), ""),
            "{args:?}"
        );
    }
}

/// A character device in `dir` that refuses every write with ENOSPC, like the system's
/// /dev/full (major 1, minor 7), made by mknod(1), which needs root; None otherwise.
fn full_device(dir: &Path) -> Option<PathBuf> {
    let path = dir.join("full");
    let made = Command::new("mknod")
        .arg(&path)
        .args(["c", "1", "7"])
        .stderr(Stdio::null())
        .status();
    made.is_ok_and(|s| s.success()).then_some(path)
}

#[test]
fn a_write_error_names_the_output_not_an_input() {
    // Regression: `stream ... > /dev/full` said "--val ...: No space left on device".
    let dir = TempDir::new().unwrap();
    let cal = calibration(dir.path());
    let Some(full) = full_device(dir.path()) else {
        eprintln!("SKIPPED a_write_error_names_the_output_not_an_input: mknod needs root");
        return;
    };
    for args in commands(&cal) {
        let device = std::fs::OpenOptions::new().write(true).open(&full).unwrap();
        let out = run(&args, device);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(
            stderr.trim_end(),
            "error: standard output: No space left on device (os error 28)",
            "{args:?}"
        );
    }
    // The same device as --output is named by its path, and stays a device.
    let mut args = commands(&cal).swap_remove(0);
    args.extend(["--output".to_string(), full.display().to_string()]);
    let out = run(&args, Stdio::null());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains(&full.display().to_string()), "{stderr}");
    assert!(stderr.contains("No space left on device"), "{stderr}");
    assert!(!stderr.contains("--val"), "{stderr}");
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata(&full).unwrap().file_type().is_char_device());
}
