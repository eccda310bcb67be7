//! # qtvpr-capi: the C interface of qtvpr
//!
//! Online thresholds (a decision for each deployment query as it arrives, from a
//! calibration file made offline) behind a small C ABI, for C and C++ robotics stacks
//! that embed neither Python nor Rust. The library is `libqtvpr.so` / `libqtvpr.a`; its
//! header, `include/qtvpr.h`, is generated from this crate by cbindgen and is what C
//! users read: every exported item's documentation here is its documentation there.
//!
//! The crate is as thin as the CLI and the Python binding: it turns pointers and lengths
//! into views, calls [`qtvpr::Calibration::load`], [`qtvpr::Online::new`] and
//! [`qtvpr::Online::push`], and turns their errors into codes and messages. It does no
//! arithmetic.
//!
//! The shape follows regex-capi: opaque handles with a `_new`/`_free` pair (the caller
//! owns what a constructor returns and nothing else), one guard around every exported
//! function so that no panic unwinds into C ([`error`]), and errors as values the
//! caller reads (a code, and this thread's last error message).

use std::ffi::{CStr, c_char, c_int};
use std::path::Path;
use std::ptr;
use std::sync::Arc;

use ndarray::ArrayView1;
use qtvpr::{Calibration, Matching, Online, OnlineParams, Score};

pub mod error;

use error::qtvpr_status::*;
use error::{Failure, catch, guard};

/// A calibration loaded from a calibration file (an .npz written by `qtvpr-cli
/// calibrate`, `qtvpr.Calibration.save` or `qtvpr::Calibration::save`). Opaque.
///
/// Read-only once loaded: any number of threads may use one calibration at once (to
/// query it or to create online states from it).
#[allow(non_camel_case_types)]
pub struct qtvpr_calibration {
    inner: Arc<Calibration>,
}

/// The state of an online deployment: a calibration, its parameters and the window of
/// the last queries pushed. Opaque.
///
/// Not thread-safe: one thread at a time may use a state (it may move from thread to
/// thread between calls). Give each camera or thread its own.
#[allow(non_camel_case_types)]
pub struct qtvpr_online {
    inner: Online,
}

/// The decision of one deployment query: the decision record, with the values of a
/// `qtvpr-cli stream` line and of Python's decisions, in both matching modes (a test
/// holds its members to the core's list of fields, `qtvpr::Decision::RECORD`).
///
/// best and score are the query's best match (the first highest score: the matcher's
/// own choice) in both modes. accepted is the number of accepted database entries: in
/// single matching 1 if the best match is accepted (score >= threshold), else 0; in
/// multi matching every entry with a score >= threshold (qtvpr_online_accepted lists
/// them). accept == (accepted > 0). confidence and confidence_lower95 (semantics §14)
/// were added after 0.1.0, consistency and consistency_level (semantics §15) after
/// them: the struct is larger, an ABI change (recompile against this header).
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy, PartialEq)]
// Its members by name, for the test that holds them to the core's record.
#[cfg_attr(test, derive(serde::Serialize))]
pub struct qtvpr_decision {
    /// Index of the query in arrival order, from 0.
    pub query: usize,
    /// The window's quantile.
    pub quantile: f64,
    /// Accept a score >= threshold.
    pub threshold: f64,
    /// Index of the best database match (the first maximum of the query's scores).
    pub best: usize,
    /// Its score.
    pub score: f64,
    /// Whether anything is accepted: accepted > 0.
    pub accept: bool,
    /// The number of accepted database entries (0 or 1 in single matching).
    pub accepted: usize,
    /// The query's own quantile q_j: that of its subset threshold among its k
    /// calibration neighbours (the window's quantile is their weighted median).
    pub query_quantile: f64,
    /// The query's weight w_j in that median: the mean correlation of its neighbours,
    /// clipped at 0.
    pub weight: f64,
    /// With the margin gate: the query's margin, how far its best match stands out of
    /// its scores ((best - second best) / their standard deviation). NaN without it.
    pub margin: f64,
    /// With the margin gate: m*, the margin a best match needs besides a score >=
    /// threshold (accepted is 1 only with both). NaN without it.
    pub gate: f64,
    /// The probability that the best match is right: the calibration's hit rate at the
    /// query's PA-score, whatever the gate. NaN in multi matching, with one database
    /// image (n_db = 1: no second-best score, so no PA-score), or for a calibration
    /// without a decision.
    pub confidence: f64,
    /// The one-sided 95% Clopper-Pearson lower bound on confidence. NaN where it is.
    pub confidence_lower95: f64,
    /// With the sequence gate: the query's consistency, the share of the previous
    /// sequence_window queries of the stream whose best matches agree with its own
    /// (semantics §15). NaN without it.
    pub consistency: f64,
    /// With the sequence gate: the consistency a best match needs besides a score >=
    /// threshold (accepted is 1 only with both, and with the margin gate's too). NaN
    /// without it.
    pub consistency_level: f64,
}

