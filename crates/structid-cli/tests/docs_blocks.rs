//! Every fenced code block of `README.md` and `docs/*.md`, run or checked.
//!
//! The blocks are found by their fences (with the language tag and the line of the opening
//! fence) and handled by their language:
//!
//! * `rust`: compiled and run as doc tests of the facade crate (`src/readme_doctests.rs`
//!   includes every page; `cargo test --doc -p structid`). Checked here: every page is included.
//! * `python`: run by `python/tests/test_readme.py` (every `python` block of every page, in a
//!   temporary directory). Checked here: that test exists and reads every page.
//! * `toml`: loaded. A file with `[signals]` is a model file: parsed and validated by the
//!   library (`ModelFile::parse`) and, when every block has its `truth` (or is an operator),
//!   simulated by `structid simulate` on a short input. A file with `[[experiment]]` is a sweep
//!   configuration (`SweepFile::parse`). Anything else is a fragment of a model file (a
//!   `[linear]` or a `[discover]` section alone), completed by the sections it lacks (fixed,
//!   small ones: see `complete_fragment`) and loaded as a model file. A block that the text just
//!   before it names ("Save this as `first.toml`") is also written under that name, for the
//!   commands after it.
//! * `sh`, `bash`, `console`, and `text` blocks whose first line is a command (`structid …`,
//!   `target/release/structid …`, `cargo …`): split into commands (lines joined at a trailing
//!   `\`, comment lines after a command are its stated output). Each page runs in a temporary
//!   directory of its own, holding a copy of the repository's `examples/` and `structid` (this
//!   crate's binary) on the PATH; its commands run in page order, so later blocks use the
//!   outputs of earlier ones, and must exit with success. Input files a command names that no
//!   earlier command wrote are made first from the fixtures of `make_fixture` (inputs by
//!   `structid input`, records by `structid simulate` of the shipped Hammerstein model, MAT-files
//!   written here). Where the text states a result, `STATED` asserts it.
//!
//!   A command is **only checked statically** when it
//!   1. runs cargo (a build, a test run, a benchmark or an example: minutes, and a nested
//!      cargo), except `cargo run -p structid-cli -- ARGS`, which is `structid ARGS`;
//!   2. is a synopsis (usage notation: `[--option]`, `a|b` alternatives, `…`);
//!   3. reads the shared benchmark records (`../shared/data`, `$STRUCTID_DATA`, `structid data
//!      silverbox|tanks`), which are not part of the repository;
//!   4. uses a path that a statically checked command before it in the same block writes;
//!   5. runs another tool (`pip`, `maturin`: the Python package, built by the `python_bindings`
//!      test).
//!
//!   Static checks: for `structid`, the subcommand exists and every option is listed by
//!   `structid <subcommand> --help`, with each value among the option's possible values when
//!   it has a fixed set; for cargo, the package (`-p`) and the example, test or bench target
//!   named exist in the workspace's file tree; for other tools, the `./paths` they name exist.
//! * `text` blocks that are not commands (formulas, messages) have nothing to run.
//!
//! A batch script (`#SBATCH --array=A-B`) runs once per array index, with the variables Slurm
//! sets (`SLURM_ARRAY_TASK_ID`, `SLURM_CPUS_PER_TASK`).

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

const BIN: &str = env!("CARGO_BIN_EXE_structid");

/// The workspace root (the parent of `crates/`).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("crates/structid-cli lies two levels below the workspace root")
        .to_path_buf()
}

// ---------------------------------------------------------------------------------------------
// Blocks
// ---------------------------------------------------------------------------------------------

/// A fenced code block of a page.
#[derive(Clone, Debug)]
struct Block {
    /// The page, relative to the workspace root (`docs/cli.md`).
    page: String,
    /// Line (1-based) of the opening fence.
    line: usize,
    /// The language tag (empty when there is none).
    lang: String,
    /// The lines between the fences.
    body: Vec<String>,
    /// The paragraph of text just before the block.
    before: String,
}

impl Block {
    fn at(&self) -> String {
        format!("{}:{}", self.page, self.line)
    }
}

/// The pages whose blocks are run: README.md and docs/*.md.
fn pages() -> Vec<String> {
    let root = root();
    let mut pages = vec!["README.md".to_string()];
    let mut docs: Vec<String> = std::fs::read_dir(root.join("docs"))
        .expect("docs/ exists")
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    docs.sort();
    pages.extend(docs);
    pages
}

