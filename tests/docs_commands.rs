//! Every `twinbench …` (and `cargo run --release -- …`) command in the README's and docs/'
//! shell blocks still parses: a renamed subcommand or flag fails here, not in a reader's
//! terminal. Placeholders (`FILE`, `N`, `STEP.csv`) may fail their value's check; optional
//! parts in brackets are taken as written, `...` left out.

use clap::error::ErrorKind;
use clap::Parser;
use std::path::{Path, PathBuf};
use twinbench::cli::Cli;

fn docs() -> Vec<PathBuf> {
    let root = twinbench::pack::workspace_root();
    let mut files = vec![root.join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

/// (line number, command line) of every twinbench command in a shell block of `path`.
fn commands(path: &Path) -> Vec<(usize, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = Vec::new();
    let mut in_shell = false;
    let mut pending: Option<(usize, String)> = None;
    for (k, line) in text.lines().enumerate() {
        let trimmed = line.trim();
        if let Some(lang) = trimmed.strip_prefix("```") {
            in_shell = !in_shell && matches!(lang, "sh" | "bash" | "console" | "shell");
            continue;
        }
        if !in_shell {
            continue;
        }
        let (start, text) = match pending.take() {
            Some((n, acc)) => (n, format!("{acc} {trimmed}")),
            None => (k + 1, trimmed.to_string()),
        };
        if let Some(head) = text.strip_suffix('\\') {
            pending = Some((start, head.to_string()));
            continue;
        }
        let text = text.trim_start_matches("$ ");
        for prefix in ["twinbench ", "cargo run --release -- "] {
            if let Some(args) = text.strip_prefix(prefix) {
                out.push((start, args.to_string()));
            }
        }
    }
    out
}

/// Shell words of a documented command: quotes respected, a `#` comment cut, `[`/`]` of
/// optional parts dropped, `...` and `|`-alternatives' later choices left out.
fn words(args: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut cur = String::new();
    let mut quote: Option<char> = None;
    let mut started = false;
    for c in args.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => cur.push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                started = true;
            }
            (None, '#') if !started => break,
            (None, c) if c.is_whitespace() => {
                if started {
                    words.push(std::mem::take(&mut cur));
                    started = false;
                }
            }
            (None, c) => {
                cur.push(c);
                started = true;
            }
        }
    }
    if started {
        words.push(cur);
    }
    words
        .into_iter()
        .map(|w| w.trim_start_matches('[').trim_end_matches(']').to_string())
        .map(|w| w.split('|').next().unwrap_or_default().to_string())
        .filter(|w| !w.is_empty() && w != "..." && w != "…")
        .collect()
}

#[test]
fn every_documented_command_parses() {
    let mut checked = 0;
    let mut failures = Vec::new();
    for doc in docs() {
        for (line, args) in commands(&doc) {
            let mut argv = vec!["twinbench".to_string()];
            argv.extend(words(&args));
            checked += 1;
            if let Err(e) = Cli::try_parse_from(&argv) {
                let placeholder = matches!(
                    e.kind(),
                    ErrorKind::InvalidValue | ErrorKind::ValueValidation
                );
                let help = matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion);
                if !placeholder && !help {
                    failures.push(format!(
                        "{}:{line}: twinbench {args}\n    {}",
                        doc.display(),
                        e.to_string().lines().next().unwrap_or_default()
                    ));
                }
            }
        }
    }
    assert!(checked >= 20, "only {checked} documented commands found");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_word_splitter_reads_documented_commands_as_a_shell_would() {
    assert_eq!(
        words("run systems/rls_v.toml --out lap.csv [--set vehicle.c_lift_front=0.9] [--json]   # comment"),
        ["run", "systems/rls_v.toml", "--out", "lap.csv", "--set", "vehicle.c_lift_front=0.9", "--json"]
    );
    assert_eq!(
        words("identify step STEP.csv ..."),
        ["identify", "step", "STEP.csv"]
    );
    assert_eq!(
        words("lap 'my lap.csv' --out x"),
        ["lap", "my lap.csv", "--out", "x"]
    );
    // A renamed flag is caught.
    let e = Cli::try_parse_from(["twinbench", "run", "x.toml", "--no-such-flag"]).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::UnknownArgument);
}