/// The parameters of a new online state (qtvpr_online_new_with), each either given or
/// "the calibration file's" (its params; else the library's default).
///
/// Fill one with qtvpr_online_options_init, which sets every member to "the file's",
/// then set those to give: a struct that is not initialised so is refused. Members may
/// be added at the end in later versions (size tells the library which it has), so
/// code written against this header keeps working, recompiled or not.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy)]
pub struct qtvpr_online_options {
    /// sizeof(qtvpr_online_options) of the caller's header: set by
    /// qtvpr_online_options_init, not by hand.
    pub size: usize,
    /// Calibration queries sampled per deployment query, >= 1 (SIZE_MAX: all); 0: the
    /// file's.
    pub k: usize,
    /// The precision target, in (0, 1]; 0: the file's (as in qtvpr_online_new).
    pub precision: f64,
    /// Each query is thresholded on its last window queries, >= 1; 0: the file's (an
    /// error if it sets none). See qtvpr_online_new for its memory.
    pub window: usize,
    /// Queries before the min_window-th are rejected, in 1..=window; 0: 1.
    pub min_window: usize,
    /// The gates, a NUL-terminated name: "none", "margin" (semantics §13), "sequence"
    /// (semantics §15) or "margin,sequence" (either order); NULL: the file's. The
    /// string is read during the call only.
    pub gate: *const c_char,
    /// The sequence gate: how many previous queries a query's best match is compared
    /// with, >= 1; 0: the file's (else 5).
    pub sequence_window: usize,
    /// The sequence gate: the share of them whose best matches must agree, in (0, 1];
    /// NaN: the file's (else 0.8).
    pub sequence_level: f64,
    /// The sequence gate: database rows per query (-1: the route driven backwards),
    /// finite; NaN: the file's (else 1).
    pub sequence_speed: f64,
    /// The sequence gate: how far in rows a neighbour one step away may lie from the
    /// line, >= 0; NaN: the file's (else 2).
    pub sequence_tolerance: f64,
    /// The sequence gate: how much that widens per step away, >= 0; NaN: the file's
    /// (else 0.2).
    pub sequence_drift: f64,
    /// The sequence length L the caller expects of the calibration (its
    /// qtvpr_calibration_sequence): another one is an error; 0: whatever it is.
    pub sequence: usize,
}

/// How a calibration matches queries, as qtvpr_calibration_matching returns it.
#[repr(C)]
#[allow(non_camel_case_types, clippy::upper_case_acronyms)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum qtvpr_matching {
    /// Each query's best database match is accepted or rejected.
    QTVPR_SINGLE = 1,
    /// Every database image with a score >= threshold is accepted.
    QTVPR_MULTI = 2,
}

/// The version of the qtvpr library, e.g. "0.1.0": a static string, never NULL, not to
/// be freed. Thread-safe; does not change the last error.
#[unsafe(no_mangle)]
pub extern "C" fn qtvpr_version() -> *const c_char {
    catch(ptr::null(), || {
        const VERSION: &CStr = match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
            Ok(v) => v,
            Err(_) => panic!("the version has no NUL"),
        };
        VERSION.as_ptr()
    })
}

