//! Every recipe in README.md and the book (docs/src/*.md) is a test: each
//! ```` ```sh ```` block runs as it is written, through `bash -e`, in a
//! fresh directory laid out as a checkout (the repository's files, and
//! `../shared` beside it where the real data sets are), with this build's
//! `twindrive` first on the PATH. An HTML comment on the line above a block
//! says what it needs:
//!
//! - none: run as it is;
//! - `<!-- recipe: ci-runs-this -->`: the quick start, the install line and
//!   the test suite, not run here: each of its lines must be one that CI
//!   runs ([`ci_runs`]);
//! - `needs-demo`: `twindrive-out/` as `twindrive demo` writes it (the demo
//!   runs once, for every recipe that needs it);
//! - `ports P ...`: the loopback ports the recipe listens on: recipes that
//!   share one run one after another, and a port something else holds
//!   fails the recipe, saying so;
//! - `serves NAME`: the recipe's `twindrive NAME` serves a page until
//!   Ctrl-C: once it prints its address the test opens it, then interrupts
//!   the process (SIGINT, as Ctrl-C does) and the recipe carries on;
//! - `probe tls-router PORT CA`: while the recipe's router listens on PORT,
//!   a client that trusts CA but shows no certificate is refused.
//!
//! A recipe fails on a non-zero exit, on a process it leaves running, on a
//! colour code, a Rust source path or a panic in what it prints, and after
//! [`LIMIT_S`] (its processes killed); the failure names the block's file
//! and line. ```` ```toml ```` blocks are files a user saves: each parses
//! with the project's own reader, named by `<!-- toml: KIND [ARG][; saved
//! as NAME] -->` (a saved one is in every recipe's directory on its page);
//! ```` ```text ```` blocks are shown, not typed (synopses, output). Any
//! other block, or one of these without what it needs, fails.

mod common;

use std::collections::{BTreeSet, VecDeque};
use std::io::{Read, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Condvar, Mutex, OnceLock};
use std::time::{Duration, Instant};

use common::{repo, text};

/// How long a recipe may run before its processes are killed and it fails.
const LIMIT_S: f64 = 300.0;
/// How long a recipe's processes may outlive it (a `kill %1` takes a
/// moment).
const GRACE_S: f64 = 15.0;
/// Recipes run side by side (those on the same port one after another).
const WORKERS: usize = 3;

/// A fenced block of a markdown file.
#[derive(Debug, Clone)]
struct Block {
    /// Relative to the repository: `README.md`, `docs/src/NAME.md`.
    file: String,
    /// The line of its opening fence (1-based).
    line: usize,
    lang: String,
    /// The HTML comment on the line above it, without `<!--` and `-->`.
    marker: Option<String>,
    body: String,
}

impl Block {
    fn at(&self) -> String {
        format!("{}:{}", self.file, self.line)
    }
}

/// The fenced blocks of `text` (named `file`), or what is wrong with a
/// fence or a marker.
fn parse(file: &str, text: &str) -> Result<Vec<Block>, String> {
    let lines: Vec<&str> = text.lines().collect();
    let mut blocks = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let trimmed = lines[i].trim_start();
        let is_marker = |l: &str| {
            let l = l.trim();
            l.starts_with("<!-- recipe:") || l.starts_with("<!-- toml:")
        };
        if is_marker(lines[i])
            && !lines
                .get(i + 1)
                .is_some_and(|l| l.trim().starts_with("```"))
        {
            return Err(format!(
                "{file}:{}: a marker with no fenced block on the next line",
                i + 1
            ));
        }
        if let Some(lang) = trimmed.strip_prefix("```") {
            let indent = lines[i].len() - trimmed.len();
            let start = i;
            let marker = (i > 0)
                .then(|| lines[i - 1].trim())
                .and_then(|l| l.strip_prefix("<!--"))
                .and_then(|l| l.strip_suffix("-->"))
                .map(|l| l.trim().to_string());
            i += 1;
            let mut body = String::new();
            loop {
                let Some(l) = lines.get(i) else {
                    return Err(format!("{file}:{}: the block never ends", start + 1));
                };
                if l.trim() == "```" {
                    break;
                }
                body.push_str(l.get(indent.min(l.len())..).unwrap_or(l));
                body.push('\n');
                i += 1;
            }
            blocks.push(Block {
                file: file.to_string(),
                line: start + 1,
                lang: lang.trim().to_string(),
                marker,
                body,
            });
        }
        i += 1;
    }
    Ok(blocks)
}

