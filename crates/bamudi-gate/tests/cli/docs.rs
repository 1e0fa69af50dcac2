//! Every documented `bamudi` command runs as written.
//!
//! * Fenced `console` blocks of README.md, docs/*.md and the crates' READMEs are replayed in
//!   order, one temporary directory per document: `$ bamudi ...` lines run the binary (with
//!   the global `--element-size 60`, a coarse gate that builds in about a second, so the
//!   replay fits in CI; the commands are otherwise unchanged; `predict` reads its gate from
//!   the calibration and gets no gate flag), `$ cat FILE` followed by text
//!   writes that text to FILE (the documents show configuration files that way). Each command
//!   must exit 0. The printed output beside the commands is illustrative (numbers depend on
//!   the mesh) and is not compared.
//! * `bamudi ...` commands quoted inline in the prose must at least parse: they run with
//!   `--help` appended, which exits 0 only when every argument before it is accepted.
//! * Other commands in console blocks (`cargo ...`) are not replayed here: CI runs the test
//!   suite, and the quick reproduction test runs `reproduce-paper --quick` in-process.

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The documents whose commands are checked.
fn documents() -> Vec<PathBuf> {
    let root = workspace_root();
    let mut docs = vec![root.join("README.md")];
    for dir in ["docs", "crates"] {
        let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "md") {
                docs.push(p);
            } else if p.join("README.md").exists() {
                docs.push(p.join("README.md"));
            }
        }
    }
    docs.sort();
    docs
}

/// One step of a console block.
#[derive(Debug)]
enum Step {
    /// A `bamudi` command line (arguments after `bamudi`).
    Run(Vec<String>),
    /// `$ cat FILE` and the lines shown after it.
    Write(String, String),
}

/// The steps of every `console` block of `text`.
fn console_steps(text: &str) -> Vec<Step> {
    let mut steps = vec![];
    let mut in_console = false;
    let mut cat: Option<(String, String)> = None;
    for line in text.lines() {
        let fence = line.trim_start().starts_with("```");
        if fence {
            if let Some((f, body)) = cat.take() {
                steps.push(Step::Write(f, body));
            }
            in_console = !in_console && line.trim_start().trim_start_matches('`') == "console";
            continue;
        }
        if !in_console {
            continue;
        }
        if let Some(cmd) = line.strip_prefix("$ ") {
            if let Some((f, body)) = cat.take() {
                steps.push(Step::Write(f, body));
            }
            let words: Vec<String> = cmd.split_whitespace().map(String::from).collect();
            match words.first().map(String::as_str) {
                Some("bamudi") => steps.push(Step::Run(words[1..].to_vec())),
                Some("cat") if words.len() == 2 => cat = Some((words[1].clone(), String::new())),
                _ => {}
            }
        } else if let Some((_, body)) = cat.as_mut() {
            body.push_str(line);
            body.push('\n');
        }
    }
    steps
}

/// `bamudi ...` commands quoted inline (between backticks, within one line) in the prose,
/// outside fenced blocks; spans with alternatives (`a\|b`) or placeholders (`...`) are
/// skipped.
fn inline_commands(text: &str) -> Vec<Vec<String>> {
    let mut fenced = false;
    let mut out = vec![];
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        for span in line.split('`').skip(1).step_by(2) {
            if let Some(rest) = span.strip_prefix("bamudi ")
                && !rest.contains('|')
                && !rest.contains("...")
            {
                out.push(rest.split_whitespace().map(String::from).collect());
            }
        }
    }
    out
}

fn bamudi(dir: &Path, args: &[String]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_bamudi"))
        .args(args)
        .current_dir(dir)
        .env("CI", "1")
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("the bamudi binary runs")
}

#[test]
fn every_documented_command_runs_as_written() {
    let mut failures = vec![];
    let (mut replayed, mut parsed) = (0, 0);
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        let name = doc.file_name().unwrap().to_string_lossy().into_owned();
        let dir = std::env::temp_dir().join(format!("bamudi_docs_{}_{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for step in console_steps(&text) {
            match step {
                Step::Write(file, body) => std::fs::write(dir.join(file), body).unwrap(),
                Step::Run(args) => {
                    // `predict` takes its gate from the calibration's model.json
                    let mut all = match args.first().map(String::as_str) {
                        Some("predict") => vec![],
                        _ => vec!["--element-size".to_string(), "60".to_string()],
                    };
                    all.extend(args.iter().cloned());
                    let o = bamudi(&dir, &all);
                    replayed += 1;
                    if !o.status.success() {
                        let e = String::from_utf8_lossy(&o.stderr);
                        failures.push(format!("{}: bamudi {}\n{e}", doc.display(), args.join(" ")));
                    }
                }
            }
        }
        for mut args in inline_commands(&text) {
            args.push("--help".into());
            let o = bamudi(&dir, &args);
            parsed += 1;
            if !o.status.success() {
                let e = String::from_utf8_lossy(&o.stderr);
                failures.push(format!(
                    "{} (inline): bamudi {}\n{e}",
                    doc.display(),
                    args.join(" ")
                ));
            }
        }
    }
    // the documents hold a simulate -> calibrate -> predict and a simulate -> close-loop
    // walk-through (docs/cli.md): fewer replayed commands means the extraction broke
    assert!(
        replayed >= 5,
        "only {replayed} documented commands replayed"
    );
    assert!(parsed >= 2, "only {parsed} inline commands checked");
    assert!(
        failures.is_empty(),
        "documented commands fail:\n{}",
        failures.join("\n")
    );
}

#[test]
fn the_extraction_reads_console_blocks_and_inline_commands() {
    let doc = "text `bamudi predict --h-up 1` more `cargo run -- ...`\n```console\n$ cat a.toml\nx = 1\n$ bamudi calibrate --config a.toml\noutput line\n```\n```sh\n$ bamudi not-console\n```\n";
    let steps = console_steps(doc);
    assert_eq!(steps.len(), 2, "{steps:?}");
    assert!(matches!(&steps[0], Step::Write(f, b) if f == "a.toml" && b == "x = 1\n"));
    assert!(matches!(&steps[1], Step::Run(a) if a[0] == "calibrate"));
    assert_eq!(inline_commands(doc), vec![vec!["predict", "--h-up", "1"]]);
}
