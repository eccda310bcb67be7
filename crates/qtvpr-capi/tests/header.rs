//! `include/qtvpr.h` is generated from this crate by cbindgen and committed, so that C
//! users have it without a Rust toolchain. This test generates it and fails when the
//! committed header differs, so CI catches a header left stale by a change here.
//!
//! Regenerate it with `QTVPR_UPDATE_HEADER=1 cargo test -p qtvpr-capi --test header`.
//!
//! cbindgen's output is made C89-clean here (scripts/capi.sh compiles the header with
//! `-std=c89 -pedantic -Werror`): cbindgen 0.29 ends every enumerator with a comma and
//! comments its `cpp_compat` guards with `//`, and no option of its configuration changes
//! either, so [`c89`] drops the comma after each enum's last enumerator and turns those
//! comments into `/* */`.

use std::path::Path;

#[test]
fn header_is_current() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let header_path = crate_dir.join("../../include/qtvpr.h");
    let config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).expect("cbindgen.toml parses");
    // The crate's own sources only (following its `mod`s): no `cargo metadata` run, and
    // no C type comes from a dependency.
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(crate_dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let generated = c89(&String::from_utf8(generated).expect("the header is UTF-8"));

    if std::env::var_os("QTVPR_UPDATE_HEADER").is_some_and(|v| v == "1") {
        std::fs::write(&header_path, &generated).expect("include/qtvpr.h is writable");
        return;
    }
    let committed = std::fs::read_to_string(&header_path).unwrap_or_default();
    if committed != generated {
        let first = committed
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or_else(|| committed.lines().count().min(generated.lines().count()));
        panic!(
            "include/qtvpr.h is not what crates/qtvpr-capi generates (first difference at line {}); \
             regenerate it with QTVPR_UPDATE_HEADER=1 cargo test -p qtvpr-capi --test header",
            first + 1
        );
    }
}

/// `header` without the two C89 (`-pedantic`) violations cbindgen writes: a comma after
/// the last enumerator (`X = 7,` before `} name;`) and `//` comments after code
/// (`#endif // __cplusplus`). Lines of block comments are left alone.
fn c89(header: &str) -> String {
    let lines: Vec<&str> = header.lines().collect();
    let mut out = String::with_capacity(header.len());
    for (i, &line) in lines.iter().enumerate() {
        let trimmed = line.trim_start();
        let code = !(trimmed.starts_with('*') || trimmed.starts_with("/*"));
        let closes_enum = lines
            .get(i + 1)
            .is_some_and(|next| next.starts_with("} ") && next.ends_with(';'));
        match (line.strip_suffix(','), line.find("//")) {
            (Some(last), _) if code && closes_enum => out.push_str(last),
            (_, Some(at)) if code => {
                out.push_str(&format!("{}/* {} */", &line[..at], line[at + 2..].trim()));
            }
            _ => out.push_str(line),
        }
        out.push('\n');
    }
    out
}
