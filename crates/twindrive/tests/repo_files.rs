//! No file in the repository can rot unnoticed: every scenario, benchmark
//! setup and example TOML loads and runs (and the book's configuration
//! names its sources; `scripts/docs.sh` builds the book).

mod common;

use std::path::{Path, PathBuf};

use common::repo;
use twindrive_mission::PathSample;
use twindrive_mission::redundancy::{RedundancyConfig, remove_redundancy};
use twindrive_sim::{Scenario, Simulator, StepOutput};

/// Every `*.toml` under the repository but the build's own (`Cargo.toml`,
/// `.cargo/`), outside `target/`, hidden directories and virtualenvs.
fn toml_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for path in entries {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            if !(name.starts_with('.') || name == "target" || name == "node_modules") {
                toml_files(&path, out);
            }
        } else if name.ends_with(".toml") && name != "Cargo.toml" {
            out.push(path);
        }
    }
}

/// Twice round a circle of 0.5 m, for redundancy definitions to work on.
fn two_laps() -> Vec<PathSample> {
    (0..=1_256)
        .map(|k| {
            let a = k as f64 * 0.01 / 0.5;
            PathSample {
                t_s: k as f64 * 0.05,
                pose: twindrive_kinematics::Pose::new(0.5 * a.sin(), 0.5 - 0.5 * a.cos(), a),
                v_m_s: 0.2,
                omega_rad_s: 0.4,
            }
        })
        .collect()
}

