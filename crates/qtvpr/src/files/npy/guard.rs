//! The file boundary's last line (semantics §10: no panic reaches a user): every public
//! reader runs under [`guarded`], which turns a panic inside it, in this crate or in a
//! dependency on hostile bytes, into an error naming the file.
//!
//! No reader is known to panic: every check of the module's readers exists so that none
//! does. This is what stands behind them, for a dependency's panic nobody has found yet.
//! A panic caught here prints nothing: the panic hook is wrapped, once, so that it stays
//! silent on a thread while that thread is inside a guarded read, and is the previous
//! hook everywhere else (a program's own hook, or Rust's default, keeps working).

use std::cell::Cell;
use std::panic::{self, AssertUnwindSafe};
use std::path::Path;
use std::sync::Once;

use super::open::file_error;
use crate::error::Result;

thread_local! {
    /// How deep this thread is in guarded reads (a reader calls another).
    static GUARDED: Cell<usize> = const { Cell::new(0) };
}

/// Run `read`, a reader of the file `path` names; a panic in it becomes an
/// [`Error::File`](crate::error::Error::File) naming the file.
///
/// # Errors
/// Those of `read`, and a panic as an error.
pub(crate) fn guarded<T>(path: &Path, read: impl FnOnce() -> Result<T>) -> Result<T> {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            if GUARDED.with(Cell::get) == 0 {
                previous(info);
            }
        }));
    });
    GUARDED.with(|g| g.set(g.get() + 1));
    // Unwind safety: what `read` builds is dropped with the panic; it holds no state
    // that outlives the call.
    let result = panic::catch_unwind(AssertUnwindSafe(read));
    GUARDED.with(|g| g.set(g.get() - 1));
    result.unwrap_or_else(|payload| {
        let why = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(file_error(
            path,
            format!("cannot be read: its reader failed on it ({why}); please report this file"),
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_an_error_naming_the_file_and_the_hook_stays() {
        let e = guarded::<()>(Path::new("x.npz"), || panic!("index out of bounds")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "x.npz cannot be read: its reader failed on it (index out of bounds); please report this file"
        );
        // Nested, and the depth is restored after a panic.
        let e = guarded::<()>(Path::new("a"), || guarded(Path::new("b"), || panic!("{}", 7))).unwrap_err();
        assert_eq!(
            e.to_string(),
            "b cannot be read: its reader failed on it (7); please report this file"
        );
        assert_eq!(GUARDED.with(Cell::get), 0);
        assert_eq!(guarded(Path::new("c"), || Ok(3)).unwrap(), 3);
        // Outside a guard a panic still panics.
        assert!(panic::catch_unwind(|| panic!("not guarded")).is_err());
    }
}
