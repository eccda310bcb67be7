//! The `console` examples of README.md and docs/*.md run as written (trycmd, the tool
//! clap and cargo test their own examples with): each `$ qtvpr-cli ...` line is run and
//! its output compared with the lines under it (`[..]` and `...` elide).
//!
//! Each document runs in a fresh sandbox that holds the repository's `data/` (trycmd's
//! `NAME.in/` template, copied for the run), so that `data/corridor/...` reads the
//! embedded real data as it does from the repository root, and what a command writes
//! (`cal.npz`, `figures/`) stays out of the repository. A block that cannot run here is
//! tagged `console,ignore`. Regenerate the outputs with `TRYCMD=overwrite`.

use std::path::Path;

#[test]
fn console_examples_run_as_written() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let work = tempfile::tempdir().unwrap();
    let cases = trycmd::TestCases::new();
    cases.register_bin("qtvpr-cli", Path::new(env!("CARGO_BIN_EXE_qtvpr-cli")));
    // The documents with `console` blocks.
    for doc in [
        "README.md",
        "docs/cli.md",
        "docs/margin-gate.md",
        "docs/deployment.md",
        "docs/self-motion-labels.md",
        "docs/sequence.md",
    ] {
        let name = doc.replace('/', "-");
        let case = work.path().join(&name);
        std::fs::copy(root.join(doc), &case).unwrap();
        let stem = case.with_extension("");
        let template = stem.with_extension("in");
        std::fs::create_dir(&template).unwrap();
        copy_dir(&root.join("data"), &template.join("data"));
        // An (empty) expected tree: trycmd then runs the document in a sandbox.
        std::fs::create_dir(stem.with_extension("out")).unwrap();
        cases.case(case);
    }
    cases.run();
}

/// `from` copied into `to` (the embedded data is a few hundred kB).
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}