#[test]
fn every_toml_in_the_repository_loads_and_runs() {
    let mut files = Vec::new();
    toml_files(&repo(), &mut files);
    let (mut scenarios, mut definitions) = (0, 0);
    for path in &files {
        let text = std::fs::read_to_string(path).unwrap();
        let table: toml::Table =
            toml::from_str(&text).unwrap_or_else(|e| panic!("{}: not TOML: {e}", path.display()));
        if table.contains_key("simulation") {
            // A scenario: it loads (maps and command files too) and steps.
            let scenario =
                Scenario::load(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let mut sim = Simulator::new(scenario);
            let mut out = StepOutput::new(sim.beams());
            for step in 0..20 {
                assert!(
                    sim.step(&mut out),
                    "{}: ended after {step} steps",
                    path.display()
                );
            }
            assert!(out.record.t_ns > 0, "{}", path.display());
            scenarios += 1;
        } else if table.contains_key("pinch_distance_m") {
            // A redundancy definition: it parses, validates and prunes.
            let cfg: RedundancyConfig =
                toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            cfg.validate()
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let path_samples = two_laps();
            let pruned = remove_redundancy(&path_samples, &cfg)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(pruned.kept.len() < path_samples.len(), "{}", path.display());
            definitions += 1;
        } else if let Some(book) = table.get("book") {
            // mdBook's configuration (docs/book.toml): its sources are there.
            let src = book.get("src").and_then(|s| s.as_str()).unwrap_or("src");
            let summary = path.parent().unwrap().join(src).join("SUMMARY.md");
            assert!(
                summary.is_file(),
                "{}: no {}",
                path.display(),
                summary.display()
            );
        } else {
            panic!(
                "{}: neither a scenario nor a redundancy definition; teach this test what it is",
                path.display()
            );
        }
    }
    // The built-in scenarios, the two ir-sim setups and the example definition.
    assert!(scenarios >= 5 && definitions >= 1, "{files:?}");
}

/// The workspace's layers, lowest first: a crate depends only on crates of
/// lower layers. Data-only crates sit under the ones that compute with them;
/// the protocol (`link`) reads plans through `plan` alone, never through the
/// pipeline or the simulator.
const LAYERS: [&[&str]; 9] = [
    &[
        "twindrive-kinematics",
        "twindrive-plot",
        "twindrive-files",
        "twindrive-progress",
    ],
    &["twindrive-plan", "twindrive-log"],
    &[
        "twindrive-sim",
        "twindrive-estimation",
        "twindrive-ros",
        "twindrive-link",
    ],
    &["twindrive-calibrate"],
    &["twindrive-mission"],
    &["twindrive-agent"],
    &["twindrive-store", "twindrive-net", "twindrive-workflow"],
    &["twindrive-console", "twindrive-experiment", "twindrive-ops"],
    &["twindrive"],
];

#[test]
fn no_crate_depends_on_one_of_its_own_layer_or_above() {
    let layer = |name: &str| LAYERS.iter().position(|l| l.contains(&name));
    let mut crates = 0;
    for entry in std::fs::read_dir(repo().join("crates")).unwrap() {
        let manifest = entry.unwrap().path().join("Cargo.toml");
        let Ok(text) = std::fs::read_to_string(&manifest) else {
            continue;
        };
        let table: toml::Table = toml::from_str(&text).unwrap();
        let name = table["package"]["name"].as_str().unwrap().to_owned();
        let own = layer(&name).unwrap_or_else(|| panic!("{name} is in no layer of LAYERS"));
        let deps = table.get("dependencies").and_then(|d| d.as_table());
        for dep in deps.into_iter().flat_map(|d| d.keys()) {
            if let Some(theirs) = layer(dep) {
                assert!(
                    theirs < own,
                    "{name} (layer {own}) depends on {dep} (layer {theirs})"
                );
            }
        }
        crates += 1;
    }
    assert_eq!(crates, LAYERS.iter().map(|l| l.len()).sum::<usize>());
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The protocol and the agents do no I/O: no files, sockets, clocks or
/// operating-system randomness, in their code, tests and benchmarks alike.
/// What they keep goes through their store traits (`twindrive-store` keeps
/// it on disk, memory stores serve tests and in-process missions), what
/// they send leaves through `poll_transmit`, and time is an argument.
#[test]
fn link_and_agent_touch_no_file_system_socket_clock_or_randomness() {
    const FORBIDDEN: [&str; 14] = [
        "std::fs",
        "fs::",
        "File::",
        "OpenOptions",
        "read_dir",
        "tempfile",
        "std::net",
        "TcpStream",
        "UdpSocket",
        "Instant::now",
        "SystemTime",
        "getrandom",
        "thread_rng",
        "std::env::var",
    ];
    const IO_CRATES: [&str; 7] = [
        "tempfile",
        "getrandom",
        "tokio",
        "zenoh",
        "twindrive-store",
        "twindrive-net",
        "rusqlite",
    ];
    let mut found = Vec::new();
    for krate in ["link", "agent"] {
        let dir = repo().join("crates").join(krate);
        let lines = code_lines(&dir);
        let files: std::collections::BTreeSet<&str> = lines
            .iter()
            .filter_map(|(at, _)| at.rsplit_once(':').map(|(file, _)| file))
            .collect();
        assert!(files.len() > 5, "{krate}: {files:?}");
        for (at, code) in &lines {
            for word in FORBIDDEN.iter().filter(|w| code.contains(*w)) {
                found.push(format!("{at}: `{word}`"));
            }
        }
        for (table, dep) in dependencies(&dir) {
            if IO_CRATES.contains(&dep.as_str()) {
                found.push(format!("crates/{krate}/Cargo.toml [{table}]: `{dep}`"));
            }
        }
    }
    assert!(
        found.is_empty(),
        "I/O in link or agent:\n{}",
        found.join("\n")
    );
}

/// Every line of code (not a `//` comment) in crate `dir`'s sources, tests,
/// benches and examples: `(file:line, the line trimmed)`.
fn code_lines(dir: &Path) -> Vec<(String, String)> {
    let mut files = Vec::new();
    for sub in ["src", "tests", "benches", "examples"] {
        rust_files(&dir.join(sub), &mut files);
    }
    let mut out = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        for (k, line) in text.lines().enumerate() {
            let code = line.trim_start();
            if !code.starts_with("//") {
                out.push((format!("{}:{}", file.display(), k + 1), code.to_string()));
            }
        }
    }
    out
}

/// Crate `dir`'s dependencies and dev-dependencies: `(table, name)`.
fn dependencies(dir: &Path) -> Vec<(&'static str, String)> {
    let manifest: toml::Table =
        toml::from_str(&std::fs::read_to_string(dir.join("Cargo.toml")).unwrap()).unwrap();
    let mut out = Vec::new();
    for table in ["dependencies", "dev-dependencies"] {
        let deps = manifest.get(table).and_then(|d| d.as_table());
        out.extend(
            deps.into_iter()
                .flat_map(|d| d.keys())
                .map(|k| (table, k.clone())),
        );
    }
    out
}

/// The transport seam: only `twindrive-net` knows zenoh; every other crate
/// (the processes in `twindrive-ops`, the console, the binary, their tests)
/// takes a `twindrive_net::Network`.
#[test]
fn only_the_net_crate_names_zenoh() {
    let mut found = Vec::new();
    let crates = std::fs::read_dir(repo().join("crates")).unwrap();
    let mut checked = 0;
    for entry in crates {
        let dir = entry.unwrap().path();
        if dir.file_name().is_some_and(|n| n == "net") || !dir.join("Cargo.toml").exists() {
            continue;
        }
        checked += 1;
        for (at, code) in code_lines(&dir) {
            // `zenoh::` as a path of its own (not `rmw_zenoh::`).
            let named = code.match_indices(concat!("zenoh", "::")).any(|(k, _)| {
                !code[..k]
                    .chars()
                    .next_back()
                    .is_some_and(|c| c.is_alphanumeric() || c == '_')
            });
            if named {
                found.push(at);
            }
        }
        for (table, dep) in dependencies(&dir) {
            if dep == "zenoh" {
                found.push(format!("{}/Cargo.toml [{table}]", dir.display()));
            }
        }
    }
    assert!(checked > 10, "{checked} crates");
    assert!(
        found.is_empty(),
        "zenoh outside twindrive-net:\n{}",
        found.join("\n")
    );
}

/// The module a source file is (`src/robot/run.rs`: `robot::run`;
/// `src/robot/mod.rs`: `robot`; the crate root: nothing).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    if parts.len() == 1 && (parts[0] == "lib" || parts[0] == "main") {
        parts.clear();
    }
    parts
}

