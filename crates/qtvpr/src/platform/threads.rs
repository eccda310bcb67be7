//! The library's own thread pool, rebuilt in a process that forked after using it.
//!
//! Every parallel region of the core (rayon's parallel iterators, faer's `Par::rayon`)
//! runs inside [`install`], never in rayon's *global* pool. The reason is `fork()`: a
//! child process inherits a copy of the parent's memory but only the thread that
//! called `fork`. A global pool built before the fork is, in the child, a registry
//! whose worker threads do not exist, so the child's first parallel call queues a job
//! no thread will ever run and waits forever. Python's `multiprocessing` forks by
//! default on Linux, and a `Calibration` sent to worker processes is the common case
//! (semantics §10: a process that forks after using the library has a working library
//! in the child).
//!
//! So the pool is owned here and tagged with the id of the process that built it.
//! [`install`] compares that id with the current one and, in a forked child, builds a
//! new pool. The inherited one is leaked, never dropped: its threads do not exist, and
//! its locks may have been held by one of them at the time of the fork, so dropping it
//! could block or touch freed state.
//!
//! The pool has [`ThreadPoolBuilder`]'s default size (`RAYON_NUM_THREADS` if set, at
//! most [`MAX_THREADS`], else one thread per core) until [`set_threads`] sets another.
//! Its threads are named `qtvpr-0`, `qtvpr-1`, ..., so a real-time application can
//! find and pin them. It is built on first use.
//!
//! The slot that holds the pool is guarded by a spin lock that records the id of the
//! process whose thread holds it, not by a `Mutex`: a fork while another thread holds a
//! `Mutex` leaves it locked forever in the child, whereas a lock word naming another
//! process is known to be stale and is taken over. The lock is held only to read or
//! replace the slot (and while a pool is built), never while work runs.

use std::sync::Arc;
use std::sync::atomic::{AtomicPtr, AtomicU32, AtomicUsize, Ordering};

use rayon::{ThreadPool, ThreadPoolBuilder};

use crate::error::{Error, Result};

/// A pool and the process that built it.
struct Pool {
    pid: u32,
    pool: ThreadPool,
}

/// The current pool: a boxed `Arc<Pool>` turned into a raw pointer, or null before the
/// first use. Read and replaced only while [`LOCK`] is held. (A box rather than
/// `Arc::into_raw`, which points inside its allocation: leak checkers such as valgrind
/// would report the live pool as "possibly lost".)
static SLOT: AtomicPtr<Arc<Pool>> = AtomicPtr::new(std::ptr::null_mut());

/// The id of the process one of whose threads holds [`SLOT`], or 0 when it is free.
static LOCK: AtomicU32 = AtomicU32::new(0);

/// The most threads [`set_threads`] starts, and a pool sized by `RAYON_NUM_THREADS`:
/// more than the hardware threads of the largest common machines (768 on two 192-core
/// CPUs with SMT), and the work is CPU-bound, so threads beyond the cores only contend.
/// A pool's start-up grows faster than its size (measured on 2 busy cores: 256 threads
/// 0.1 s, 1024 threads 1.1 s, 4096 threads 23 s; rayon's own limit, 65,535, minutes): a
/// count above this is a typo, not a pool anyone waits for.
pub const MAX_THREADS: usize = 1024;

/// The size [`set_threads`] asked for; 0 for rayon's default.
static THREADS: AtomicUsize = AtomicUsize::new(0);

/// The size of a pool built without [`set_threads`], from the environment as `var`
/// reads it: 0 (rayon's default) unless rayon would read a count above
/// [`MAX_THREADS`] from `RAYON_NUM_THREADS` (or, when that is unset or not a number,
/// the deprecated `RAYON_RS_NUM_CPUS`), which is then [`MAX_THREADS`]. rayon would
/// start up to 65,535 threads, one by one, for minutes; a variable cannot be refused
/// with an error (the pool is built by the first computation, which has no error of
/// its own for it), so it is capped. rayon has no function that returns the size it
/// would pick, hence its two variables read here the way it reads them.
fn default_threads(var: impl Fn(&str) -> Option<String>) -> usize {
    let count = |name: &str| var(name).and_then(|s| s.parse::<usize>().ok());
    match count("RAYON_NUM_THREADS").or_else(|| count("RAYON_RS_NUM_CPUS")) {
        Some(n) if n > MAX_THREADS => MAX_THREADS,
        _ => 0,
    }
}

