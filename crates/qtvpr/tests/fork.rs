//! Semantics §10: a process that forks after using the library has a working library
//! in the child. The parent calibrates, transfers and pushes (so the thread pool
//! exists and has run work), then forks; the child does the same again and must get
//! the parent's results. Before the library owned its pool (rayon's global one), the
//! child's first parallel call waited forever for threads that exist only in the
//! parent; each child here gets 20 s before it is killed and the test fails.
//!
//! Real data: the embedded VPR-Bench Corridor matrices (`data/corridor`, float64).
#![cfg(all(unix, feature = "npy"))]

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ndarray::{ArrayView2, s};
use qtvpr::npy::{read_ground_truth, read_scores};
use qtvpr::{Calibration, Decision, Gate, Matching, Online, OnlineParams, Params, ScoresView, Transfer};

fn corridor(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/corridor")
        .join(name)
}

const PARAMS: OnlineParams = OnlineParams {
    k: 5,
    precision: 1.0,
    window: 20,
    min_window: 1,
    gate: Gate::None,
    sequence_gate: qtvpr::SequenceParams::DEFAULT,
};

/// The calibration (111 x 11) and the deployment scores (111 x 100).
fn load() -> (Calibration, qtvpr::npy::MatrixFile) {
    let s_cal = read_scores(&corridor("cal_S.npy")).unwrap();
    let gt = read_ground_truth(&corridor("cal_GT.npy"), None).unwrap();
    let cal = qtvpr::with_scores!(s_cal.view(), |v| Calibration::new(v, &gt, Matching::Single)).unwrap();
    (cal, read_scores(&corridor("deploy_S.npy")).unwrap())
}

fn deployment(scores: &qtvpr::npy::MatrixFile) -> ArrayView2<'_, f64> {
    match scores.view() {
        ScoresView::F64(v) => v,
        ScoresView::F32(_) => panic!("data/corridor/deploy_S.npy is float64"),
    }
}

fn transfer(cal: &Calibration, s: ArrayView2<'_, f64>) -> Transfer {
    let params = Params {
        k: 5,
        precision: 1.0,
        segment_size: Some(20),
        gate: Gate::None,
        sequence_gate: Default::default(),
    };
    cal.transfer(s, &params).unwrap()
}

/// Run `child` in a forked child process and wait for it: `Ok` if it returned true,
/// `Err` saying why not if it returned false, panicked, or did not end within 20 s
/// (it is then killed).
fn in_child(child: impl FnOnce() -> bool) -> Result<(), String> {
    // SAFETY: the child only runs `child` and `_exit`s; it never returns into the test
    // harness, whose other threads do not exist in it.
    let pid = unsafe { libc::fork() };
    assert!(pid >= 0, "fork failed");
    if pid == 0 {
        let ok = std::panic::catch_unwind(AssertUnwindSafe(child)).unwrap_or(false);
        // SAFETY: ends the child without running the parent's exit handlers.
        unsafe { libc::_exit(if ok { 0 } else { 1 }) };
    }
    let start = Instant::now();
    let mut status = 0;
    loop {
        // SAFETY: waits for our own child; `status` is a valid out-pointer.
        let done = unsafe { libc::waitpid(pid, &mut status, libc::WNOHANG) };
        assert!(done >= 0, "waitpid failed");
        if done == pid {
            break;
        }
        if start.elapsed() > Duration::from_secs(20) {
            // SAFETY: kills and reaps our own child.
            unsafe {
                libc::kill(pid, libc::SIGKILL);
                libc::waitpid(pid, &mut status, 0);
            }
            return Err("the forked child hung: no result after 20 s".into());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    match (libc::WIFEXITED(status), libc::WEXITSTATUS(status)) {
        (true, 0) => Ok(()),
        (true, 1) => Err("the forked child got other results than the parent".into()),
        _ => Err(format!("the forked child ended with status {status:#x}")),
    }
}

#[test]
fn a_forked_child_calibrates_transfers_and_pushes() {
    let (cal, scores) = load();
    let s = deployment(&scores);
    let cal = Arc::new(cal);
    // The parent uses every parallel path first: a transfer, a batch of pushes, and
    // single pushes.
    let want_transfer = transfer(&cal, s);
    let mut online = Online::new(Arc::clone(&cal), PARAMS).unwrap();
    let mut want: Vec<Decision> = online.push_many(s.slice(s![.., ..50])).unwrap();
    for j in 50..60 {
        want.push(online.push(s.column(j)).unwrap());
    }
    // The same state as `online` after 50 queries, to be continued in the child.
    let mut half = Online::new(Arc::clone(&cal), PARAMS).unwrap();
    half.push_many(s.slice(s![.., ..50])).unwrap();
    assert_eq!(want.len(), 60);
    assert_eq!(want_transfer.segments.len(), 5);

    let result = in_child(|| {
        // Continue the parent's state, one push at a time.
        let next: Vec<Decision> = (50..60).map(|j| half.push(s.column(j)).unwrap()).collect();
        // Calibrate again from the files, transfer, and stream from scratch.
        let (cal2, scores2) = load();
        let s2 = deployment(&scores2);
        let again = Online::new(Arc::new(cal2), PARAMS)
            .unwrap()
            .push_many(s2.slice(s![.., ..60]))
            .unwrap();
        next == want[50..] && again == want && transfer(&cal, s2) == want_transfer
    });
    result.unwrap();
}

#[test]
fn the_pool_size_holds_in_a_forked_child() {
    assert_eq!(
        qtvpr::set_threads(0).unwrap_err().to_string(),
        "threads must be >= 1, got 0"
    );
    qtvpr::set_threads(3).unwrap();
    assert_eq!(qtvpr::current_threads(), 3);
    let (cal, scores) = load();
    let s = deployment(&scores);
    let want = transfer(&cal, s);
    in_child(|| {
        // The child's pool is new, of the size set in the parent, and runs the work on
        // its own named threads.
        let same = transfer(&cal, s) == want;
        same && qtvpr::current_threads() == 3 && pool_threads_named()
    })
    .unwrap();
}

/// Whether this process has a thread of the library's pool, named `qtvpr-0`, `qtvpr-1`,
/// ...: its threads as Linux lists them (`/proc/self/task/*/comm`); true where there is
/// no such list to read.
fn pool_threads_named() -> bool {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return true;
    };
    tasks
        .filter_map(Result::ok)
        .any(|t| std::fs::read_to_string(t.path().join("comm")).is_ok_and(|name| name.starts_with("qtvpr-")))
}