/// The blocks of README.md and of every page of the book.
fn doc_blocks() -> Vec<Block> {
    let mut files = vec!["README.md".to_string()];
    let mut pages: Vec<String> = std::fs::read_dir(repo().join("docs/src"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/src/{n}"))
        .collect();
    pages.sort();
    files.extend(pages);
    let mut blocks = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(repo().join(&f)).unwrap();
        blocks.extend(parse(&f, &text).unwrap_or_else(|e| panic!("{e}")));
    }
    blocks
}

/// The items of a marker `KIND: a b; c` (or `,`-separated) when it is of
/// `kind`, each split into words.
fn items(marker: Option<&str>, kind: &str) -> Option<Vec<Vec<String>>> {
    let rest = marker?.strip_prefix(kind)?.strip_prefix(':')?;
    Some(
        rest.split([';', ','])
            .map(|item| item.split_whitespace().map(String::from).collect())
            .filter(|words: &Vec<String>| !words.is_empty())
            .collect(),
    )
}

/// A shell block to run, with what it needs.
#[derive(Debug, Clone, Default)]
struct Recipe {
    file: String,
    line: usize,
    body: String,
    needs_demo: bool,
    ports: Vec<u16>,
    serves: Option<String>,
    /// The TLS router's port and the CA file a client trusts.
    probe_tls: Option<(u16, String)>,
    /// Files saved from the page's TOML blocks: (name, content).
    files: Vec<(String, String)>,
}

impl Recipe {
    fn at(&self) -> String {
        format!("{}:{}", self.file, self.line)
    }
}

/// What a `sh` block is: run by CI already (`None`), or a recipe to run.
fn recipe(block: &Block, saved: &[(String, String, String)]) -> Result<Option<Recipe>, String> {
    let at = block.at();
    let Some(items) = items(block.marker.as_deref(), "recipe") else {
        if let Some(m) = &block.marker {
            return Err(format!("{at}: unknown marker `{m}` above a sh block"));
        }
        return Ok(Some(Recipe {
            file: block.file.clone(),
            line: block.line,
            body: block.body.clone(),
            files: page_files(&block.file, saved),
            ..Recipe::default()
        }));
    };
    let mut r = Recipe {
        file: block.file.clone(),
        line: block.line,
        body: block.body.clone(),
        files: page_files(&block.file, saved),
        ..Recipe::default()
    };
    for words in &items {
        let w: Vec<&str> = words.iter().map(String::as_str).collect();
        match w.as_slice() {
            ["ci-runs-this"] => {
                if items.len() > 1 {
                    return Err(format!("{at}: ci-runs-this goes alone"));
                }
                for command in commands(&block.body) {
                    ci_runs(&command).map_err(|e| {
                        format!("{at}: marked ci-runs-this, but `{command}`: {e}; run it here (drop the marker) or make it a line CI runs")
                    })?;
                }
                return Ok(None);
            }
            ["needs-demo"] => r.needs_demo = true,
            ["ports", ports @ ..] if !ports.is_empty() => {
                for p in ports {
                    r.ports.push(
                        p.parse()
                            .map_err(|_| format!("{at}: ports: `{p}` is not a port"))?,
                    );
                }
            }
            ["serves", name] => r.serves = Some(name.to_string()),
            ["probe", "tls-router", port, ca] => {
                let port = port
                    .parse()
                    .map_err(|_| format!("{at}: probe: `{port}` is not a port"))?;
                r.probe_tls = Some((port, ca.to_string()));
            }
            _ => {
                return Err(format!(
                    "{at}: unknown recipe item `{}` (known: ci-runs-this, needs-demo, ports P..., serves NAME, probe tls-router PORT CA)",
                    words.join(" ")
                ));
            }
        }
    }
    if let Some((port, _)) = r.probe_tls
        && !r.ports.contains(&port)
    {
        return Err(format!(
            "{at}: the probed port {port} is not among its ports"
        ));
    }
    Ok(Some(r))
}

/// The page's saved TOML files (`saved`: page, name, content).
fn page_files(page: &str, saved: &[(String, String, String)]) -> Vec<(String, String)> {
    saved
        .iter()
        .filter(|(p, _, _)| p == page)
        .map(|(_, n, c)| (n.clone(), c.clone()))
        .collect()
}

/// A block's commands: its lines without comments, continuation lines
/// joined.
fn commands(body: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    for line in body.lines() {
        let code = match line.find(" #") {
            Some(k) => &line[..k],
            None if line.trim_start().starts_with('#') => "",
            None => line,
        };
        let code = code.trim();
        if let Some(head) = code.strip_suffix('\\') {
            current.push_str(head.trim());
            current.push(' ');
            continue;
        }
        current.push_str(code);
        let command = current.split_whitespace().collect::<Vec<_>>().join(" ");
        if !command.is_empty() {
            out.push(command);
        }
        current.clear();
    }
    out
}

/// Whether CI runs `command` (a line of a block marked `ci-runs-this`),
/// and how.
fn ci_runs(command: &str) -> Result<(), String> {
    match command {
        // This test runs `twindrive demo` for the recipes that need its
        // outputs (tests/cli.rs runs it as well, from another directory).
        "cargo run --release -- demo" => Ok(()),
        "scripts/test.sh" => {
            let ci = std::fs::read_to_string(repo().join(".ci/run")).unwrap_or_default();
            if ci.lines().any(|l| l.trim() == "bash scripts/test.sh") {
                Ok(())
            } else {
                Err("`.ci/run` does not run it".into())
            }
        }
        // CI builds this package, the binary every recipe here runs.
        "cargo install --locked --path crates/twindrive" => {
            let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
            if manifest.ends_with("crates/twindrive") && repo().join("Cargo.lock").is_file() {
                Ok(())
            } else {
                Err("the binary these tests run is not built from crates/twindrive".into())
            }
        }
        _ => Err("CI does not run it".into()),
    }
}

/// The case study's robot's footprint radius (m), what `plan --freedom`
/// validates a freedom file's widths against.
fn case_study_footprint_m() -> f64 {
    twindrive_sim::Scenario::load(&repo().join("scenarios/wall_following.toml"))
        .unwrap()
        .robot
        .footprint_radius_m
}

/// Reads a TOML block as the command that takes it would; what is wrong.
fn check_toml(block: &Block) -> Result<Option<(String, String)>, String> {
    let at = block.at();
    let Some(items) = items(block.marker.as_deref(), "toml") else {
        return Err(format!(
            "{at}: a toml block needs a marker naming its reader (<!-- toml: freedom | goals | redundancy | scenario | ros-site SCENARIO.toml [; saved as NAME] -->)"
        ));
    };
    let mut saved = None;
    let mut kind: Option<Vec<String>> = None;
    for words in items {
        if let ["saved", "as", name] = words.iter().map(String::as_str).collect::<Vec<_>>()[..] {
            saved = Some((name.to_string(), block.body.clone()));
        } else if kind.is_none() {
            kind = Some(words);
        } else {
            return Err(format!("{at}: unknown toml item `{}`", words.join(" ")));
        }
    }
    let kind = kind.ok_or_else(|| format!("{at}: the toml marker names no reader"))?;
    let body = &block.body;
    let k: Vec<&str> = kind.iter().map(String::as_str).collect();
    match k.as_slice() {
        ["freedom"] => {
            let s: twindrive_mission::freedom::FreedomSettings =
                toml::from_str(body).map_err(|e| format!("{at}: freedom: {e}"))?;
            s.validate(case_study_footprint_m())
                .map_err(|e| format!("{at}: freedom: {e}"))?;
        }
        ["goals"] => {
            twindrive_mission::goals::Goals::parse(body)
                .map_err(|e| format!("{at}: goals: {e}"))?;
        }
        ["redundancy"] => {
            toml::from_str::<twindrive_mission::redundancy::RedundancyConfig>(body)
                .map_err(|e| format!("{at}: redundancy: {e}"))?;
        }
        ["scenario"] => {
            twindrive_sim::Scenario::from_toml(body, Path::new(&block.file))
                .map_err(|e| format!("{at}: scenario: {e}"))?;
        }
        ["ros-site", scenario] => {
            // The section added to a site file, read as `twindrive robot`
            // reads its --site.
            let base = std::fs::read_to_string(repo().join(scenario))
                .map_err(|e| format!("{at}: ros-site: {scenario}: {e}"))?;
            let dir = tempfile::tempdir().unwrap();
            let site = dir.path().join("site.toml");
            std::fs::write(&site, format!("{base}\n{body}")).unwrap();
            let scenario =
                twindrive_sim::Scenario::load(&site).map_err(|e| format!("{at}: ros-site: {e}"))?;
            let ros = twindrive_ops::robot::read_ros_section(&site)
                .map_err(|e| format!("{at}: ros-site: {e:#}"))?
                .ok_or_else(|| format!("{at}: ros-site: no [ros] section"))?;
            twindrive_agent::ros::RosBridge::new(ros, &scenario, 0.0)
                .map_err(|e| format!("{at}: ros-site: {e}"))?;
        }
        _ => {
            return Err(format!(
                "{at}: unknown toml reader `{}` (known: freedom, goals, redundancy, scenario, ros-site SCENARIO.toml)",
                kind.join(" ")
            ));
        }
    }
    Ok(saved)
}

/// The saved TOML files of every page: (page, name, content).
fn saved_files(blocks: &[Block]) -> Vec<(String, String, String)> {
    blocks
        .iter()
        .filter(|b| b.lang == "toml")
        .filter_map(|b| {
            check_toml(b)
                .ok()
                .flatten()
                .map(|(n, c)| (b.file.clone(), n, c))
        })
        .collect()
}

/// The recipes of `blocks` (and what is wrong with the others).
fn classify(blocks: &[Block]) -> (Vec<Recipe>, Vec<String>) {
    let saved = saved_files(blocks);
    let mut recipes = Vec::new();
    let mut wrong = Vec::new();
    for b in blocks {
        match b.lang.as_str() {
            "sh" => match recipe(b, &saved) {
                Ok(Some(r)) => recipes.push(r),
                Ok(None) => {}
                Err(e) => wrong.push(e),
            },
            "toml" => {
                if let Err(e) = check_toml(b) {
                    wrong.push(e);
                }
            }
            "text" => {
                if let Some(m) = &b.marker {
                    wrong.push(format!("{}: a marker `{m}` above a text block", b.at()));
                }
            }
            other => wrong.push(format!(
                "{}: a ```{other} block: recipes are ```sh (run by this test), files ```toml (parsed), the rest ```text (shown)",
                b.at()
            )),
        }
    }
    (recipes, wrong)
}

/// `twindrive-out/` as `twindrive demo` wrote it, made once per build.
fn demo() -> &'static Path {
    static DEMO: OnceLock<PathBuf> = OnceLock::new();
    DEMO.get_or_init(|| {
        common::shared_fixture("recipe-demo", |d| {
            let o = common::twindrive_in(&["demo"], d);
            assert!(
                o.status.success(),
                "twindrive demo failed: {}",
                text(&o.stderr)
            );
        })
        .join("twindrive-out")
    })
}