/// The fenced blocks of a page (fences of three or more backticks or tildes, indented by at
/// most three spaces).
fn blocks(page: &str) -> Vec<Block> {
    let text = std::fs::read_to_string(root().join(page))
        .unwrap_or_else(|e| panic!("cannot read {page}: {e}"));
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    let mut paragraph: Vec<&str> = Vec::new();
    let mut paragraph_ended = false;
    while i < lines.len() {
        let l = lines[i];
        let trimmed = l.trim_start();
        let indent = l.len() - trimmed.len();
        let fence: String = trimmed
            .chars()
            .take_while(|c| *c == '`' || *c == '~')
            .collect();
        let is_fence = indent <= 3
            && fence.len() >= 3
            && fence.chars().all(|c| c == fence.chars().next().unwrap());
        if !is_fence {
            // The last paragraph before the block, across the blank line before its fence.
            if l.trim().is_empty() {
                paragraph_ended = true;
            } else {
                if paragraph_ended {
                    paragraph.clear();
                    paragraph_ended = false;
                }
                paragraph.push(l);
            }
            i += 1;
            continue;
        }
        let lang = trimmed[fence.len()..]
            .split_whitespace()
            .next()
            .unwrap_or("")
            .to_string();
        let start = i;
        let mut body = Vec::new();
        i += 1;
        loop {
            assert!(
                i < lines.len(),
                "{page}:{}: the code block is never closed",
                start + 1
            );
            let t = lines[i].trim();
            if t.starts_with(&fence) && t.chars().all(|c| c == fence.chars().next().unwrap()) {
                break;
            }
            body.push(lines[i].to_string());
            i += 1;
        }
        out.push(Block {
            page: page.to_string(),
            line: start + 1,
            lang,
            body,
            before: paragraph.join(" "),
        });
        paragraph.clear();
        paragraph_ended = false;
        i += 1;
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Commands: logical lines, words, classification
// ---------------------------------------------------------------------------------------------

/// One command of a shell block: a logical line (continuations joined, a `for … done` loop as
/// one), with the comment lines after it.
#[derive(Clone, Debug)]
struct Cmd {
    /// Doc line of its first line.
    line: usize,
    /// The text as a shell reads it (continuations joined).
    text: String,
    /// The comments after it: its own trailing comment and the comment lines that follow.
    comments: Vec<String>,
}

fn logical_commands(block: &Block) -> Vec<Cmd> {
    let mut cmds: Vec<Cmd> = Vec::new();
    let mut i = 0;
    let body = &block.body;
    while i < body.len() {
        let line = body[i].trim();
        if line.is_empty() {
            i += 1;
            continue;
        }
        if line.starts_with('#') {
            if let Some(last) = cmds.last_mut() {
                last.comments
                    .push(line.trim_start_matches('#').trim().to_string());
            }
            i += 1;
            continue;
        }
        // A synopsis continues on indented lines of options: `    [--beta B|auto] …`.
        let raw = &body[i];
        if raw.starts_with(char::is_whitespace)
            && line.starts_with(['[', '(', '-', '|'])
            && let Some(last) = cmds.last_mut()
        {
            last.text.push(' ');
            last.text.push_str(line);
            i += 1;
            continue;
        }
        let first = i;
        let mut text = String::new();
        let mut depth = 0i32;
        loop {
            let l = body[i].trim_end();
            let (content, more) = match l.strip_suffix('\\') {
                Some(c) => (c, true),
                None => (l, false),
            };
            text.push_str(content.trim());
            let first_word = content.split_whitespace().next().unwrap_or("");
            if matches!(first_word, "for" | "while" | "until" | "if") {
                depth += 1;
            }
            if matches!(first_word, "done" | "fi")
                || content.trim_end().ends_with("; done")
                || content.trim_end().ends_with("; fi")
            {
                depth -= 1;
            }
            i += 1;
            if (more || depth > 0) && i < body.len() {
                text.push(if more { ' ' } else { '\n' });
                continue;
            }
            break;
        }
        let comment = trailing_comment(&text);
        cmds.push(Cmd {
            line: block.line + 1 + first,
            text,
            comments: comment.into_iter().collect(),
        });
    }
    cmds
}

/// The comment at the end of a command line (` # …` outside quotes).
fn trailing_comment(text: &str) -> Option<String> {
    comment_start(text).map(|k| text[k + 1..].trim().to_string())
}

/// The byte index of the `#` that starts a comment (outside quotes, at the start of a word).
fn comment_start(text: &str) -> Option<usize> {
    let (mut single, mut double) = (false, false);
    let mut previous = ' ';
    for (k, c) in text.char_indices() {
        match c {
            '\'' if !double => single = !single,
            '"' if !single => double = !double,
            '#' if !single && !double && previous.is_whitespace() => return Some(k),
            _ => {}
        }
        previous = c;
    }
    None
}

/// A word of a command line or an operator between simple commands.
#[derive(Clone, Debug, PartialEq)]
enum Word {
    Arg(String),
    Op(String),
}

/// The words of a shell line: quotes removed, `$NAME` and `${NAME}` expanded from `vars` (left
/// as they are when unknown), comments dropped, operators (`;`, `&&`, `|`, `>`, parentheses …)
/// separated.
fn words(text: &str, vars: &HashMap<String, String>) -> Vec<Word> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut in_word = false;
    let mut k = 0;
    let flush = |cur: &mut String, in_word: &mut bool, out: &mut Vec<Word>| {
        if *in_word {
            out.push(Word::Arg(std::mem::take(cur)));
            *in_word = false;
        }
    };
    while k < chars.len() {
        let c = chars[k];
        match c {
            '\n' => {
                flush(&mut cur, &mut in_word, &mut out);
                out.push(Word::Op(";".into()));
            }
            c if c.is_whitespace() => flush(&mut cur, &mut in_word, &mut out),
            '#' if !in_word => {
                while k < chars.len() && chars[k] != '\n' {
                    k += 1;
                }
                continue;
            }
            '\'' => {
                in_word = true;
                k += 1;
                while k < chars.len() && chars[k] != '\'' {
                    cur.push(chars[k]);
                    k += 1;
                }
            }
            '"' => {
                in_word = true;
                k += 1;
                while k < chars.len() && chars[k] != '"' {
                    if chars[k] == '$' {
                        k = expand(&chars, k, vars, &mut cur);
                        continue;
                    }
                    cur.push(chars[k]);
                    k += 1;
                }
            }
            '\\' if k + 1 < chars.len() => {
                in_word = true;
                cur.push(chars[k + 1]);
                k += 1;
            }
            '$' => {
                in_word = true;
                k = expand(&chars, k, vars, &mut cur);
                continue;
            }
            ';' | '|' | '&' | '>' | '<' | '(' | ')' => {
                flush(&mut cur, &mut in_word, &mut out);
                let mut op = c.to_string();
                if k + 1 < chars.len() && chars[k + 1] == c && matches!(c, '|' | '&' | '>') {
                    op.push(c);
                    k += 1;
                }
                out.push(Word::Op(op));
            }
            _ => {
                in_word = true;
                cur.push(c);
            }
        }
        k += 1;
    }
    flush(&mut cur, &mut in_word, &mut out);
    out
}

/// Expands the variable at `chars[k] == '$'` into `cur`; returns the index after it.
fn expand(chars: &[char], k: usize, vars: &HashMap<String, String>, cur: &mut String) -> usize {
    let (name, end) = if chars.get(k + 1) == Some(&'{') {
        let close = (k + 2..chars.len())
            .find(|&j| chars[j] == '}')
            .unwrap_or(chars.len() - 1);
        (chars[k + 2..close].iter().collect::<String>(), close + 1)
    } else {
        let end = (k + 1..chars.len())
            .find(|&j| !(chars[j].is_alphanumeric() || chars[j] == '_'))
            .unwrap_or(chars.len());
        (chars[k + 1..end].iter().collect::<String>(), end)
    };
    match vars.get(&name) {
        Some(v) if !name.is_empty() => cur.push_str(v),
        _ => cur.extend(&chars[k..end]),
    }
    end
}

/// A simple command: its variable assignments, its words and where its output goes.
#[derive(Clone, Debug, Default)]
struct Simple {
    assignments: Vec<(String, String)>,
    args: Vec<String>,
    redirects: Vec<String>,
}

/// The simple commands of a line (split at `;`, `&&`, `||`, `|`, parentheses; shell keywords
/// such as `do` dropped).
fn simple_commands(words: &[Word]) -> Vec<Simple> {
    let mut out = Vec::new();
    let mut cur = Simple::default();
    let mut redirect = false;
    let push = |cur: &mut Simple, out: &mut Vec<Simple>| {
        if !cur.args.is_empty() || !cur.assignments.is_empty() {
            out.push(std::mem::take(cur));
        }
    };
    for w in words {
        match w {
            Word::Op(op) if op == ">" || op == ">>" || op == "<" => redirect = true,
            Word::Op(_) => push(&mut cur, &mut out),
            Word::Arg(a) => {
                if redirect {
                    cur.redirects.push(a.clone());
                    redirect = false;
                } else if cur.args.is_empty()
                    && matches!(a.as_str(), "do" | "then" | "else" | "done" | "fi")
                {
                } else if cur.args.is_empty()
                    && let Some((name, value)) = assignment(a)
                {
                    cur.assignments.push((name, value));
                } else {
                    cur.args.push(a.clone());
                }
            }
        }
    }
    push(&mut cur, &mut out);
    out.retain(|s| !matches!(s.args.first().map(String::as_str), Some("for" | "while")));
    out
}

/// `NAME=value`, a shell variable assignment.
fn assignment(word: &str) -> Option<(String, String)> {
    let (name, value) = word.split_once('=')?;
    (!name.is_empty()
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !name.starts_with(|c: char| c.is_ascii_digit()))
    .then(|| (name.to_string(), value.to_string()))
}

fn is_structid(program: &str) -> bool {
    program == "structid" || program.ends_with("/structid")
}

/// Usage notation: optional parts in brackets, alternatives `a|b` written without spaces,
/// ellipses.
fn is_synopsis(text: &str) -> bool {
    let text = &text[..comment_start(text).unwrap_or(text.len())];
    let chars: Vec<char> = text.chars().collect();
    text.contains("[-")
        || text.contains('…')
        || text.contains("...")
        || (1..chars.len().saturating_sub(1)).any(|k| {
            chars[k] == '|' && !chars[k - 1].is_whitespace() && !chars[k + 1].is_whitespace()
        })
}

/// What is done with a command.
#[derive(Clone, Debug, PartialEq)]
enum Plan {
    /// Variable assignments only: kept for the commands after it.
    Assign,
    /// Run with bash (the text given, which may differ from the doc's for `cargo run -p
    /// structid-cli -- ARGS`).
    Run(String),
    /// Checked statically, for the reason given.
    Static(String),
}

const SHARED_DATA: [&str; 3] = ["../shared/data", "STRUCTID_DATA", "shared/data/"];

/// Decides how a command is handled (see the module documentation), given the paths that
/// statically checked commands before it in the block write.
fn plan(cmd: &Cmd, vars: &HashMap<String, String>, written: &[String]) -> Plan {
    let simple = simple_commands(&words(&cmd.text, vars));
    if simple.iter().all(|s| s.args.is_empty()) {
        return Plan::Assign;
    }
    if is_synopsis(&cmd.text) {
        return Plan::Static("a synopsis (usage notation)".into());
    }
    let mut run_text = cmd.text.clone();
    for s in &simple {
        let Some(program) = s.args.first().map(String::as_str) else {
            continue;
        };
        if program == "cargo" {
            match structid_cli_args(&s.args) {
                Some(_) if simple.len() == 1 => {
                    let after = cmd
                        .text
                        .split_once(" -- ")
                        .expect("`--` before the arguments")
                        .1;
                    run_text = format!("structid {after}");
                }
                _ => return Plan::Static("runs cargo (a build, tests, an example)".into()),
            }
        } else if !is_structid(program) && !is_shell_utility(program) {
            return Plan::Static(format!("runs `{program}`, another tool"));
        }
    }
    let all: Vec<&String> = simple
        .iter()
        .flat_map(|s| s.args.iter().chain(&s.redirects))
        .collect();
    if all
        .iter()
        .any(|a| SHARED_DATA.iter().any(|d| a.contains(d)))
        || simple.iter().any(|s| {
            let sub = structid_words(s);
            sub.len() >= 2 && sub[0] == "data" && matches!(sub[1].as_str(), "silverbox" | "tanks")
        })
    {
        return Plan::Static("reads the shared benchmark records".into());
    }
    let normal = |p: &str| p.trim_start_matches("./").trim_end_matches('/').to_string();
    if let Some(p) = all.iter().find(|a| {
        let a = normal(a);
        written
            .iter()
            .any(|w| !w.is_empty() && (a == *w || a.starts_with(&format!("{w}/"))))
    }) {
        return Plan::Static(format!(
            "uses `{p}`, which a statically checked command before it writes"
        ));
    }
    Plan::Run(run_text)
}

fn is_shell_utility(program: &str) -> bool {
    matches!(
        program,
        "head" | "tail" | "cat" | "cp" | "mv" | "mkdir" | "rm" | "ls" | "echo" | "cd" | "wc"
    )
}

/// The `structid` arguments of `cargo run … -p structid-cli … -- ARGS`.
fn structid_cli_args(args: &[String]) -> Option<Vec<String>> {
    if args.get(1).map(String::as_str) != Some("run") {
        return None;
    }
    let dash = args.iter().position(|a| a == "--")?;
    let pkg = args[..dash]
        .windows(2)
        .find(|w| w[0] == "-p" || w[0] == "--package")
        .map(|w| w[1].as_str());
    (pkg == Some("structid-cli")).then(|| args[dash + 1..].to_vec())
}

/// The words of a structid command after the program (or of `cargo run -p structid-cli --`).
fn structid_words(s: &Simple) -> Vec<String> {
    let Some(program) = s.args.first() else {
        return Vec::new();
    };
    if is_structid(program) {
        s.args[1..].to_vec()
    } else if program == "cargo" {
        structid_cli_args(&s.args).unwrap_or_default()
    } else {
        Vec::new()
    }
}

/// The paths a command writes: `--out`/`-o` values, redirections, and the arguments of a
/// program run by `cargo run … -- ARGS`.
fn writes(cmd: &Cmd, vars: &HashMap<String, String>) -> Vec<String> {
    let mut out = Vec::new();
    for s in simple_commands(&words(&cmd.text, vars)) {
        out.extend(s.redirects.iter().cloned());
        for w in s.args.windows(2) {
            if w[0] == "--out" || w[0] == "-o" {
                out.push(w[1].clone());
            }
        }
        if s.args.first().map(String::as_str) == Some("cargo")
            && let Some(dash) = s.args.iter().position(|a| a == "--")
        {
            out.extend(
                s.args[dash + 1..]
                    .iter()
                    .filter(|a| !a.starts_with('-'))
                    .cloned(),
            );
        }
    }
    out.into_iter()
        .map(|p| p.trim_start_matches("./").trim_end_matches('/').to_string())
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Static checks
// ---------------------------------------------------------------------------------------------

/// The help of `structid <path> --help`, cached.
fn help(path: &[String]) -> String {
    static CACHE: OnceLock<Mutex<HashMap<Vec<String>, String>>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    if let Some(h) = cache.lock().unwrap().get(path) {
        return h.clone();
    }
    let out = Command::new(BIN)
        .args(path)
        .arg("--help")
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "structid {} --help failed: {}",
        path.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    let h = String::from_utf8_lossy(&out.stdout).into_owned();
    cache.lock().unwrap().insert(path.to_vec(), h.clone());
    h
}

/// The subcommands a help text lists.
fn subcommands(help: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut inside = false;
    for l in help.lines() {
        if l.starts_with("Commands:") {
            inside = true;
        } else if inside {
            if !l.starts_with("  ") {
                break;
            }
            if let Some(name) = l.split_whitespace().next() {
                out.push(name.to_string());
            }
        }
    }
    out
}

/// The options of a help text, each with its paragraph (its lines up to the next option).
fn options(help: &str) -> BTreeMap<String, String> {
    let mut out: BTreeMap<String, String> = BTreeMap::new();
    let mut current: Vec<String> = Vec::new();
    let mut inside = false;
    for l in help.lines() {
        if l.starts_with("Options:") {
            inside = true;
            continue;
        }
        if !inside {
            continue;
        }
        let t = l.trim_start();
        let indent = l.len() - t.len();
        if t.starts_with('-') && (2..=6).contains(&indent) {
            current = t
                .split_whitespace()
                .take_while(|w| w.starts_with('-'))
                .map(|w| {
                    w.trim_end_matches(',')
                        .split(['=', '<'])
                        .next()
                        .unwrap()
                        .to_string()
                })
                .collect();
        }
        for name in &current {
            let p = out.entry(name.clone()).or_default();
            p.push_str(l);
            p.push('\n');
        }
    }
    // Aliases (`[alias: --validate]`, `[aliases: --a, --b]`) share their option's paragraph.
    let mut aliases = Vec::new();
    for paragraph in out.values() {
        for marker in ["[alias: ", "[aliases: "] {
            if let Some(i) = paragraph.find(marker) {
                let rest = &paragraph[i + marker.len()..];
                let list = &rest[..rest.find(']').unwrap_or(rest.len())];
                for a in list.split(',') {
                    aliases.push((a.trim().to_string(), paragraph.clone()));
                }
            }
        }
    }
    out.extend(aliases);
    out
}

/// The fixed values an option's help lists (`Possible values:` or `[possible values: …]`).
fn possible_values(paragraph: &str) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(i) = paragraph.find("[possible values: ") {
        let rest = &paragraph[i + 18..];
        let list = &rest[..rest.find(']').unwrap_or(rest.len())];
        out.extend(list.split(',').map(|v| v.trim().to_string()));
    }
    if let Some(i) = paragraph.find("Possible values:") {
        for l in paragraph[i..].lines().skip(1) {
            let t = l.trim();
            let Some(v) = t.strip_prefix("- ") else {
                continue;
            };
            out.push(v.split(':').next().unwrap().trim().to_string());
        }
    }
    out
}

/// Checks a structid command against its help: the subcommand exists, every option is listed,
/// and values are among an option's fixed values. Returns the problems.
fn check_structid(args: &[String]) -> Vec<String> {
    let clean = |w: &str| {
        w.trim_matches(|c| c == '[' || c == ']' || c == '(' || c == ')')
            .to_string()
    };
    let args: Vec<String> = args
        .iter()
        .map(|a| clean(a))
        .filter(|a| !a.is_empty())
        .collect();
    let mut problems = Vec::new();
    let mut path: Vec<String> = Vec::new();
    let mut k = 0;
    loop {
        let subs = subcommands(&help(&path));
        let Some(next) = args.get(k) else { break };
        if subs.is_empty() || next.starts_with('-') {
            break;
        }
        // `silverbox|tanks` in a synopsis: every alternative must be a subcommand.
        let alternatives: Vec<&str> = next.split('|').collect();
        let unknown: Vec<&&str> = alternatives
            .iter()
            .filter(|a| !subs.contains(&a.to_string()))
            .collect();
        if !unknown.is_empty() {
            if path.is_empty() || alternatives.len() > 1 {
                problems.push(format!(
                    "`structid {}` has no subcommand `{}` (it has {})",
                    path.join(" "),
                    unknown
                        .iter()
                        .map(|u| u.to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    subs.join(", ")
                ));
                return problems;
            }
            break;
        }
        path.push(alternatives[0].to_string());
        k += 1;
    }
    let h = help(&path);
    let opts = options(&h);
    let global = options(&help(&[]));
    for (j, a) in args.iter().enumerate().skip(k) {
        if !(a.starts_with("--") || (a.len() == 2 && a.starts_with('-') && a != "--")) {
            continue;
        }
        let name = a.split('=').next().unwrap();
        let Some(paragraph) = opts.get(name).or_else(|| global.get(name)) else {
            problems.push(format!(
                "`structid {}` has no option `{name}` (see `structid {} --help`)",
                path.join(" "),
                path.join(" ")
            ));
            continue;
        };
        let value = match a.split_once('=') {
            Some((_, v)) => Some(v.to_string()),
            None => args.get(j + 1).filter(|v| !v.starts_with('-')).cloned(),
        };
        let fixed = possible_values(paragraph);
        if let (Some(value), false) = (value, fixed.is_empty()) {
            for v in value.split('|') {
                // Placeholders (`B`, `N`) and variables are not values.
                let literal = v
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c == '-' || c.is_ascii_digit())
                    && v.chars().any(|c| c.is_ascii_lowercase());
                if literal && !fixed.iter().any(|f| f == v) {
                    problems.push(format!(
                        "`structid {} {name}` takes {}, not `{v}`",
                        path.join(" "),
                        fixed.join(", ")
                    ));
                }
            }
        }
    }
    problems
}

/// A package of the workspace: its directory and the targets its file tree and manifest give.
struct Package {
    examples: Vec<String>,
    tests: Vec<String>,
    benches: Vec<String>,
    dir: PathBuf,
}

/// The workspace's packages by name: the root package and `crates/*`.
fn packages() -> &'static BTreeMap<String, Package> {
    static PACKAGES: OnceLock<BTreeMap<String, Package>> = OnceLock::new();
    PACKAGES.get_or_init(|| {
        let root = root();
        let mut dirs = vec![root.clone()];
        for e in std::fs::read_dir(root.join("crates")).unwrap() {
            dirs.push(e.unwrap().path());
        }
        let mut out = BTreeMap::new();
        for dir in dirs {
            let Ok(manifest) = std::fs::read_to_string(dir.join("Cargo.toml")) else {
                continue;
            };
            let mut section = String::new();
            let mut name = None;
            let mut declared: Vec<(String, String)> = Vec::new();
            for l in manifest.lines() {
                let t = l.trim();
                if t.starts_with('[') {
                    section = t.to_string();
                } else if let Some(v) = t.strip_prefix("name") {
                    let v = v
                        .trim_start()
                        .trim_start_matches('=')
                        .trim()
                        .trim_matches('"');
                    if section == "[package]" {
                        name = Some(v.to_string());
                    } else {
                        declared.push((section.clone(), v.to_string()));
                    }
                }
            }
            let Some(name) = name else { continue };
            let targets = |folder: &str, kind: &str| {
                let mut t: Vec<String> = std::fs::read_dir(dir.join(folder))
                    .into_iter()
                    .flatten()
                    .map(|e| e.unwrap().path())
                    .filter_map(|p| {
                        if p.extension().is_some_and(|x| x == "rs") {
                            Some(p.file_stem()?.to_string_lossy().into_owned())
                        } else if p.join("main.rs").is_file() {
                            Some(p.file_name()?.to_string_lossy().into_owned())
                        } else {
                            None
                        }
                    })
                    .collect();
                t.extend(
                    declared
                        .iter()
                        .filter(|(s, _)| s == &format!("[[{kind}]]"))
                        .map(|(_, n)| n.clone()),
                );
                t
            };
            out.insert(
                name,
                Package {
                    examples: targets("examples", "example"),
                    tests: targets("tests", "test"),
                    benches: targets("benches", "bench"),
                    dir: dir.clone(),
                },
            );
        }
        out
    })
}

