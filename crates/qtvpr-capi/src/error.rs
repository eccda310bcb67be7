//! Error codes, this thread's last error, and the one guard every exported function runs
//! its body in.
//!
//! A C caller cannot receive a Rust `Result` or survive an unwinding panic, so each
//! exported function hands its body to [`guard`] (or, for the three functions that read
//! the error state itself, [`catch`]): a panic is caught there and becomes
//! `QTVPR_ERR_PANIC`, and an error becomes this thread's last error, a code and a
//! message the caller reads with `qtvpr_last_error_code()` and `qtvpr_last_error()`.

use std::any::Any;
use std::cell::RefCell;
use std::ffi::{CString, c_char, c_int};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::ptr;

/// The codes a function of this library fails with.
///
/// The push functions return them; the functions that return a pointer or a count
/// return NULL or 0 instead, and `qtvpr_last_error_code()` tells which code it was.
/// Every error also sets a message, `qtvpr_last_error()`, which names the function and
/// says what is wrong (and for a file, which file).
#[repr(C)]
#[allow(non_camel_case_types, clippy::upper_case_acronyms)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum qtvpr_status {
    /// Success.
    QTVPR_OK = 0,
    /// A pointer argument that must not be NULL is NULL.
    QTVPR_ERR_NULL = 1,
    /// n_db is not the calibration's number of database images.
    QTVPR_ERR_SIZE = 2,
    /// The scores are unusable: a NaN or infinite score (the message gives its index),
    /// or a pointer not aligned for its type.
    QTVPR_ERR_INPUT = 3,
    /// k, precision, window, min_window or a sequence gate parameter is out of range (a
    /// window too large to be allocated included), no window is given and the
    /// calibration file sets none, a gate is unknown or cannot apply to the calibration,
    /// a sequence length is not the calibration's, options were not initialised by
    /// qtvpr_online_options_init, or qtvpr_set_threads got 0 threads or more than 1024.
    QTVPR_ERR_PARAM = 4,
    /// A file cannot be read: missing, a directory, no permission.
    QTVPR_ERR_IO = 5,
    /// A file is not a valid calibration file: not an .npz, truncated, a missing or
    /// malformed array, an unknown format or version.
    QTVPR_ERR_FILE = 6,
    /// A bug in qtvpr (a Rust panic, caught at the boundary); please report the message.
    QTVPR_ERR_PANIC = 7,
    /// Memory for a buffer that a file or a parameter sizes cannot be allocated (a
    /// calibration file whose arrays do not fit in memory); the message names the file
    /// and member, or the buffer.
    QTVPR_ERR_MEMORY = 8,
}

use qtvpr_status::*;

/// An error on its way to the caller: its code and its message.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Failure {
    pub(crate) code: qtvpr_status,
    pub(crate) message: String,
}

impl Failure {
    pub(crate) fn new(code: qtvpr_status, message: impl Into<String>) -> Self {
        Self {
            code,
            message: message.into(),
        }
    }

    /// The error for a NULL `argument`.
    pub(crate) fn null(argument: &str) -> Self {
        Self::new(QTVPR_ERR_NULL, format!("{argument} is NULL"))
    }
}

impl From<qtvpr::Error> for Failure {
    fn from(err: qtvpr::Error) -> Self {
        use qtvpr::Error as E;
        let code = match &err {
            E::ColumnLength { .. } | E::DatabaseMismatch { .. } | E::ShapeMismatch { .. } => QTVPR_ERR_SIZE,
            E::InvalidParameter { .. } => QTVPR_ERR_PARAM,
            E::Io { .. } | E::Write { .. } => QTVPR_ERR_IO,
            E::Allocation { .. } => QTVPR_ERR_MEMORY,
            E::InFile { error, .. } if matches!(**error, E::Allocation { .. }) => QTVPR_ERR_MEMORY,
            E::File { .. } | E::Dtype { .. } | E::InFile { .. } => QTVPR_ERR_FILE,
            _ => QTVPR_ERR_INPUT,
        };
        Self::new(code, err.to_string())
    }
}

/// This thread's last error: its code and its message as C reads it.
struct LastError {
    code: qtvpr_status,
    message: CString,
}

thread_local! {
    static LAST_ERROR: RefCell<Option<LastError>> = const { RefCell::new(None) };
}

/// Replace this thread's last error (None: the last call succeeded). While a thread is
/// being torn down its storage may be gone; the error is then dropped, which is all a
/// caller on that thread could still observe.
fn set_last_error(error: Option<LastError>) {
    let _ = LAST_ERROR.try_with(|last| *last.borrow_mut() = error);
}

/// Run `body`, which must not unwind into C: a panic becomes `on_panic`'s value.
pub(crate) fn catch<T>(on_panic: T, body: impl FnOnce() -> T) -> T {
    catch_unwind(AssertUnwindSafe(body)).unwrap_or(on_panic)
}

/// The body of an exported function `function`: clears this thread's last error, runs
/// `body` with panics caught, and records its error (prefixed by `function`). Returns
/// the body's value, or the error's code for the caller to turn into its C return value
/// (NULL, 0 or the code).
pub(crate) fn guard<T>(function: &str, body: impl FnOnce() -> Result<T, Failure>) -> Result<T, qtvpr_status> {
    set_last_error(None);
    let failure = match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(value)) => return Ok(value),
        Ok(Err(failure)) => failure,
        Err(payload) => Failure::new(
            QTVPR_ERR_PANIC,
            format!("internal error, please report it: {}", panic_message(payload.as_ref())),
        ),
    };
    let code = failure.code;
    // A message is text; a NUL inside it (from a path, say) would cut it short in C.
    let message = format!("{function}: {}", failure.message).replace('\0', "\\0");
    let message = CString::new(message).unwrap_or_default();
    catch((), || set_last_error(Some(LastError { code, message })));
    Err(code)
}