/// Set the number of threads of the library's thread pool to n.
///
/// The library runs its parallel work (loading a calibration) on a pool of its own
/// threads (a push runs on the calling thread and never waits for them), named qtvpr-0, qtvpr-1, ... (pthread_getname_np), so that a
/// real-time application can find and pin them. By default the pool has
/// RAYON_NUM_THREADS threads (at most 1024) if that environment variable is set when the
/// pool is first used, else one per core. This call replaces the pool with one of n threads: calls
/// already running finish on the old pool, later calls use the new one. The size is
/// kept by a child forked afterwards, which gets a pool of its own (a process that
/// forks after using the library has a working library in the child).
///
/// Returns QTVPR_OK (0), or on error: QTVPR_ERR_PARAM (n is 0 or more than 1024, or the
/// threads cannot be started; nothing is changed). Thread-safe.
#[unsafe(no_mangle)]
pub extern "C" fn qtvpr_set_threads(n: usize) -> c_int {
    let done = guard("qtvpr_set_threads", || Ok(qtvpr::set_threads(n)?));
    done.err().unwrap_or(QTVPR_OK) as c_int
}

/// Load the calibration file at path (a NUL-terminated file name; on Unix any bytes,
/// elsewhere UTF-8).
///
/// Returns a new calibration, which the caller frees with qtvpr_calibration_free, or
/// NULL on error: QTVPR_ERR_NULL (path is NULL), QTVPR_ERR_IO (the file cannot be read),
/// QTVPR_ERR_FILE (it is not a valid calibration file); the message names the file.
/// Thread-safe.
///
/// # Safety
/// path is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_calibration_load(path: *const c_char) -> *mut qtvpr_calibration {
    guard("qtvpr_calibration_load", || {
        if path.is_null() {
            return Err(Failure::null("path"));
        }
        // SAFETY: the caller passes a NUL-terminated string.
        let path = unsafe { CStr::from_ptr(path) };
        let calibration = Calibration::load(c_path(path)?)?;
        let handle = qtvpr_calibration {
            inner: Arc::new(calibration),
        };
        Ok(Box::into_raw(Box::new(handle)))
    })
    .unwrap_or(ptr::null_mut())
}

/// A C file name as a path: its bytes on Unix, UTF-8 elsewhere.
fn c_path(path: &CStr) -> Result<&Path, Failure> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Ok(Path::new(std::ffi::OsStr::from_bytes(path.to_bytes())))
    }
    #[cfg(not(unix))]
    {
        path.to_str()
            .map(Path::new)
            .map_err(|_| Failure::new(QTVPR_ERR_IO, format!("path {path:?} is not UTF-8")))
    }
}

/// Free a calibration returned by qtvpr_calibration_load. NULL is a no-op.
///
/// Online states created from it keep what they need: it may be freed while they are
/// still in use. Not to be called while another thread uses the same calibration.
///
/// # Safety
/// cal is NULL or a calibration from qtvpr_calibration_load, not freed before.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_calibration_free(cal: *mut qtvpr_calibration) {
    let _ = guard("qtvpr_calibration_free", || {
        if !cal.is_null() {
            // SAFETY: cal came from Box::into_raw in qtvpr_calibration_load, and is freed once.
            drop(unsafe { Box::from_raw(cal) });
        }
        Ok(())
    });
}

/// The calibration's number of database images, |DB|: the n_db every push must pass.
///
/// Returns 0 on error (QTVPR_ERR_NULL: cal is NULL); a calibration has at least one
/// database image. Thread-safe.
///
/// # Safety
/// cal is NULL or a live calibration.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_calibration_db_size(cal: *const qtvpr_calibration) -> usize {
    guard("qtvpr_calibration_db_size", || {
        // SAFETY: the caller passes NULL or a live calibration.
        Ok(unsafe { arg(cal, "cal") }?.inner.db_size())
    })
    .unwrap_or(0)
}