/// Checks a cargo command: the package and the example, test or bench target it names, and
/// test-name filters. Returns the problems.
fn check_cargo(args: &[String]) -> Vec<String> {
    let packages = packages();
    let mut problems = Vec::new();
    let dash = args.iter().position(|a| a == "--").unwrap_or(args.len());
    let own = &args[..dash];
    let value = |flags: &[&str]| {
        own.windows(2)
            .find(|w| flags.contains(&w[0].as_str()))
            .map(|w| w[1].clone())
    };
    let workspace = own.iter().any(|a| a == "--workspace");
    let name = value(&["-p", "--package"]).unwrap_or_else(|| "structid".into());
    let Some(pkg) = packages.get(&name) else {
        return vec![format!(
            "the workspace has no package `{name}` (it has {})",
            packages.keys().cloned().collect::<Vec<_>>().join(", ")
        )];
    };
    let candidates: Vec<&Package> = if workspace {
        packages.values().collect()
    } else {
        vec![pkg]
    };
    for (flag, what) in [
        ("--example", "example"),
        ("--test", "test"),
        ("--bench", "bench"),
    ] {
        if let Some(target) = value(&[flag]) {
            let found = candidates.iter().any(|p| {
                let list = match what {
                    "example" => &p.examples,
                    "test" => &p.tests,
                    _ => &p.benches,
                };
                list.contains(&target)
            });
            if !found {
                problems.push(format!("package `{name}` has no {what} `{target}`"));
            }
        }
    }
    // A test-name filter of `cargo test` / `cargo bench` must match some function.
    if matches!(args.get(1).map(String::as_str), Some("test" | "bench")) {
        let mut k = 2;
        while k < own.len() {
            let a = &own[k];
            if a.starts_with('-') {
                if matches!(
                    a.as_str(),
                    "-p" | "--package"
                        | "--test"
                        | "--bench"
                        | "--example"
                        | "--features"
                        | "-F"
                        | "--target-dir"
                        | "-j"
                        | "--jobs"
                ) {
                    k += 1;
                }
            } else {
                let found = candidates
                    .iter()
                    .any(|p| tree_contains(&p.dir, &format!("fn {a}")));
                if !found {
                    problems.push(format!("no test function of `{name}` is named like `{a}`"));
                }
            }
            k += 1;
        }
    }
    problems
}

