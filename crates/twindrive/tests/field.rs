//! A field team's first deployment: the fleet's certificates where they
//! are copied, and what happens when an endpoint is wrong: a process that
//! cannot listen, or cannot reach its router, says why and exits 1 within
//! a bounded time, with no Rust source path in what it prints. (The
//! README's TLS recipe runs as written in tests/recipes.rs.)

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{Proc, fixture, python, repo, text, twindrive};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Whether something on 127.0.0.1 accepts connections on `port`.
fn listening(port: u16) -> bool {
    std::net::TcpStream::connect_timeout(
        &std::net::SocketAddr::from(([127, 0, 0, 1], port)),
        Duration::from_millis(200),
    )
    .is_ok()
}

/// `twindrive ARGS` run to its end (bounded: `limit_s`): its exit code and
/// what it said on stderr.
fn run_bounded<I, A>(args: I, limit_s: f64) -> (Option<i32>, String)
where
    I: IntoIterator<Item = A>,
    A: AsRef<std::ffi::OsStr>,
{
    common::finish(
        Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        ),
        limit_s,
    )
}

/// `scripts/forger.py capture` for a second on `endpoint` over TLS,
/// trusting `ca`, showing `cert` (certificate, key) if given: its exit code
/// (3: it could not connect) and what it said.
fn capture(
    endpoint: &str,
    file: &Path,
    ca: &Path,
    cert: Option<(&Path, &Path)>,
) -> (Option<i32>, String) {
    let mut args = vec![
        "capture",
        endpoint,
        "twindrive/rover/up",
        s(file),
        "--for",
        "1",
        "--ca",
        s(ca),
    ];
    if let Some((pem, key)) = cert {
        args.extend(["--cert", s(pem), "--private-key", s(key)]);
    }
    common::finish(
        Proc(
            Command::new(python())
                .arg(repo().join("scripts/forger.py"))
                .args(&args)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        ),
        60.0,
    )
}