/// The calibration's matching: QTVPR_SINGLE or QTVPR_MULTI (a qtvpr_matching), which
/// says how to read a qtvpr_decision.
///
/// Returns 0 on error (QTVPR_ERR_NULL: cal is NULL). Thread-safe.
///
/// # Safety
/// cal is NULL or a live calibration.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_calibration_matching(cal: *const qtvpr_calibration) -> c_int {
    guard("qtvpr_calibration_matching", || {
        // SAFETY: the caller passes NULL or a live calibration.
        let matching = match unsafe { arg(cal, "cal") }?.inner.matching() {
            Matching::Single => qtvpr_matching::QTVPR_SINGLE,
            Matching::Multi => qtvpr_matching::QTVPR_MULTI,
        };
        Ok(matching as c_int)
    })
    .unwrap_or(0)
}

/// The calibration's sequence length L (semantics §15): 1, or the length its calibration
/// traverse was causally sequence-matched over (`qtvpr-cli calibrate --sequence L`).
/// A state over it decides each query on its causal sequence-matched column, formed from
/// the last L - 1 columns pushed (8 x (L - 1) x n_db bytes more), as `qtvpr-cli stream`
/// does.
///
/// Returns 0 on error (QTVPR_ERR_NULL: cal is NULL). Thread-safe.
///
/// # Safety
/// cal is NULL or a live calibration.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_calibration_sequence(cal: *const qtvpr_calibration) -> usize {
    guard("qtvpr_calibration_sequence", || {
        // SAFETY: the caller passes NULL or a live calibration.
        Ok(unsafe { arg(cal, "cal") }?.inner.sequence())
    })
    .unwrap_or(0)
}

/// Set every member of *opts to "the calibration file's" (0, NaN or NULL as each member
/// says), and its size to this library's. Does nothing when opts is NULL. Thread-safe.
///
/// # Safety
/// opts is NULL or points to a writable qtvpr_online_options.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_options_init(opts: *mut qtvpr_online_options) {
    let _ = guard("qtvpr_online_options_init", || {
        // SAFETY: the caller passes NULL or a writable struct.
        if let Some(opts) = unsafe { opts.as_mut() } {
            *opts = DEFAULT_OPTIONS;
        }
        Ok(())
    });
}

/// A new online state over cal with the parameters of *opts (initialised by
/// qtvpr_online_options_init; NULL: every parameter the file's).
///
/// Returns a new state, which the caller frees with qtvpr_online_free, or NULL on error:
/// QTVPR_ERR_NULL (cal is NULL), QTVPR_ERR_PARAM (opts not initialised by
/// qtvpr_online_options_init; a parameter out of range, the message names it; a gate
/// that is not "none" or a set of "margin" and "sequence", or one the calibration cannot
/// have: multi matching, the margin gate with one database image, the sequence gate on
/// a database its tolerance covers; a sequence other than the calibration's), the
/// message saying why. The state holds its own reference to the calibration: cal may be
/// freed afterwards, and opts and its gate string are not kept. Thread-safe (cal and
/// opts are only read).
///
/// # Safety
/// cal is NULL or a live calibration; opts is NULL or points to a qtvpr_online_options
/// whose gate is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_new_with(
    cal: *const qtvpr_calibration,
    opts: *const qtvpr_online_options,
) -> *mut qtvpr_online {
    guard("qtvpr_online_new_with", || {
        // SAFETY: the caller passes NULL or a live calibration.
        let cal = unsafe { arg(cal, "cal") }?;
        let mut options = DEFAULT_OPTIONS;
        // SAFETY: the caller passes NULL or a readable struct; its size member is read
        // first, and no more than that size.
        if let Some(given) = unsafe { opts.as_ref() } {
            if given.size != size_of::<qtvpr_online_options>() {
                return Err(Failure::new(
                    error::qtvpr_status::QTVPR_ERR_PARAM,
                    format!(
                        "opts was not initialised by qtvpr_online_options_init: its size is {}, this library's \
                         qtvpr_online_options is {} bytes",
                        given.size,
                        size_of::<qtvpr_online_options>()
                    ),
                ));
            }
            options = *given;
        }
        // SAFETY: the caller's gate is NULL or a NUL-terminated string.
        unsafe { online_new(cal, &options) }
    })
    .unwrap_or(ptr::null_mut())
}