/// Whether a Rust file below `dir` (not below `target`) holds `needle` as the start of a
/// word sequence.
fn tree_contains(dir: &Path, needle: &str) -> bool {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return false;
    };
    entries.flatten().any(|e| {
        let p = e.path();
        if p.is_dir() {
            !matches!(
                p.file_name().and_then(|n| n.to_str()),
                Some("target" | ".git" | "crates")
            ) && tree_contains(&p, needle)
        } else {
            p.extension().is_some_and(|x| x == "rs")
                && std::fs::read_to_string(&p).is_ok_and(|t| t.contains(needle))
        }
    })
}

/// Checks another tool's command: the `./paths` it names exist in the repository.
fn check_other(args: &[String]) -> Vec<String> {
    args.iter()
        .filter(|a| a.starts_with("./"))
        .filter(|a| !root().join(a).exists())
        .map(|a| format!("`{a}` does not exist in the repository"))
        .collect()
}

/// The static checks of every simple command of a line. Returns the problems.
fn check_statically(cmd: &Cmd, vars: &HashMap<String, String>) -> Vec<String> {
    let synopsis = is_synopsis(&cmd.text);
    let mut problems = Vec::new();
    let ws = if synopsis {
        // Usage notation is not shell syntax: `a|b` is no pipe.
        cmd.text
            .split_whitespace()
            .take_while(|w| !w.starts_with('#'))
            .map(|w| Word::Arg(w.to_string()))
            .collect()
    } else {
        words(&cmd.text, vars)
    };
    for s in simple_commands(&ws) {
        let Some(program) = s.args.first().map(String::as_str) else {
            continue;
        };
        if program == "cargo" {
            problems.extend(check_cargo(&s.args));
            if let Some(args) = structid_cli_args(&s.args) {
                problems.extend(check_structid(&args));
            }
        } else if is_structid(program) {
            problems.extend(check_structid(&s.args[1..]));
        } else if !is_shell_utility(program) {
            problems.extend(check_other(&s.args));
        }
    }
    problems
}

