//! The layout of `--help`: every command lists its own options first and the global
//! ones (`--threads`, `-q/--quiet`) last, under a heading of their own.

use std::process::Command;

fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_qtvpr-cli"))
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

/// The subcommands `qtvpr-cli --help` lists (so that a new one is checked too).
fn commands() -> Vec<String> {
    let text = help(&["--help"]);
    let section = text.split("Commands:\n").nth(1).expect("a Commands section");
    section
        .lines()
        .take_while(|l| !l.is_empty())
        // A command line is "  name  description"; continuations are indented further.
        .filter(|l| l.starts_with("  ") && !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|&name| name != "help")
        .map(str::to_string)
        .collect()
}

#[test]
fn global_options_come_last_under_their_own_heading() {
    let commands = commands();
    assert!(
        ["threshold", "evaluate", "similarity", "ground-truth"]
            .iter()
            .all(|c| commands.iter().any(|n| n == c)),
        "{commands:?}"
    );
    for command in &commands {
        for flag in ["--help", "-h"] {
            let text = help(&[command, flag]);
            let at = |needle: &str| {
                text.find(needle)
                    .unwrap_or_else(|| panic!("{command} {flag}: no {needle:?} in\n{text}"))
            };
            let heading = at("\nGlobal options:\n");
            // The command's own options, up to its --help, all before the heading ...
            assert!(at("\nOptions:\n") < heading, "{command} {flag}:\n{text}");
            assert!(at("--help") < heading, "{command} {flag}:\n{text}");
            // ... and the global ones only after it, each once, in this order.
            let (own, global) = text.split_at(heading);
            for option in ["--threads", "--quiet"] {
                assert!(
                    !own.contains(option),
                    "{command} {flag}: {option} among the own options"
                );
                assert_eq!(global.matches(option).count(), 1, "{command} {flag}:\n{global}");
            }
            assert!(global.find("--threads") < global.find("--quiet"), "{command} {flag}");
            // Nothing after the global options: the heading is the last one.
            let headings = global.lines().filter(|l| l.ends_with(':') && !l.starts_with(' '));
            assert_eq!(headings.count(), 1, "{command} {flag}:\n{global}");
        }
    }
}