/// Every member "the file's" (what qtvpr_online_options_init writes).
const DEFAULT_OPTIONS: qtvpr_online_options = qtvpr_online_options {
    size: size_of::<qtvpr_online_options>(),
    k: 0,
    precision: 0.0,
    window: 0,
    min_window: 0,
    gate: ptr::null(),
    sequence_window: 0,
    sequence_level: f64::NAN,
    sequence_speed: f64::NAN,
    sequence_tolerance: f64::NAN,
    sequence_drift: f64::NAN,
    sequence: 0,
};

/// A new online state over cal: an empty window.
///
/// Each parameter takes the calibration file's value when 0 (min_window: 1):
/// - k, the calibration queries sampled per deployment query: >= 1; a k above the
///   calibration's number of queries is clipped to it (SIZE_MAX means all of them);
/// - precision, the target: in (0, 1];
/// - window, each query is thresholded on its last window queries: >= 1, and at most
///   PTRDIFF_MAX / 8 / n_db (qtvpr_calibration_db_size), the largest whose full state
///   (window x n_db doubles) could be allocated at all; the state takes memory as
///   queries arrive, 8 x n_db bytes each until the window is full, so choose the window
///   the application can hold (e.g. 1000 queries x 10000 images = 80 MB);
/// - min_window, queries before the min_window-th are rejected: in 1..=window.
///
/// The gate and the sequence gate's parameters are the file's (see
/// qtvpr_online_new_with to choose them; this is qtvpr_online_new_with with these four
/// members set, 0 taken as "the file's").
///
/// Returns a new state, which the caller frees with qtvpr_online_free, or NULL on error:
/// QTVPR_ERR_NULL (cal is NULL), QTVPR_ERR_PARAM (a parameter out of range, e.g. window
/// SIZE_MAX, or window 0 and the file sets none; the message names the parameter). The
/// state holds its own reference to the calibration: cal may be freed afterwards.
/// Thread-safe (cal is only read).
///
/// # Safety
/// cal is NULL or a live calibration.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_new(
    cal: *const qtvpr_calibration,
    k: usize,
    precision: f64,
    window: usize,
    min_window: usize,
) -> *mut qtvpr_online {
    guard("qtvpr_online_new", || {
        // SAFETY: the caller passes NULL or a live calibration.
        let cal = unsafe { arg(cal, "cal") }?;
        // SAFETY: the options' gate is NULL.
        unsafe { online_new(cal, &legacy(k, precision, window, min_window, ptr::null())) }
    })
    .unwrap_or(ptr::null_mut())
}

/// The options of qtvpr_online_new's arguments, each 0 "the file's".
fn legacy(k: usize, precision: f64, window: usize, min_window: usize, gate: *const c_char) -> qtvpr_online_options {
    qtvpr_online_options {
        k,
        precision,
        window,
        min_window,
        gate,
        ..DEFAULT_OPTIONS
    }
}

/// qtvpr_online_new with a gate: gate is NULL (the file's), "none", "margin" (a best
/// match is then accepted only if its margin is also at least the calibration's m*, and
/// each qtvpr_decision carries margin and gate), "sequence" (only if the best matches of
/// the previous queries agree with it, semantics §15, with the file's parameters; each
/// qtvpr_decision carries consistency and consistency_level) or "margin,sequence".
/// Single matching only. qtvpr_online_new_with chooses the sequence gate's parameters.
///
/// Returns as qtvpr_online_new; QTVPR_ERR_PARAM also for another gate name, or a gate
/// the calibration cannot have (the message says why).
///
/// # Safety
/// cal is NULL or a live calibration; gate is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_new_gate(
    cal: *const qtvpr_calibration,
    k: usize,
    precision: f64,
    window: usize,
    min_window: usize,
    gate: *const c_char,
) -> *mut qtvpr_online {
    guard("qtvpr_online_new_gate", || {
        // SAFETY: the caller passes NULL or a live calibration.
        let cal = unsafe { arg(cal, "cal") }?;
        // SAFETY: the caller passes NULL or a NUL-terminated string.
        unsafe { online_new(cal, &legacy(k, precision, window, min_window, gate)) }
    })
    .unwrap_or(ptr::null_mut())
}