// ---------------------------------------------------------------------------------------------
// Running commands
// ---------------------------------------------------------------------------------------------

/// A page's working directory: a copy of `examples/` and `structid` on the PATH.
struct Workdir {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
    bin: PathBuf,
}

impl Workdir {
    fn new() -> Self {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("work");
        let bin = tmp.path().join("bin");
        std::fs::create_dir_all(&bin).unwrap();
        copy_dir(&root().join("examples"), &dir.join("examples"));
        #[cfg(unix)]
        std::os::unix::fs::symlink(BIN, bin.join("structid")).unwrap();
        Workdir {
            _tmp: tmp,
            dir,
            bin,
        }
    }

    /// Runs `script` with bash in the directory; returns (success, stdout, stderr).
    fn bash(&self, script: &str, env: &[(String, String)]) -> (bool, String, String) {
        let path = format!(
            "{}:{}",
            self.bin.display(),
            std::env::var("PATH").unwrap_or_default()
        );
        let out = Command::new("bash")
            .arg("-c")
            .arg(format!("set -eo pipefail\n{script}"))
            .current_dir(&self.dir)
            .env("PATH", path)
            .envs(env.iter().map(|(k, v)| (k, v)))
            .output()
            .expect("bash runs");
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    }

    /// Runs structid with `args` in the directory, which must succeed; its stdout.
    fn structid(&self, args: &[&str]) -> String {
        let out = Command::new(BIN)
            .args(args)
            .current_dir(&self.dir)
            .output()
            .expect("the binary runs");
        assert!(
            out.status.success(),
            "fixture: structid {} failed:\n{}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// The files a structid command reads (the values of its input options), by their spelling.
fn inputs(args: &[String]) -> Vec<String> {
    const INPUT: [&str; 13] = [
        "--model",
        "-m",
        "--data",
        "-d",
        "--input",
        "--validate",
        "--validation-data",
        "--file",
        "-f",
        "--config",
        "-c",
        "--estimate",
        "-e",
    ];
    let mut out = Vec::new();
    for (j, a) in args.iter().enumerate() {
        if let Some((flag, v)) = a.split_once('=')
            && INPUT.contains(&flag)
        {
            out.push(v.to_string());
        } else if INPUT.contains(&a.as_str())
            && let Some(v) = args.get(j + 1)
        {
            out.push(v.clone());
        }
    }
    out.retain(|p| !p.contains('$') && !p.contains('*'));
    out
}

/// The shipped model every record of the fixtures comes from: y = G·N(u) + e with
/// N(z) = tanh(2z), signals `u` and `y`.
const FIXTURE_MODEL: &str = "examples/models/hammerstein.toml";

/// Makes the input file `name` that a command reads and no command before it wrote. Returns
/// false when there is no fixture of that name.
fn make_fixture(w: &Workdir, name: &str) -> bool {
    let fx = |f: &str| format!(".fixtures/{f}");
    std::fs::create_dir_all(w.dir.join(".fixtures")).unwrap();
    // Inputs: random levels, uniform in [−2, 2], a new level every sample.
    let input = |out: &str, length: usize, seed: u32| {
        w.structid(&[
            "input",
            "steps",
            "--length",
            &length.to_string(),
            "--amplitude",
            "2",
            "--hold",
            "1,1",
            "--seed",
            &seed.to_string(),
            "--out",
            out,
        ]);
    };
    // Records of the fixture model, with noise of standard deviation 0.05.
    let record = |out: &str, length: usize, seed: u32| {
        let u = fx(&format!("u-{seed}.csv"));
        input(&u, length, 100 + seed);
        w.structid(&[
            "simulate",
            "--model",
            FIXTURE_MODEL,
            "--input",
            &u,
            "--out",
            out,
            "--noise-std",
            "0.05",
            "--seed",
            &seed.to_string(),
        ]);
    };
    match name {
        "u.csv" => input(name, 1000, 1),
        "u_val.csv" => input(name, 500, 2),
        "u2.csv" => input(name, 500, 3),
        "u_test.csv" => input(name, 500, 4),
        "est.csv" => record(name, 1000, 1),
        "val.csv" => record(name, 500, 2),
        "test.csv" => record(name, 500, 3),
        // A model file to identify: the fixture model itself.
        "m.toml" => {
            std::fs::copy(w.dir.join(FIXTURE_MODEL), w.dir.join(name)).unwrap();
        }
        // A start for `refine --joint`: the fixture model with a linear guess of its map.
        "start.toml" => {
            let text = std::fs::read_to_string(w.dir.join(FIXTURE_MODEL)).unwrap();
            assert!(text.contains("truth = \"tanh(2*z0)\""));
            let start = text.replace("truth = \"tanh(2*z0)\"", "truth = \"1.5*z0\"");
            std::fs::write(w.dir.join(name), start).unwrap();
        }
        // A record of the fixture model as a MAT-file, u and y as the variables V1 and V2.
        "silverbox.mat" | "rec.mat" => {
            let csv = fx(&format!("{name}.csv"));
            record(&csv, 400, 5);
            let (u, y) = (
                csv_column(&w.dir.join(&csv), "u"),
                csv_column(&w.dir.join(&csv), "y"),
            );
            let vars = if name == "silverbox.mat" {
                vec![
                    mat_variable("V1", u.len(), 1, &u),
                    mat_variable("V2", y.len(), 1, &y),
                ]
            } else {
                // One matrix variable `data`, samples in rows, columns u and y.
                let both: Vec<f64> = u.iter().chain(&y).copied().collect();
                vec![mat_variable("data", u.len(), 2, &both)]
            };
            std::fs::write(w.dir.join(name), mat_file(&vars)).unwrap();
        }
        // A log with `;` between its fields: a time and two channels.
        "log.txt" => {
            let mut t = String::from("time;V1;V2\n");
            for k in 0..200 {
                let v1 = (0.1 * k as f64).sin();
                writeln!(t, "{};{v1};{}", k as f64 * 0.01, v1.tanh()).unwrap();
            }
            std::fs::write(w.dir.join(name), t).unwrap();
        }
        // A scatter of a static map w = atan(3z) in noise (std 0.02), z slow against the
        // sampling: what `structid static` rates as static.
        "record.csv" => {
            let model = fx("static.toml");
            std::fs::write(
                w.dir.join(&model),
                "[lft]\nA = []\nDyw = [[1.0]]\nDye = [[1.0]]\nDzu = [[1.0]]\n\
                 [signals]\nu = [\"z\"]\ny = [\"w\"]\n\
                 [[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\ntruth = \"atan(3*z0)\"\n",
            )
            .unwrap();
            let z = fx("z.csv");
            w.structid(&[
                "input",
                "multisine",
                "--length",
                "2000",
                "--band",
                "0.001,0.01",
                "--amplitude",
                "1.5",
                "--name",
                "z",
                "--seed",
                "4",
                "--out",
                &z,
            ]);
            w.structid(&[
                "simulate",
                "--model",
                &model,
                "--input",
                &z,
                "--noise-std",
                "0.02",
                "--seed",
                "4",
                "--out",
                name,
            ]);
        }
        // A sweep of 8 small cases (2 β values × 4 seeds) on records of the fixture model.
        "sweep.toml" => {
            input("u_sweep.csv", 300, 5);
            std::fs::write(
                w.dir.join(name),
                format!(
                    "[[experiment]]\nname = \"hammerstein\"\nmodel = \"{FIXTURE_MODEL}\"\n\
                     [experiment.simulate]\ninput = \"u_sweep.csv\"\nnoise_std = 0.05\nseeds = 4\n\n\
                     [[dispersion]]\nname = \"gaussian\"\nkind = \"gaussian\"\nsigma = 0.3\n\
                     beta = [0.001, 0.01]\n"
                ),
            )
            .unwrap();
        }
        _ => return false,
    }
    true
}

/// A column of a CSV file with a header row.
fn csv_column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let j = header
        .iter()
        .position(|h| h.trim() == name)
        .unwrap_or_else(|| panic!("{} has no column `{name}`: {header:?}", path.display()));
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').nth(j).unwrap().trim().parse().unwrap())
        .collect()
}

/// The data rows of a CSV file.
fn csv_rows(path: &Path) -> Result<usize, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    Ok(text
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .count())
}

/// An uncompressed MAT v5 element, padded to 8 bytes.
fn mat_element(ty: u32, data: &[u8]) -> Vec<u8> {
    let mut out = ty.to_le_bytes().to_vec();
    out.extend((data.len() as u32).to_le_bytes());
    out.extend(data);
    while !out.len().is_multiple_of(8) {
        out.push(0);
    }
    out
}

/// A double matrix variable (values in column-major order).
fn mat_variable(name: &str, rows: usize, cols: usize, values: &[f64]) -> Vec<u8> {
    let mut body = mat_element(6, &[6, 0, 0, 0, 0, 0, 0, 0]);
    let mut dims = (rows as u32).to_le_bytes().to_vec();
    dims.extend((cols as u32).to_le_bytes());
    body.extend(mat_element(5, &dims));
    body.extend(mat_element(1, name.as_bytes()));
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    body.extend(mat_element(9, &data));
    mat_element(14, &body)
}

fn mat_file(vars: &[Vec<u8>]) -> Vec<u8> {
    let mut out = format!("{:<116}", "MATLAB 5.0 MAT-file, written by docs_blocks").into_bytes();
    out.extend([0; 8]);
    out.extend([0, 1]);
    out.extend(b"IM");
    for v in vars {
        out.extend(v);
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Stated results
// ---------------------------------------------------------------------------------------------

/// What a command printed and left behind, with the comments the text gives it.
struct Ran<'a> {
    dir: &'a Path,
    stdout: &'a str,
    comments: &'a [String],
}

/// A result the text states for a command: on `page`, for the command containing `command`.
struct Stated {
    page: &'static str,
    command: &'static str,
    check: fn(&Ran) -> Result<(), String>,
}

/// The number after `label` in `text` (e.g. "simulation RMS 5.25e-2").
fn number_after(text: &str, label: &str) -> Result<f64, String> {
    let i = text
        .find(label)
        .ok_or_else(|| format!("no `{label}` in the output:\n{text}"))?;
    let rest = text[i + label.len()..].trim_start();
    let n: String = rest
        .chars()
        .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | 'e' | '+'))
        .collect();
    n.parse()
        .map_err(|_| format!("`{label}` is not followed by a number in:\n{text}"))
}