#[test]
fn the_fleets_files_work_where_they_are_copied() {
    let tmp = tempfile::tempdir().unwrap();
    let made = tmp.path().join("made");
    let port = common::port().to_string();
    let o = twindrive(&[
        "certs",
        "--out",
        s(&made),
        "--robot",
        "rover",
        "--port",
        &port,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    // The whole directory moved, as to the robot and the operator's machine.
    let copied = tmp.path().join("elsewhere/certs");
    std::fs::create_dir_all(copied.parent().unwrap()).unwrap();
    std::fs::rename(&made, &copied).unwrap();
    let router = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args(["router", "--zenoh-config", s(&copied.join("router.json5"))])
            .current_dir(tmp.path())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let started = Instant::now();
    while !listening(port.parse().unwrap()) {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the router never listened on its configuration's port {port}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // A client with its copied configuration reaches it.
    let (code, err) = capture(
        &format!("tls/localhost:{port}"),
        &tmp.path().join("got.bin"),
        &copied.join("ca.pem"),
        Some((&copied.join("rover.pem"), &copied.join("rover.key"))),
    );
    assert_eq!(code, Some(0), "the robot's certificate was refused: {err}");
    drop(router);
}

#[test]
fn a_robot_that_cannot_listen_says_why_and_exits_1() {
    let f = fixture();
    let tmp = tempfile::tempdir().unwrap();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let started = Instant::now();
    let (code, err) = run_bounded(
        [
            "robot",
            "--id",
            "rover",
            "--site",
            s(&repo().join("scenarios/wall_following.toml")),
            "--trust",
            s(&f.path("keys/master.pub")),
            "--key",
            s(&f.path("keys/rover.key")),
            "--state-dir",
            s(&tmp.path().join("robot")),
            "--listen",
            &format!("tcp/127.0.0.1:{port}"),
        ],
        60.0,
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(started.elapsed() < Duration::from_secs(20), "{err}");
    assert!(
        err.contains(&format!("tcp/127.0.0.1:{port}")) && err.contains("cannot listen"),
        "{err}"
    );
    assert!(
        !err.contains(".rs:") && !err.contains('\u{1b}'),
        "a source path or a colour code: {err}"
    );
    drop(taken);
}

#[test]
fn a_master_that_reaches_nothing_says_why_and_exits_1() {
    let f = fixture();
    let tmp = tempfile::tempdir().unwrap();
    // A TLS router (made by certs) that this master reaches over plain TCP,
    // and a client configuration whose router is not there at all.
    let certs = tmp.path().join("certs");
    let port = common::port().to_string();
    let o = twindrive(&[
        "certs",
        "--out",
        s(&certs),
        "--robot",
        "rover",
        "--port",
        &port,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let _router = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args(["router", "--zenoh-config", s(&certs.join("router.json5"))])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let idle = common::port().to_string();
    for (how, endpoint_args, expect) in [
        (
            "plain TCP to the TLS router",
            vec!["--connect".to_string(), format!("tcp/127.0.0.1:{port}")],
            "TLS refused this process: the peer speaks TLS and this process spoke plain TCP",
        ),
        (
            "TLS to a port where nothing listens",
            vec![
                "--zenoh-config".to_string(),
                s(&certs.join("master.json5")).to_string(),
                "--connect".to_string(),
                format!("tls/localhost:{idle}"),
            ],
            "nothing answered",
        ),
    ] {
        let out = tmp.path().join(format!("m-{idle}-{}", how.len()));
        let mut args: Vec<String> = [
            "master",
            "--plan",
            s(&f.path("plan/plan.json")),
            "--key",
            s(&f.path("keys/master.key")),
            "--trust-robot",
            s(&f.path("keys/rover.pub")),
            "--link-state",
            s(&tmp.path().join("link")),
            "--robot",
            "rover",
            "--out",
            s(&out),
            "--connect-timeout",
            "3",
        ]
        .map(String::from)
        .to_vec();
        args.extend(endpoint_args);
        let started = Instant::now();
        let (code, err) = run_bounded(&args, 90.0);
        assert_eq!(code, Some(1), "{how}: {err}");
        assert!(
            started.elapsed() < Duration::from_secs(40),
            "{how}: {:?}",
            started.elapsed()
        );
        assert!(err.contains(expect), "{how}: {err}");
        assert!(
            !err.contains(".rs:") && !err.contains('\u{1b}'),
            "{how}: a source path or a colour code: {err}"
        );
    }
}

#[test]
fn a_console_that_cannot_listen_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let address = taken.local_addr().unwrap().to_string();
    let out = tmp.path().join("console");
    let (code, err) = run_bounded(["console", "--listen", &address, "--out", s(&out)], 60.0);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains(&address) && err.contains("cannot listen"),
        "{err}"
    );
    assert!(!out.exists(), "the console left {}", out.display());
    drop(taken);
}

#[test]
fn key_and_plan_mistakes_name_the_file_and_what_to_do() {
    let f = fixture();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    // A robot's own key given to sign with.
    let signed = d.join("plan.signed");
    let o = twindrive(&[
        "sign",
        s(&f.path("plan/plan.json")),
        "--key",
        s(&f.path("keys/rover.key")),
        "--robot",
        "rover",
        "--out",
        s(&signed),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("robot rover's own key"),
        "{}",
        text(&o.stderr)
    );
    assert!(!signed.exists());
    let o = twindrive(&[
        "sign",
        s(&f.path("plan/plan.json")),
        "--key",
        s(&f.path("keys/master.key")),
        "--robot",
        "rover",
        "--out",
        s(&signed),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    // A signed plan cut short: the master names the file.
    let bytes = std::fs::read(&signed).unwrap();
    let cut = d.join("cut.signed");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let (master_key, link_state) = (f.path("keys/master.key"), d.join("link"));
    let master = |extra: &[&str]| {
        let mut args = vec![
            "master",
            "--key",
            s(&master_key),
            "--robot",
            "rover",
            "--link-state",
            s(&link_state),
            "--connect-timeout",
            "1",
        ];
        args.extend_from_slice(extra);
        twindrive(&args)
    };
    let o = master(&[
        "--signed",
        s(&cut),
        "--trust-robot",
        s(&f.path("keys/rover.pub")),
        "--out",
        s(&d.join("m1")),
    ]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("--signed {}", cut.display())),
        "{err}"
    );
    assert!(err.contains("cut short"), "{err}");
    // A --trust-robot that is not there.
    let missing = d.join("no-such-keys");
    let o = master(&[
        "--plan",
        s(&f.path("plan/plan.json")),
        "--trust-robot",
        s(&missing),
        "--out",
        s(&d.join("m2")),
    ]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&missing.display().to_string()) && err.contains("no such file or directory"),
        "{err}"
    );
}