/// Holds [`LOCK`] for this process; releases it when dropped.
struct Guard {
    /// The lock was held by a thread of another process, i.e. of the parent before a
    /// fork: the slot may be half-written and must not be trusted.
    stale: bool,
}

impl Guard {
    fn acquire(pid: u32) -> Guard {
        loop {
            let holder = LOCK.load(Ordering::Acquire);
            if holder != pid
                && LOCK
                    .compare_exchange_weak(holder, pid, Ordering::Acquire, Ordering::Relaxed)
                    .is_ok()
            {
                return Guard { stale: holder != 0 };
            }
            // Held by another thread of this process, for the few microseconds it
            // takes to clone an Arc (or to build a pool).
            std::thread::yield_now();
        }
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        LOCK.store(0, Ordering::Release);
    }
}

/// Build a pool of `threads` threads (0: the environment's, [`default_threads`]) for
/// process `pid`.
fn build(pid: u32, threads: usize) -> Result<Arc<Pool>> {
    let threads = match threads {
        0 => default_threads(|name| std::env::var(name).ok()),
        n => n,
    };
    let pool = ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("qtvpr-{i}"))
        .build()
        .map_err(|e| Error::param("threads", format!("cannot start the thread pool: {e}")))?;
    Ok(Arc::new(Pool { pid, pool }))
}

/// Put `new` in the slot, releasing the old pool if it belongs to
/// this process and leaking it otherwise. Called with the lock held.
fn replace(guard: &Guard, pid: u32, new: Arc<Pool>) {
    let old = SLOT.swap(Box::into_raw(Box::new(new)), Ordering::AcqRel);
    if old.is_null() || guard.stale {
        return;
    }
    // SAFETY: a non-null slot holds a pointer from `Box::into_raw`, and it is written
    // whole (an atomic store), so it is valid unless the lock was stale.
    let old = unsafe { Box::from_raw(old) };
    if old.pid == pid {
        // Dropped when the last `install` running on it returns.
        drop(old);
    } else {
        // Built by the parent: its threads do not exist here and its locks may be
        // held, so it must never be dropped.
        std::mem::forget(old);
    }
}

/// The pool of the current process, built if there is none yet.
fn current() -> Arc<Pool> {
    let pid = std::process::id();
    let guard = Guard::acquire(pid);
    let ptr = SLOT.load(Ordering::Acquire);
    if !ptr.is_null() && !guard.stale {
        // SAFETY: as in `replace`; the lock keeps the box alive while it is read.
        let pool = unsafe { &*ptr };
        if pool.pid == pid {
            return Arc::clone(pool);
        }
        // The parent's pool: `replace` leaks it.
    }
    // No pool yet, or the parent's. Building can only fail if the system cannot start
    // a thread; there is then no way to run the computation, and rayon's global pool
    // panics in the same case.
    let pool = build(pid, THREADS.load(Ordering::Relaxed)).unwrap_or_else(|e| panic!("{e}"));
    replace(&guard, pid, Arc::clone(&pool));
    pool
}

/// Run `f` in the library's thread pool, so that the parallel iterators inside it use
/// that pool; the pool of this process, built first if there is none or if the
/// process is a child forked after the pool was built.
///
/// Calling `install` again from inside `f` (from any thread of the pool) runs the inner
/// closure directly, so entry points may nest freely.
///
/// # Panics
/// Only if the operating system cannot start the pool's threads (as rayon's global
/// pool would), or if `f` panics (the panic is propagated).
pub(crate) fn install<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    #[cfg(test)]
    INSTALLS.with(|n| n.set(n.get() + 1));
    current().pool.install(f)
}