/// Whether something on 127.0.0.1 accepts connections on `port`.
fn listening(port: u16) -> bool {
    std::net::TcpStream::connect_timeout(
        &std::net::SocketAddr::from(([127, 0, 0, 1], port)),
        Duration::from_millis(200),
    )
    .is_ok()
}

/// The processes of process group `pgid`: (pid, command line).
fn group_members(pgid: u32) -> Vec<(u32, Vec<String>)> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in entries.flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
            continue;
        };
        // pid (comm) state ppid pgrp ...; comm may hold spaces.
        let Some(rest) = stat.rfind(')').map(|k| &stat[k + 1..]) else {
            continue;
        };
        let fields: Vec<&str> = rest.split_whitespace().collect();
        if fields.first() == Some(&"Z") || fields.get(2) != Some(&pgid.to_string().as_str()) {
            continue;
        }
        let cmdline = std::fs::read(e.path().join("cmdline")).unwrap_or_default();
        let args = cmdline
            .split(|&b| b == 0)
            .filter(|a| !a.is_empty())
            .map(|a| String::from_utf8_lossy(a).into_owned())
            .collect();
        out.push((pid, args));
    }
    out
}

/// A recipe's shell and everything it started, killed as a process group
/// when dropped.
struct Group(std::process::Child);