fn files_exist(dir: &Path, files: &[&str]) -> Result<(), String> {
    match files.iter().find(|f| !dir.join(f).is_file()) {
        Some(f) => Err(format!("the text says it writes `{f}`, which is not there")),
        None => Ok(()),
    }
}

/// The comment line after a command that begins with `prefix`, which the output must hold
/// (outputs that do not depend on the fixtures' numbers).
fn stated_line_printed(r: &Ran, prefix: &str) -> Result<(), String> {
    let line = r
        .comments
        .iter()
        .find(|c| c.starts_with(prefix))
        .ok_or_else(|| format!("the text gives no `{prefix}` line"))?;
    if r.stdout.lines().any(|l| l.trim() == line.trim()) {
        Ok(())
    } else {
        Err(format!(
            "the text says it prints\n  {line}\nbut it printed\n{}",
            r.stdout
        ))
    }
}

const STATED: &[Stated] = &[
    // "writes into structid-demo/spray/: fig4.svg, summary.json, model.toml and data.csv"
    Stated {
        page: "README.md",
        command: "demo spray",
        check: |r| {
            files_exist(
                &r.dir.join("structid-demo/spray"),
                &["fig4.svg", "summary.json", "model.toml", "data.csv"],
            )
        },
    },
    Stated {
        page: "docs/cli.md",
        command: "structid demo spray",
        check: |r| {
            files_exist(
                &r.dir.join("structid-demo/spray"),
                &["fig4.svg", "summary.json", "model.toml", "data.csv"],
            )
        },
    },
    // "identified 1 block(s) from 1000 samples with β = 1.33e-5 …, RMS error vs truth …"
    Stated {
        page: "README.md",
        command: "structid identify --model first.toml",
        check: |r| {
            if !r.stdout.contains("identified 1 block(s) from 1000 samples") {
                return Err(format!("not 1 block from 1000 samples:\n{}", r.stdout));
            }
            let beta = number_after(r.stdout, "with β =")?;
            let rms = number_after(r.stdout, "RMS error vs truth")?;
            if !(1e-6..1e-4).contains(&beta) || rms > 0.05 {
                return Err(format!(
                    "β = {beta} (the text: 1.33e-5) and RMS error {rms} against the truth"
                ));
            }
            Ok(())
        },
    },
    // "output y: simulation RMS 5.2513e-2, fit 96.01 %" (noise of standard deviation 0.05)
    Stated {
        page: "README.md",
        command: "structid validate --estimate fit/estimate.json",
        check: |r| {
            let rms = number_after(r.stdout, "simulation RMS")?;
            let fit = number_after(r.stdout, ", fit")?;
            if (0.04..0.07).contains(&rms) && fit > 90.0 {
                Ok(())
            } else {
                Err(format!(
                    "simulation RMS {rms} and fit {fit} % (the text: 5.25e-2, 96 %)"
                ))
            }
        },
    },
    // "`wh/divisions.json` lists every division with its score"
    Stated {
        page: "README.md",
        command: "structid wiener-hammerstein",
        check: |r| files_exist(r.dir, &["wh/divisions.json", "wh/model.toml"]),
    },
    // "36 cases"
    Stated {
        page: "docs/cli.md",
        command: "structid compare --config examples/compare/paper.toml",
        check: |r| match csv_rows(&r.dir.join("runs/paper/results.csv"))? {
            36 => Ok(()),
            n => Err(format!("{n} cases in results.csv, the text says 36")),
        },
    },
    // The merge gathers every shard's cases: the 8 of the sweep the array ran.
    Stated {
        page: "docs/cli.md",
        command: "structid compare merge",
        check: |r| match csv_rows(&r.dir.join("runs/all/results.csv"))? {
            8 => Ok(()),
            n => Err(format!(
                "{n} cases in the merged results.csv, the sweep has 8"
            )),
        },
    },
    // "validate --model …: the true maps"
    Stated {
        page: "docs/cli.md",
        command: "--out validation-truth",
        check: |r| {
            let text = std::fs::read_to_string(r.dir.join("validation-truth/validation.json"))
                .map_err(|e| e.to_string())?;
            let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
            match v["maps"].as_str() {
                Some("truth") => Ok(()),
                other => Err(format!(
                    "validation.json has maps = {other:?}, not \"truth\""
                )),
            }
        },
    },
    // The static map of the fixture is rated static, on its 2000 samples.
    Stated {
        page: "docs/cli.md",
        command: "structid static --data record.csv",
        check: |r| {
            if !r.stdout.contains("from 2000 samples") {
                return Err(format!("not 2000 samples:\n{}", r.stdout));
            }
            stated_line_printed(r, "verdict:")
        },
    },
    // The multisine's summary line, printed as the text gives it.
    Stated {
        page: "docs/cli.md",
        command: "structid input multisine",
        check: |r| stated_line_printed(r, "multisine:"),
    },
    // `discover` writes report.md (and, when it finds an effect, augmented.toml).
    Stated {
        page: "docs/cli.md",
        command: "structid discover --model nominal.toml",
        check: |r| files_exist(r.dir, &["found/report.md", "found/report.json"]),
    },
    // `--range 100..` keeps the rows from 100 on, as columns u and y.
    Stated {
        page: "docs/files.md",
        command: "--range 100..",
        check: |r| {
            let rows = csv_rows(&r.dir.join("rec.csv"))?;
            let header =
                std::fs::read_to_string(r.dir.join("rec.csv")).map_err(|e| e.to_string())?;
            if rows == 300 && header.starts_with("u,y") {
                Ok(())
            } else {
                Err(format!(
                    "rec.csv has {rows} rows (400 − 100 expected) and header {:?}",
                    header.lines().next()
                ))
            }
        },
    },
];