#[cfg(test)]
thread_local! {
    /// The calls of [`install`] on this thread: for tests of what runs on the caller's
    /// thread alone.
    pub(crate) static INSTALLS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The number of threads of the library's pool (building it if needed).
pub fn current_threads() -> usize {
    current().pool.current_num_threads()
}

/// Set the size of the library's thread pool: a new pool of `n` threads replaces the
/// current one. Work already running finishes on the old pool, whose threads then end.
/// The size also holds for the pool a forked child builds.
///
/// Without a call, the pool has `RAYON_NUM_THREADS` threads (at most [`MAX_THREADS`])
/// if that variable is set, else one per core.
///
/// # Errors
/// [`Error::InvalidParameter`] for `n == 0` or `n >` [`MAX_THREADS`], or when the
/// threads cannot be started.
pub fn set_threads(n: usize) -> Result<()> {
    if n == 0 {
        return Err(Error::param("threads", "must be >= 1, got 0"));
    }
    if n > MAX_THREADS {
        return Err(Error::param(
            "threads",
            format!("must be at most {MAX_THREADS}, got {n}"),
        ));
    }
    let pid = std::process::id();
    let pool = build(pid, n)?;
    let guard = Guard::acquire(pid);
    THREADS.store(n, Ordering::Relaxed);
    replace(&guard, pid, pool);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_install_runs_in_the_pool() {
        let (outer, inner) = install(|| {
            let outer = rayon::current_thread_index();
            let inner = install(rayon::current_thread_index);
            (outer, inner)
        });
        assert!(outer.is_some());
        // Nested: the same worker thread, no hop.
        assert_eq!(inner, outer);
        let name = install(|| std::thread::current().name().map(str::to_owned));
        assert!(name.is_some_and(|n| n.starts_with("qtvpr-")));
    }

    #[test]
    fn the_environment_asks_for_at_most_the_cap() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| pairs.iter().find(|(k, _)| *k == name).map(|(_, v)| v.to_string())
        };
        // rayon's choice (0) for what it reads as a count up to the cap, or as none.
        for pairs in [
            &[][..],
            &[("RAYON_NUM_THREADS", "4")],
            &[("RAYON_NUM_THREADS", "1024")],
            &[("RAYON_NUM_THREADS", "0"), ("RAYON_RS_NUM_CPUS", "1000000")],
            &[("RAYON_NUM_THREADS", "many")],
            &[("RAYON_NUM_THREADS", "99999999999999999999999")],
        ] {
            assert_eq!(default_threads(env(pairs)), 0, "{pairs:?}");
        }
        for pairs in [
            &[("RAYON_NUM_THREADS", "1025")][..],
            &[("RAYON_NUM_THREADS", "1000000")],
            &[("RAYON_NUM_THREADS", "x"), ("RAYON_RS_NUM_CPUS", "70000")],
        ] {
            assert_eq!(default_threads(env(pairs)), MAX_THREADS, "{pairs:?}");
        }
    }

    #[test]
    fn zero_threads_is_an_error() {
        let e = set_threads(0).unwrap_err();
        assert_eq!(e.to_string(), "threads must be >= 1, got 0");
    }

    #[test]
    fn more_threads_than_the_cap_is_an_error_that_starts_none() {
        // Refused before a pool is built: the pool's size is unchanged.
        let before = current_threads();
        for (n, shown) in [
            (MAX_THREADS + 1, "1025"),
            (1 << 40, "1099511627776"),
            (usize::MAX, "18446744073709551615"),
        ] {
            let e = set_threads(n).unwrap_err();
            assert_eq!(e.to_string(), format!("threads must be at most 1024, got {shown}"));
        }
        assert_eq!(current_threads(), before);
    }
}
