//! A progress bar on stderr for long runs: drawn only when stderr is a terminal, never
//! under `--quiet`, so pipes and logs stay clean.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar counting `len` items of `what`.
pub fn bar(quiet: bool, len: usize, what: &'static str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(len as u64), ProgressDrawTarget::stderr());
    let style = ProgressStyle::with_template("{msg} {wide_bar} {pos}/{len} [{elapsed}<{eta}]").expect("valid template");
    bar.set_style(style);
    bar.set_message(what);
    bar
}