// ---------------------------------------------------------------------------------------------
// Model files
// ---------------------------------------------------------------------------------------------

fn has_section(text: &str, section: &str) -> bool {
    text.lines().any(|l| l.trim_start().starts_with(section))
}

/// A fragment of a model file completed by the sections it lacks: `[signals]` (`u`, `y`); an
/// `[lft]` of two states with one declared injection point (w) and one z row, for a
/// `[discover]` section alone; and, for a `[linear]` structure other than `lti`, its block
/// with a small linear truth.
fn complete_fragment(text: &str) -> String {
    let mut out = text.to_string();
    if !has_section(text, "[lft]") && !has_section(text, "[linear]") {
        out.push_str(
            "\n[lft]\nA = [[0.5, 0.1], [0.0, 0.4]]\nBu = [[1.0], [0.0]]\nBw = [[0.0], [1.0]]\n\
             Cy = [[1.0, 0.0]]\nDye = [[1.0]]\nCz = [[1.0, 0.0]]\n",
        );
    }
    if !has_section(text, "[signals]") {
        out.push_str("\n[signals]\nu = [\"u\"]\ny = [\"y\"]\n");
    }
    if has_section(text, "[linear]")
        && !has_section(text, "[[nonlinearity]]")
        && !text.contains("\"lti\"")
    {
        out.push_str(
            "\n[[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\ntruth = \"0.1*z0\"\n",
        );
    }
    out
}

/// Loads a toml block: returns what it was, or the problem.
fn load_toml(w: &Workdir, block: &Block) -> Result<String, String> {
    let text = block.body.join("\n") + "\n";
    if has_section(&text, "[[experiment]]") {
        structid_io::SweepFile::parse(&text, Some(&w.dir))
            .map_err(|e| format!("the sweep configuration does not load: {e}"))?;
        return Ok("sweep configuration, parsed".into());
    }
    let (what, model_text) = if has_section(&text, "[signals]") {
        ("model file", text.clone())
    } else {
        ("model-file fragment, completed", complete_fragment(&text))
    };
    let model = structid_io::ModelFile::parse(&model_text, Some(&w.dir))
        .map_err(|e| format!("the {what} does not load: {e}\n--- as loaded ---\n{model_text}"))?;
    // The command-line tool reads it too: simulate it on a short input when its maps are given.
    if model
        .blocks
        .iter()
        .all(|b| b.truth.is_some() || b.operator.is_some())
    {
        let name = format!(".fixtures/block-{}.toml", block.line);
        std::fs::create_dir_all(w.dir.join(".fixtures")).unwrap();
        std::fs::write(w.dir.join(&name), &model_text).unwrap();
        let mut csv = model.signals.u.join(",") + "\n";
        for k in 0..50 {
            let v = (0.3 * k as f64).sin();
            let row: Vec<String> = model.signals.u.iter().map(|_| v.to_string()).collect();
            csv.push_str(&(row.join(",") + "\n"));
        }
        let input = format!(".fixtures/block-{}-u.csv", block.line);
        std::fs::write(w.dir.join(&input), csv).unwrap();
        let out = format!(".fixtures/block-{}-sim.csv", block.line);
        let script = format!("structid simulate --model {name} --input {input} --out {out}");
        let (ok, _, err) = w.bash(&script, &[]);
        if !ok {
            return Err(format!(
                "`structid simulate` does not take the {what}: {err}"
            ));
        }
        return Ok(format!("{what}, loaded and simulated"));
    }
    Ok(format!("{what}, loaded"))
}

/// The file name the text before a block gives it ("Save this as `first.toml`").
fn saved_as(block: &Block) -> Option<String> {
    let i = block.before.find("as `")?;
    let rest = &block.before[i + 4..];
    let name = &rest[..rest.find('`')?];
    (!name.contains(' ')).then(|| name.to_string())
}

// ---------------------------------------------------------------------------------------------
// A page
// ---------------------------------------------------------------------------------------------

const SHELL: [&str; 4] = ["sh", "bash", "console", "shell"];

/// Whether a block holds commands: a shell block, or a text block whose first command is
/// `structid`, `cargo` or a path to the binary.
fn is_command_block(block: &Block) -> bool {
    if SHELL.contains(&block.lang.as_str()) {
        return true;
    }
    if block.lang != "text" {
        return false;
    }
    let Some(first) = logical_commands(block).into_iter().next() else {
        return false;
    };
    let vars = HashMap::new();
    let simple = simple_commands(&words(&first.text, &vars));
    simple
        .first()
        .and_then(|s| s.args.first())
        .is_some_and(|p| p == "cargo" || is_structid(p))
}

/// `#SBATCH --array=A-B` and `--cpus-per-task=N` of a batch script.
fn batch_array(block: &Block) -> Option<(Vec<usize>, usize)> {
    let sbatch: Vec<&str> = block
        .body
        .iter()
        .filter_map(|l| l.trim().strip_prefix("#SBATCH"))
        .collect();
    let value = |key: &str| {
        sbatch.iter().find_map(|l| {
            let l = l.trim();
            l.strip_prefix(key)
                .map(|v| v.split_whitespace().next().unwrap_or("").to_string())
        })
    };
    let array = value("--array=")?;
    let (a, b) = array.split_once('-')?;
    let cpus = value("--cpus-per-task=")
        .and_then(|c| c.parse().ok())
        .unwrap_or(1);
    Some(((a.parse().ok()?..=b.parse().ok()?).collect(), cpus))
}

/// Runs or checks every block of `page`; panics with every problem found, naming the block.
fn run_page(page: &str) {
    let started = Instant::now();
    let w = Workdir::new();
    let mut problems: Vec<String> = Vec::new();
    let mut report = String::new();
    let mut stated_used = vec![false; STATED.len()];
    for block in blocks(page) {
        let at = block.at();
        match block.lang.as_str() {
            "rust" => writeln!(report, "{at} rust: doc test (src/readme_doctests.rs)").unwrap(),
            "python" => {
                writeln!(report, "{at} python: pytest (python/tests/test_readme.py)").unwrap()
            }
            "toml" => match load_toml(&w, &block) {
                Ok(what) => {
                    writeln!(report, "{at} toml: {what}").unwrap();
                    if let Some(name) = saved_as(&block) {
                        std::fs::write(w.dir.join(&name), block.body.join("\n") + "\n").unwrap();
                        writeln!(report, "{at}   saved as {name}").unwrap();
                    }
                }
                Err(e) => problems.push(format!("{at} (toml): {e}")),
            },
            _ if is_command_block(&block) => {
                run_commands(&w, &block, &mut problems, &mut report, &mut stated_used)
            }
            "text" => writeln!(
                report,
                "{at} text: no commands (formulas, messages): nothing to run"
            )
            .unwrap(),
            other => problems.push(format!(
                "{at}: a block tagged `{other}`, which this test does not know how to run; tag it \
                 (sh, text, toml, rust, python) and teach docs_blocks.rs"
            )),
        }
    }
    for (s, used) in STATED.iter().zip(&stated_used) {
        if s.page == page && !used {
            problems.push(format!(
                "{page}: no command contains `{}` any more: update STATED in docs_blocks.rs",
                s.command
            ));
        }
    }
    println!("{report}{page}: {:.1} s", started.elapsed().as_secs_f64());
    assert!(problems.is_empty(), "{page}:\n\n{}", problems.join("\n\n"));
}

