//! Every command's `--help` fits the terminal's 110 columns, in a pipe and on a wide terminal.

use crate::support::{binpick, stdout};

/// The commands a help text lists (its `Commands:` section), `help` left out.
fn commands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.is_empty())
        .filter(|l| l.starts_with("  ") && !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect()
}

fn help_of(path: &[String], columns: Option<&str>) -> String {
    let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
    args.push("--help");
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_binpick"));
    cmd.args(&args);
    match columns {
        Some(c) => cmd.env("COLUMNS", c),
        None => cmd.env_remove("COLUMNS"),
    };
    let o = cmd.output().expect("binpick runs");
    assert!(o.status.success(), "{args:?}");
    stdout(&o)
}

#[test]
fn every_help_fits_110_columns() {
    let top = stdout(&binpick(&["--help"]));
    let mut paths: Vec<Vec<String>> = vec![vec![]];
    for c in commands(&top) {
        let sub = commands(&help_of(std::slice::from_ref(&c), None));
        paths.push(vec![c.clone()]);
        paths.extend(sub.into_iter().map(|s| vec![c.clone(), s]));
    }
    assert!(paths.len() > 15, "{paths:?}");
    for p in &paths {
        for columns in [None, Some("300")] {
            let text = help_of(p, columns);
            let (n, line) = text.lines().map(|l| (l.chars().count(), l)).max().unwrap_or_default();
            assert!(
                n <= 110,
                "binpick {p:?} --help (COLUMNS {columns:?}): {n} columns: {line}"
            );
        }
    }
    // Negative control: what is wrapped is longer than the width unwrapped (an option's help
    // joined from its lines).
    let run = help_of(&["run".to_string()], None);
    let joined: String = run
        .lines()
        .skip_while(|l| !l.contains("--deterministic"))
        .take_while(|l| l.contains("--deterministic") || l.starts_with("                 "))
        .map(str::trim)
        .collect::<Vec<_>>()
        .join(" ");
    assert!(joined.chars().count() > 110, "{joined}");
}