/// The state of `options` over `cal`, each member "not given" (0, NaN, NULL) taking the
/// file's value: the core resolves them.
///
/// # Safety
/// `options.gate` is NULL or a NUL-terminated string.
unsafe fn online_new(cal: &qtvpr_calibration, options: &qtvpr_online_options) -> Result<*mut qtvpr_online, Failure> {
    let count = |v: usize| (v != 0).then_some(v);
    let real = |v: f64| (!v.is_nan()).then_some(v);
    let gate = if options.gate.is_null() {
        None
    } else {
        // SAFETY: the caller passes a NUL-terminated string.
        let name = unsafe { CStr::from_ptr(options.gate) }.to_string_lossy();
        Some(name.parse::<qtvpr::Gate>()?)
    };
    cal.inner.check_sequence(count(options.sequence))?;
    let sequence_gate = qtvpr::SequenceOverrides {
        window: count(options.sequence_window),
        level: real(options.sequence_level),
        speed: real(options.sequence_speed),
        tolerance: real(options.sequence_tolerance),
        drift: real(options.sequence_drift),
    };
    let params = OnlineParams::resolve(
        cal.inner.defaults(),
        count(options.k),
        (options.precision != 0.0).then_some(options.precision),
        count(options.window),
        count(options.min_window),
        gate,
        sequence_gate,
    )?;
    let inner = Online::new(Arc::clone(&cal.inner), params)?;
    Ok(Box::into_raw(Box::new(qtvpr_online { inner })))
}

/// Decide the next deployment query from its n_db float scores against the database
/// (higher is more similar), and write the decision to *out.
///
/// Returns QTVPR_OK (0), or on error: QTVPR_ERR_NULL (o, scores or out is NULL),
/// QTVPR_ERR_SIZE (n_db is not qtvpr_calibration_db_size), QTVPR_ERR_INPUT (a NaN or
/// infinite score, or scores misaligned), QTVPR_ERR_PARAM (the window, not yet full,
/// cannot grow by one query: no memory). On error *out and the state are unchanged.
/// Runs on the library's thread pool (see qtvpr_set_threads). Not thread-safe for the
/// same o.
///
/// For float64 similarity, push with qtvpr_online_push_f64: float scores are the
/// float64 ones rounded, and give other weights, quantiles and thresholds.
///
/// # Safety
/// o is NULL or a live state; scores is NULL or points to n_db floats; out is NULL or
/// points to a writable qtvpr_decision.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_push_f32(
    o: *mut qtvpr_online,
    scores: *const f32,
    n_db: usize,
    out: *mut qtvpr_decision,
) -> c_int {
    // SAFETY: the caller's promises are push's.
    unsafe { push("qtvpr_online_push_f32", o, scores, n_db, out) }
}

/// As qtvpr_online_push_f32, for n_db double scores. A state takes float and double
/// queries alike, each decided in its own precision.
///
/// # Safety
/// o is NULL or a live state; scores is NULL or points to n_db doubles; out is NULL or
/// points to a writable qtvpr_decision.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_push_f64(
    o: *mut qtvpr_online,
    scores: *const f64,
    n_db: usize,
    out: *mut qtvpr_decision,
) -> c_int {
    // SAFETY: the caller's promises are push's.
    unsafe { push("qtvpr_online_push_f64", o, scores, n_db, out) }
}

/// Both push functions.
///
/// # Safety
/// `o` is NULL or a live state, `scores` NULL or `n_db` readable `T`s, `out` NULL or
/// writable.
unsafe fn push<T: Score>(
    function: &str,
    o: *mut qtvpr_online,
    scores: *const T,
    n_db: usize,
    out: *mut qtvpr_decision,
) -> c_int {
    let done = guard(function, || {
        // SAFETY: the caller passes NULL or a live state, used by this thread only.
        let online = &mut unsafe { arg_mut(o, "o") }?.inner;
        if scores.is_null() {
            return Err(Failure::null("scores"));
        }
        // SAFETY: the caller passes NULL or a writable decision.
        let out = unsafe { arg_mut(out, "out") }?;
        let db = online.calibration().db_size();
        if n_db != db {
            // Checked before making the view, which must not claim more than the caller has.
            let query = online.pushed();
            return Err(qtvpr::Error::ColumnLength { query, len: n_db, db }.into());
        }
        if !scores.is_aligned() {
            return Err(Failure::new(
                QTVPR_ERR_INPUT,
                format!(
                    "scores {scores:p} is not aligned for {}",
                    if size_of::<T>() == 4 { "float" } else { "double" }
                ),
            ));
        }
        // SAFETY: non-NULL, aligned, and n_db = |DB| readable values (the caller's promise).
        let column = unsafe { ArrayView1::from_shape_ptr(n_db, scores) };
        *out = decision(&online.push(column)?);
        Ok(())
    });
    done.err().unwrap_or(QTVPR_OK) as c_int
}