fn run_commands(
    w: &Workdir,
    block: &Block,
    problems: &mut Vec<String>,
    report: &mut String,
    stated_used: &mut [bool],
) {
    let mut vars: HashMap<String, String> = HashMap::new();
    let mut assignments: Vec<String> = Vec::new();
    let mut written: Vec<String> = Vec::new();
    let array = batch_array(block);
    let cmds = logical_commands(block);
    if cmds.is_empty() {
        problems.push(format!("{}: a shell block without commands", block.at()));
    }
    for cmd in cmds {
        let at = format!("{}:{}", block.page, cmd.line);
        for p in check_statically(&cmd, &vars) {
            problems.push(format!("{at}: `{}`: {p}", cmd.text));
        }
        match plan(&cmd, &vars, &written) {
            Plan::Assign => {
                for s in simple_commands(&words(&cmd.text, &vars)) {
                    for (k, v) in s.assignments {
                        vars.insert(k, v);
                    }
                }
                assignments.push(cmd.text.clone());
            }
            Plan::Static(reason) => {
                writeln!(report, "{at} checked statically ({reason}): {}", cmd.text).unwrap();
                written.extend(writes(&cmd, &vars));
            }
            Plan::Run(text) => {
                let simple = simple_commands(&words(&text, &vars));
                let mut missing = Vec::new();
                for s in simple
                    .iter()
                    .filter(|s| s.args.first().is_some_and(|p| is_structid(p)))
                {
                    for input in inputs(&s.args) {
                        if !w.dir.join(&input).exists() && !make_fixture(w, &input) {
                            missing.push(input);
                        }
                    }
                }
                if !missing.is_empty() {
                    problems.push(format!(
                        "{at}: `{}` reads {}, which no command before it writes and for which \
                         docs_blocks.rs has no fixture",
                        cmd.text,
                        missing.join(", ")
                    ));
                    continue;
                }
                let script = format!("{}\n{text}", assignments.join("\n"));
                let runs: Vec<Vec<(String, String)>> = match &array {
                    Some((ids, cpus)) => ids
                        .iter()
                        .map(|i| {
                            vec![
                                ("SLURM_ARRAY_TASK_ID".to_string(), i.to_string()),
                                ("SLURM_CPUS_PER_TASK".to_string(), cpus.to_string()),
                            ]
                        })
                        .collect(),
                    None => vec![Vec::new()],
                };
                let t = Instant::now();
                let mut stdout = String::new();
                let mut failed = false;
                for env in &runs {
                    let (ok, out, err) = w.bash(&script, env);
                    stdout = out;
                    if !ok {
                        problems.push(format!(
                            "{at}: `{}` failed{}:\n--- stdout ---\n{stdout}--- stderr ---\n{err}",
                            cmd.text,
                            if env.is_empty() {
                                String::new()
                            } else {
                                format!(" with {env:?}")
                            }
                        ));
                        failed = true;
                        break;
                    }
                }
                writeln!(
                    report,
                    "{at} ran{} ({:.1} s): {}",
                    if runs.len() > 1 {
                        format!(" {} times (array)", runs.len())
                    } else {
                        String::new()
                    },
                    t.elapsed().as_secs_f64(),
                    cmd.text
                )
                .unwrap();
                for (k, s) in STATED.iter().enumerate() {
                    if s.page == block.page && cmd.text.contains(s.command) {
                        stated_used[k] = true;
                        if failed {
                            continue;
                        }
                        let ran = Ran {
                            dir: &w.dir,
                            stdout: &stdout,
                            comments: &cmd.comments,
                        };
                        if let Err(e) = (s.check)(&ran) {
                            problems.push(format!("{at}: `{}`: {e}", cmd.text));
                        }
                    }
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

#[test]
fn readme_blocks_run() {
    run_page("README.md");
}

#[test]
fn cli_blocks_run() {
    run_page("docs/cli.md");
}

#[test]
fn files_blocks_run() {
    run_page("docs/files.md");
}

#[test]
fn benchmarks_blocks_are_checked() {
    run_page("docs/benchmarks.md");
}

#[test]
fn concepts_blocks_are_checked() {
    run_page("docs/concepts.md");
}

#[test]
fn python_guide_blocks_are_checked() {
    run_page("docs/python.md");
}

/// Every page has a test above, every block a language this test handles, and the Rust and
/// Python blocks are run by the doc tests and pytest.
#[test]
fn every_block_is_covered() {
    let tested = [
        "README.md",
        "docs/cli.md",
        "docs/files.md",
        "docs/benchmarks.md",
        "docs/concepts.md",
        "docs/python.md",
    ];
    let root = root();
    let doctests = std::fs::read_to_string(root.join("src/readme_doctests.rs"))
        .expect("src/readme_doctests.rs holds the doc tests of the pages");
    let lib = std::fs::read_to_string(root.join("src/lib.rs")).unwrap();
    assert!(
        lib.contains("#[cfg(doctest)]\nmod readme_doctests;"),
        "src/lib.rs must declare `#[cfg(doctest)] mod readme_doctests;`"
    );
    let pytest = std::fs::read_to_string(root.join("python/tests/test_readme.py")).unwrap();
    let mut problems = Vec::new();
    for page in pages() {
        if !tested.contains(&page.as_str()) {
            problems.push(format!("{page} has no test in docs_blocks.rs: add one"));
        }
        if !doctests.contains(&format!("include_str!(\"../{page}\")")) {
            problems.push(format!(
                "{page} is not included in src/readme_doctests.rs: its Rust blocks would not run"
            ));
        }
        for b in blocks(&page) {
            if !matches!(
                b.lang.as_str(),
                "rust" | "python" | "toml" | "text" | "sh" | "bash" | "console" | "shell"
            ) {
                problems.push(format!(
                    "{}: a block tagged `{}`: give it a language this test runs (an untagged \
                     block is Rust to rustdoc)",
                    b.at(),
                    b.lang
                ));
            }
        }
    }
    for needle in ["README.md", "docs", "```python"] {
        if !pytest.contains(needle) {
            problems.push(format!(
                "python/tests/test_readme.py does not mention `{needle}`: it must run the python \
                 blocks of README.md and docs/*.md"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The parts of the classification that decide what runs.
#[test]
fn commands_are_classified_by_their_content() {
    let cmd = |text: &str| Cmd {
        line: 1,
        text: text.into(),
        comments: vec![],
    };
    let vars = HashMap::from([("S".to_string(), "target/release/structid".to_string())]);
    let none: Vec<String> = Vec::new();
    assert_eq!(
        plan(
            &cmd("structid identify --model m.toml --data d.csv --out r"),
            &vars,
            &none
        ),
        Plan::Run("structid identify --model m.toml --data d.csv --out r".into())
    );
    assert_eq!(
        plan(
            &cmd("cargo run --release -p structid-cli -- demo spray"),
            &vars,
            &none
        ),
        Plan::Run("structid demo spray".into())
    );
    assert!(matches!(
        plan(&cmd("cargo test --workspace --release"), &vars, &none),
        Plan::Static(_)
    ));
    assert!(matches!(
        plan(
            &cmd("structid identify --model M.toml [--beta B|auto]"),
            &vars,
            &none
        ),
        Plan::Static(_)
    ));
    assert!(matches!(
        plan(
            &cmd("$S data silverbox --file x.csv --split all --out sb"),
            &vars,
            &none
        ),
        Plan::Static(_)
    ));
    assert!(matches!(
        plan(
            &cmd("head -n 3 sb/estimation.csv > sb/fit.csv"),
            &vars,
            &["sb".into()]
        ),
        Plan::Static(_)
    ));
    assert!(matches!(
        plan(&cmd("pip install ./python"), &vars, &none),
        Plan::Static(_)
    ));
    assert_eq!(plan(&cmd("S=a; D=b"), &vars, &none), Plan::Assign);
    // The static checks find a missing option, a wrong value and a missing target.
    let args = |s: &str| s.split_whitespace().map(String::from).collect::<Vec<_>>();
    assert!(check_structid(&args("identify --model m.toml --no-such-option")).len() == 1);
    assert!(check_structid(&args("identify --selection nonsense")).len() == 1);
    assert!(check_structid(&args("identify [--selection ml|gcv|cv|validation]")).is_empty());
    assert!(check_structid(&args("no-such-command --x")).len() == 1);
    assert!(
        check_cargo(&args(
            "cargo run -p structid-benchmarks --example no_such_example"
        ))
        .len()
            == 1
    );
    assert!(check_cargo(&args("cargo test -p structid-joint --test joint_fit")).is_empty());
    assert!(check_cargo(&args("cargo test -p no-such-package")).len() == 1);
}