impl Drop for Group {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-KILL", "--", &format!("-{}", self.0.id())])
            .stderr(Stdio::null())
            .status();
        let _ = self.0.wait();
    }
}

/// The first `http://` address with a token in the whole lines of `out`.
fn served_address(out: &str) -> Option<String> {
    out[..out.rfind('\n')?]
        .split_whitespace()
        .find(|w| w.starts_with("http://") && w.contains("token="))
        .map(String::from)
}

/// GET `url` (`http://HOST:PORT/PATH`): its status line.
fn get(url: &str) -> Result<String, String> {
    let rest = url.strip_prefix("http://").ok_or("not http://")?;
    let (host, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
    let mut s = std::net::TcpStream::connect(host).map_err(|e| format!("{host}: {e}"))?;
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .map_err(|e| e.to_string())?;
    let mut response = Vec::new();
    let _ = s.read_to_end(&mut response);
    let response = text(&response);
    Ok(response.lines().next().unwrap_or("").to_string())
}

/// `scripts/forger.py capture` on `endpoint` for a second, trusting `ca`
/// and showing no certificate: its exit code (3: it could not connect) and
/// what it said.
fn capture_without_certificate(endpoint: &str, ca: &Path, file: &Path) -> (Option<i32>, String) {
    common::finish(
        common::Proc(
            Command::new(common::python())
                .arg(repo().join("scripts/forger.py"))
                .args(["capture", endpoint, "twindrive/rover/up"])
                .arg(file)
                .args(["--for", "1", "--ca"])
                .arg(ca)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        ),
        60.0,
    )
}

/// The last `n` lines of `s`.
fn tail(s: &str, n: usize) -> String {
    let lines: Vec<&str> = s.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// Runs `r` as written in a fresh checkout; what went wrong, naming its
/// file and line.
fn run(r: &Recipe) -> Result<(), String> {
    let fail = |what: String, err: &str| {
        Err(format!(
            "{}: {what}\n--- the block ---\n{}--- what it said on stderr (the end) ---\n{}\n",
            r.at(),
            r.body,
            tail(err, 40)
        ))
    };
    for &p in &r.ports {
        if listening(p) {
            return fail(
                format!("127.0.0.1:{p} is taken: the recipe listens there; stop what holds it"),
                "",
            );
        }
    }
    let tmp = tempfile::tempdir().unwrap();
    let checkout = tmp.path().join("twindrive");
    std::fs::create_dir(&checkout).unwrap();
    // What a user's checkout holds (hidden files, builds and outputs left
    // out), and the data sets beside it.
    for e in std::fs::read_dir(repo()).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !(name.starts_with('.') || name == "target" || name == "twindrive-out") {
            std::os::unix::fs::symlink(e.path(), checkout.join(&name)).unwrap();
        }
    }
    let shared = repo().join("../shared");
    if shared.is_dir() {
        std::os::unix::fs::symlink(shared.canonicalize().unwrap(), tmp.path().join("shared"))
            .unwrap();
    }
    if r.needs_demo {
        std::os::unix::fs::symlink(demo(), checkout.join("twindrive-out")).unwrap();
    }
    for (name, content) in &r.files {
        std::fs::write(checkout.join(name), content).unwrap();
    }
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_twindrive")).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let (out_log, err_log) = (tmp.path().join("stdout"), tmp.path().join("stderr"));
    let mut group = Group(
        Command::new("bash")
            .args(["-e", "-c", &r.body])
            .current_dir(&checkout)
            .env("PATH", path)
            .env_remove("BASH_ENV")
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(&out_log).unwrap())
            .stderr(std::fs::File::create(&err_log).unwrap())
            .process_group(0)
            .spawn()
            .unwrap(),
    );
    let pgid = group.0.id();
    let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
    let started = Instant::now();
    let (mut served, mut probed) = (false, false);
    let status = loop {
        if let Some(status) = group.0.try_wait().unwrap() {
            break status;
        }
        if started.elapsed().as_secs_f64() > LIMIT_S {
            drop(group);
            return fail(
                format!("did not finish in {LIMIT_S} s (its processes are killed)"),
                &read(&err_log),
            );
        }
        if let Some(name) = r.serves.as_deref().filter(|_| !served)
            && let Some(url) = served_address(&read(&out_log))
        {
            served = true;
            match get(&url) {
                Ok(line) if line.contains(" 200") => {}
                got => return fail(format!("{url} answered {got:?}"), &read(&err_log)),
            }
            // Ctrl-C on the server.
            let server: Vec<u32> = group_members(pgid)
                .into_iter()
                .filter(|(_, a)| {
                    a.first().is_some_and(|c| c.ends_with("twindrive"))
                        && a.get(1).is_some_and(|c| c == name)
                })
                .map(|(pid, _)| pid)
                .collect();
            if server.is_empty() {
                return fail(format!("no `twindrive {name}` is running"), &read(&err_log));
            }
            for pid in server {
                let _ = Command::new("kill")
                    .args(["-INT", &pid.to_string()])
                    .status();
            }
        }
        if let Some((port, ca)) = r.probe_tls.as_ref().filter(|_| !probed)
            && listening(*port)
        {
            probed = true;
            let (code, said) = capture_without_certificate(
                &format!("tls/localhost:{port}"),
                &checkout.join(ca),
                &tmp.path().join("captured.bin"),
            );
            if code != Some(3) {
                return fail(
                    format!(
                        "a client without a certificate was not refused by the router on {port} (forger exit {code:?}): {said}"
                    ),
                    &read(&err_log),
                );
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let (out, err) = (read(&out_log), read(&err_log));
    if !status.success() {
        return fail(format!("exit {:?}", status.code()), &err);
    }
    if r.serves.is_some() && !served {
        return fail("printed no address to open".into(), &err);
    }
    if r.probe_tls.is_some() && !probed {
        return fail("its router never listened".into(), &err);
    }
    for (what, bad) in [
        ("a colour code", "\u{1b}["),
        ("a Rust source path", ".cargo/registry"),
        ("a panic", "panicked at"),
    ] {
        if out.contains(bad) || err.contains(bad) {
            return fail(format!("printed {what} (not on a terminal)"), &err);
        }
    }
    // Everything it started in the background, it stopped.
    let ended = Instant::now();
    loop {
        let left = group_members(pgid);
        if left.is_empty() {
            break;
        }
        if ended.elapsed().as_secs_f64() > GRACE_S {
            let names: Vec<String> = left.iter().map(|(_, a)| a.join(" ")).collect();
            return fail(
                format!(
                    "left running {GRACE_S} s after it ended: {}",
                    names.join("; ")
                ),
                &err,
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(())
}

/// Runs every recipe, side by side where their ports allow; the failures.
fn run_all(mut recipes: Vec<Recipe>) -> Vec<String> {
    // The quick ones and those that need no demo first.
    recipes.sort_by_key(|r| (r.needs_demo, !r.ports.is_empty()));
    let state = Mutex::new((
        recipes.into_iter().collect::<VecDeque<_>>(),
        BTreeSet::<u16>::new(),
        Vec::<String>::new(),
    ));
    let freed = Condvar::new();
    std::thread::scope(|s| {
        for _ in 0..WORKERS {
            s.spawn(|| {
                loop {
                    let mut st = state.lock().unwrap();
                    let r = loop {
                        let (pending, busy, _) = &mut *st;
                        if pending.is_empty() {
                            return;
                        }
                        if let Some(k) = pending
                            .iter()
                            .position(|r| r.ports.iter().all(|p| !busy.contains(p)))
                        {
                            let r = pending.remove(k).unwrap();
                            busy.extend(&r.ports);
                            break r;
                        }
                        st = freed.wait(st).unwrap();
                    };
                    drop(st);
                    let started = Instant::now();
                    let result = run(&r);
                    eprintln!(
                        "{}: {} in {:.1} s",
                        r.at(),
                        if result.is_ok() { "ran" } else { "FAILED" },
                        started.elapsed().as_secs_f64()
                    );
                    let mut st = state.lock().unwrap();
                    for p in &r.ports {
                        st.1.remove(p);
                    }
                    if let Err(e) = result {
                        st.2.push(e);
                    }
                    drop(st);
                    freed.notify_all();
                }
            });
        }
    });
    let mut failures = state.into_inner().unwrap().2;
    failures.sort();
    failures
}

#[test]
fn every_block_in_the_docs_is_a_recipe_a_file_or_shown() {
    let blocks = doc_blocks();
    let (recipes, wrong) = classify(&blocks);
    assert!(wrong.is_empty(), "\n{}", wrong.join("\n"));
    // Every recipe types the installed binary.
    for r in &recipes {
        for bad in ["cargo ", "target/release", "target/debug", "$T "] {
            assert!(
                !r.body.contains(bad),
                "{}: types `{bad}`: recipes type `twindrive` (README says how to install it)",
                r.at()
            );
        }
    }
    assert!(recipes.len() >= 10, "{} recipes", recipes.len());
}

#[test]
fn every_toml_block_reads_with_the_projects_reader() {
    let blocks = doc_blocks();
    let tomls: Vec<&Block> = blocks.iter().filter(|b| b.lang == "toml").collect();
    assert!(!tomls.is_empty());
    let wrong: Vec<String> = tomls.iter().filter_map(|b| check_toml(b).err()).collect();
    assert!(wrong.is_empty(), "\n{}", wrong.join("\n"));
}

#[test]
fn every_recipe_runs_as_written() {
    let (mut recipes, wrong) = classify(&doc_blocks());
    assert!(wrong.is_empty(), "\n{}", wrong.join("\n"));
    // While writing a page: `TWINDRIVE_RECIPES=docs/src/ros2.md` runs its
    // recipes alone.
    if let Ok(only) = std::env::var("TWINDRIVE_RECIPES") {
        recipes.retain(|r| r.at().contains(&only));
        assert!(!recipes.is_empty(), "no recipe at {only}");
    }
    let failures = run_all(recipes);
    assert!(
        failures.is_empty(),
        "{} recipe(s) failed:\n\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// The test can fail: a recipe with a wrong flag, or a server recipe whose
/// server never prints its address, fails naming its page and line; a
/// block marked `ci-runs-this` that CI does not run, an unknown marker and
/// an unmarked TOML block are refused.
#[test]
fn a_broken_recipe_fails_naming_its_page_and_line() {
    let page = "intro\n\n```sh\ntwindrive keygen --out keys\ntwindrive simulate scenarios/wall_following.toml --no-such-flag\n```\n";
    let blocks = parse("docs/src/broken.md", page).unwrap();
    let (recipes, wrong) = classify(&blocks);
    assert!(wrong.is_empty(), "{wrong:?}");
    let err = run(&recipes[0]).unwrap_err();
    assert!(
        err.starts_with("docs/src/broken.md:3: exit Some(2)"),
        "{err}"
    );
    assert!(err.contains("--no-such-flag"), "{err}");

    let page = "<!-- recipe: serves console -->\n```sh\ntwindrive keygen --out keys\n```\n";
    let (recipes, _) = classify(&parse("README.md", page).unwrap());
    let err = run(&recipes[0]).unwrap_err();
    assert!(err.starts_with("README.md:2: printed no address"), "{err}");

    for (page, says) in [
        (
            "<!-- recipe: ci-runs-this -->\n```sh\ncargo run -- demo\n```\n",
            "README.md:2: marked ci-runs-this, but `cargo run -- demo`",
        ),
        (
            "<!-- recipe: needs-dmeo -->\n```sh\ntrue\n```\n",
            "README.md:2: unknown recipe item `needs-dmeo`",
        ),
        (
            "```toml\na = 1\n```\n",
            "README.md:1: a toml block needs a marker",
        ),
        (
            "<!-- toml: goals -->\n```toml\nspeed_m_s = 0.2\n```\n",
            "README.md:2: goals: no `[[waypoints]]`",
        ),
        ("```bash\ntrue\n```\n", "README.md:1: a ```bash block"),
        (
            "<!-- recipe: needs-demo -->\n\n```sh\ntrue\n```\n",
            "README.md:1: a marker with no fenced block",
        ),
    ] {
        let wrong = parse("README.md", page).map_or_else(|e| vec![e], |b| classify(&b).1);
        assert!(
            wrong.iter().any(|w| w.starts_with(says)),
            "{page}: {wrong:?}"
        );
    }
}