/// The C form of a decision.
fn decision(d: &qtvpr::Decision) -> qtvpr_decision {
    qtvpr_decision {
        query: d.query,
        quantile: d.quantile,
        threshold: d.threshold,
        best: d.best,
        score: d.score,
        accept: d.accept(),
        accepted: d.accepted,
        query_quantile: d.query_quantile,
        weight: d.weight,
        margin: d.margin.unwrap_or(f64::NAN),
        gate: d.gate.unwrap_or(f64::NAN),
        confidence: d.confidence,
        confidence_lower95: d.confidence_lower95,
        consistency: d.consistency.unwrap_or(f64::NAN),
        consistency_level: d.consistency_level.unwrap_or(f64::NAN),
    }
}

/// The database indices accepted for the last query pushed, ascending (multi matching:
/// every score >= threshold; single: the best match if accepted, else none).
///
/// Writes the first min(count, cap) of them to out and returns count, so a call with
/// cap 0 (out may then be NULL) asks for the size. Returns 0 before the first push, and
/// 0 on error (QTVPR_ERR_NULL: o is NULL, or out is NULL with cap > 0): check
/// qtvpr_last_error_code() when 0 is ambiguous. Not thread-safe for the same o.
///
/// # Safety
/// o is NULL or a live state; out is NULL or points to cap writable size_t.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_accepted(o: *const qtvpr_online, out: *mut usize, cap: usize) -> usize {
    guard("qtvpr_online_accepted", || {
        // SAFETY: the caller passes NULL or a live state.
        let accepted = unsafe { arg(o, "o") }?.inner.accepted();
        if cap > 0 {
            if out.is_null() {
                return Err(Failure::null("out"));
            }
            let n = accepted.len().min(cap);
            // SAFETY: out points to cap >= n writable size_t, none of them inside the state.
            unsafe { ptr::copy_nonoverlapping(accepted.as_ptr(), out, n) };
        }
        Ok(accepted.len())
    })
    .unwrap_or(0)
}

/// Free a state returned by qtvpr_online_new. NULL is a no-op.
///
/// # Safety
/// o is NULL or a state from qtvpr_online_new, not freed before and not in use by
/// another thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn qtvpr_online_free(o: *mut qtvpr_online) {
    let _ = guard("qtvpr_online_free", || {
        if !o.is_null() {
            // SAFETY: o came from Box::into_raw in qtvpr_online_new, and is freed once.
            drop(unsafe { Box::from_raw(o) });
        }
        Ok(())
    });
}

/// `*p`, or the NULL error naming `argument`.
///
/// # Safety
/// `p` is NULL or valid for reads for `'a`.
unsafe fn arg<'a, T>(p: *const T, argument: &str) -> Result<&'a T, Failure> {
    // SAFETY: the caller's promise.
    unsafe { p.as_ref() }.ok_or_else(|| Failure::null(argument))
}

/// `*p` for writing, or the NULL error naming `argument`.
///
/// # Safety
/// `p` is NULL or valid for reads and writes for `'a`, and not aliased meanwhile.
unsafe fn arg_mut<'a, T>(p: *mut T, argument: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: the caller's promise.
    unsafe { p.as_mut() }.ok_or_else(|| Failure::null(argument))
}

// The handles' promises in the header: a calibration is shared across threads, a state
// moves between them.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    const fn send<T: Send>() {}
    send_sync::<qtvpr_calibration>();
    send::<qtvpr_online>();
};

#[cfg(test)]
mod tests;