/// The text of a panic's payload (`panic!` with a message gives a `&str` or a `String`).
fn panic_message(payload: &(dyn Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("a panic without a message")
}

/// The message of the last error on the calling thread, or NULL if the last call of a
/// qtvpr function on this thread succeeded (or there was none).
///
/// The message is UTF-8, names the function that failed and says what is wrong, e.g.
/// "qtvpr_calibration_load: cannot read cal.npz: No such file or directory (os error 2)".
/// It is owned by qtvpr: do not free it. It stays valid until the calling thread next
/// calls a qtvpr function other than qtvpr_last_error, qtvpr_last_error_code and
/// qtvpr_version (every other function resets it), or exits; copy it to keep it.
///
/// Thread-safe: each thread has its own last error.
#[unsafe(no_mangle)]
pub extern "C" fn qtvpr_last_error() -> *const c_char {
    catch(ptr::null(), || {
        LAST_ERROR
            .try_with(|last| last.borrow().as_ref().map_or(ptr::null(), |e| e.message.as_ptr()))
            .unwrap_or(ptr::null())
    })
}

/// The code of the last error on the calling thread (a qtvpr_status), or QTVPR_OK (0)
/// if the last call of a qtvpr function on this thread succeeded (or there was none).
///
/// Use it after a function that returns NULL or 0 on error, e.g. to tell a missing
/// calibration file (QTVPR_ERR_IO) from a corrupt one (QTVPR_ERR_FILE). Thread-safe.
#[unsafe(no_mangle)]
pub extern "C" fn qtvpr_last_error_code() -> c_int {
    catch(QTVPR_ERR_PANIC as c_int, || {
        LAST_ERROR
            .try_with(|last| last.borrow().as_ref().map_or(QTVPR_OK, |e| e.code))
            .unwrap_or(QTVPR_OK) as c_int
    })
}

/// This thread's last error as the tests read it: its code and message.
#[cfg(test)]
pub(crate) fn last() -> (c_int, Option<String>) {
    let message = qtvpr_last_error();
    let message = (!message.is_null()).then(|| {
        // SAFETY: a non-NULL message is a NUL-terminated string valid until the next call.
        unsafe { std::ffi::CStr::from_ptr(message) }
            .to_str()
            .unwrap()
            .to_owned()
    });
    (qtvpr_last_error_code(), message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_an_error_and_success_clears_it() {
        let r: Result<(), _> = guard("qtvpr_test", || panic!("boom {}", 1));
        assert_eq!(r, Err(QTVPR_ERR_PANIC));
        assert_eq!(
            last(),
            (7, Some("qtvpr_test: internal error, please report it: boom 1".into()))
        );
        let r: Result<(), _> = guard("qtvpr_test", || panic!("static"));
        assert_eq!(r, Err(QTVPR_ERR_PANIC));
        assert_eq!(
            last().1.unwrap(),
            "qtvpr_test: internal error, please report it: static"
        );

        assert_eq!(guard("qtvpr_test", || Ok(5)), Ok(5));
        assert_eq!(last(), (0, None));
    }

    #[test]
    fn an_error_keeps_its_code_and_a_nul_does_not_cut_its_message() {
        let r: Result<(), _> = guard("qtvpr_test", || Err(Failure::new(QTVPR_ERR_FILE, "a\0b is bad")));
        assert_eq!(r, Err(QTVPR_ERR_FILE));
        assert_eq!(last(), (6, Some("qtvpr_test: a\\0b is bad".into())));
    }

    #[test]
    fn each_thread_has_its_own_last_error() {
        let _ = guard::<()>("qtvpr_test", || Err(Failure::null("cal")));
        assert_eq!(last(), (1, Some("qtvpr_test: cal is NULL".into())));
        std::thread::spawn(|| assert_eq!(last(), (0, None))).join().unwrap();
        assert_eq!(last().0, 1);
    }

    #[test]
    fn core_errors_map_to_their_codes() {
        let io = qtvpr::Error::Io {
            path: "x.npz".into(),
            kind: std::io::ErrorKind::NotFound,
            message: "gone".into(),
        };
        assert_eq!(Failure::from(io).code, QTVPR_ERR_IO);
        let file = qtvpr::Error::File {
            path: "x.npz".into(),
            message: "is not an npz".into(),
        };
        assert_eq!(Failure::from(file), Failure::new(QTVPR_ERR_FILE, "x.npz is not an npz"));
        let len = qtvpr::Error::ColumnLength {
            query: 0,
            len: 2,
            db: 3,
        };
        assert_eq!(Failure::from(len).code, QTVPR_ERR_SIZE);
        let nan = qtvpr::Error::NotFinite {
            what: qtvpr::Input::DeploymentSimilarity,
            row: 1,
            col: 0,
            value: f64::NAN,
        };
        assert_eq!(Failure::from(nan).code, QTVPR_ERR_INPUT);
    }
}