/// The paths a line of code names from `crate::` and `super::`, and from
/// the file's own child modules (`use run::Running`), as module paths
/// (items included: the caller resolves them to the longest module).
fn paths_named(code: &str, own: &[String], children: &[String]) -> Vec<Vec<String>> {
    let ident = |s: &str| -> Vec<String> {
        let mut out = Vec::new();
        for part in s.split("::") {
            let name: String = part
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if name.is_empty() {
                break;
            }
            let whole = name.len() == part.len();
            out.push(name);
            if !whole {
                break;
            }
        }
        out
    };
    // What follows a prefix: one path, or a `{...}` group of them.
    let expand = |rest: &str, base: Vec<String>| -> Vec<Vec<String>> {
        if let Some(group) = rest.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            group[..end]
                .split(',')
                .map(|p| [base.clone(), ident(p.trim())].concat())
                .collect()
        } else {
            vec![[base, ident(rest)].concat()]
        }
    };
    let mut found = Vec::new();
    let bytes = code.as_bytes();
    for (k, _) in code.match_indices("crate::") {
        if k > 0 && (bytes[k - 1].is_ascii_alphanumeric() || bytes[k - 1] == b'_') {
            continue;
        }
        found.extend(expand(&code[k + 7..], Vec::new()));
    }
    for (k, _) in code.match_indices("super::") {
        if k > 0
            && (bytes[k - 1].is_ascii_alphanumeric()
                || bytes[k - 1] == b'_'
                || bytes[k - 1] == b':')
        {
            continue;
        }
        // Each `super` is the module's parent (a `mod.rs` is its directory's
        // module).
        let mut base = own.to_vec();
        let mut rest = &code[k..];
        while let Some(r) = rest.strip_prefix("super::") {
            base.pop();
            rest = r;
        }
        found.extend(expand(rest, base));
    }
    let code = code.trim_start();
    let code = code.strip_prefix("pub ").unwrap_or(code);
    if let Some(rest) = code.strip_prefix("use ") {
        for child in children {
            if let Some(r) = rest.strip_prefix(&format!("{child}::")) {
                let base = [own.to_vec(), vec![child.clone()]].concat();
                found.extend(expand(r, base));
            }
        }
    }
    found
}

/// The files of each crate use one another without a circle: a module uses
/// what lies beside or below it and never something that uses it back. A
/// module's own parts may use their parent (a directory module's `mod.rs`
/// is their façade and holds what they share), and the crate root is no
/// node.
#[test]
fn no_circle_between_the_files_of_a_crate() {
    let mut circles = Vec::new();
    let mut crates = 0;
    for entry in std::fs::read_dir(repo().join("crates")).unwrap() {
        let src = entry.unwrap().path().join("src");
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        if files.is_empty() {
            continue;
        }
        crates += 1;
        files.sort();
        let modules: Vec<Vec<String>> = files.iter().map(|f| module_of(&src, f)).collect();
        let index = |path: &[String]| -> Option<usize> {
            (1..=path.len())
                .rev()
                .find_map(|n| modules.iter().position(|m| m.as_slice() == &path[..n]))
        };
        let mut edges: Vec<Vec<usize>> = vec![Vec::new(); files.len()];
        for (i, file) in files.iter().enumerate() {
            if modules[i].is_empty() {
                continue;
            }
            let text = std::fs::read_to_string(file).unwrap();
            let children: Vec<String> = text
                .lines()
                .filter_map(|l| {
                    let l = l.trim_start();
                    let l = l.strip_prefix("pub ").unwrap_or(l);
                    let name = l.strip_prefix("mod ")?.strip_suffix(';')?;
                    Some(name.to_string())
                })
                .collect();
            // Test modules may use anything of their file's parent.
            let code = text.split("#[cfg(test)]").next().unwrap_or_default();
            for line in code.lines() {
                if line.trim_start().starts_with("//") {
                    continue;
                }
                for path in paths_named(line, &modules[i], &children) {
                    if let Some(j) = index(&path)
                        && j != i
                        && !modules[j].is_empty()
                        && !modules[i].starts_with(&modules[j])
                        && !edges[i].contains(&j)
                    {
                        edges[i].push(j);
                    }
                }
            }
        }
        // A circle: a file that reaches itself.
        for start in 0..files.len() {
            let mut stack = vec![(start, vec![start])];
            let mut seen = vec![false; files.len()];
            while let Some((at, trail)) = stack.pop() {
                for &next in &edges[at] {
                    if next == start {
                        if trail.iter().min() == Some(&start) {
                            let names: Vec<_> = trail
                                .iter()
                                .map(|&k| {
                                    files[k]
                                        .strip_prefix(repo().join("crates"))
                                        .unwrap_or(&files[k])
                                        .display()
                                        .to_string()
                                })
                                .collect();
                            circles.push(names.join(" -> "));
                        }
                    } else if !seen[next] {
                        seen[next] = true;
                        stack.push((next, [trail.clone(), vec![next]].concat()));
                    }
                }
            }
        }
    }
    assert!(crates >= 13, "{crates} crates");
    assert!(
        circles.is_empty(),
        "files in a circle:\n{}",
        circles.join("\n")
    );
}
