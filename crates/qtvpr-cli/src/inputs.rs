//! Core errors named after the command line: which option and file a matrix came from.

/// Attach to a core error the options and files of the matrices it is about:
/// `sources` maps [`qtvpr::names`] constants to `--option FILE`, looked up by
/// [`qtvpr::Error::inputs`]. Errors about no matrix in `sources` are returned as they are.
pub fn blame(err: qtvpr::Error, sources: &[(&'static str, String)]) -> anyhow::Error {
    let context: Vec<&str> = err.inputs(sources).into_iter().map(String::as_str).collect();
    if context.is_empty() {
        err.into()
    } else {
        let context = context.join(" / ");
        anyhow::Error::new(err).context(context)
    }
}
