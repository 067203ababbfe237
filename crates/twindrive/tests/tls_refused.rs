//! A fleet's TLS router (from `twindrive certs`) and the processes it
//! refuses: a master or robot with no client certificate, with another
//! fleet's files, with this fleet's CA but another's certificate, or over
//! plain TCP, each stops on its own (exit 1) well before its
//! `--connect-timeout` with a message that names the endpoint, says TLS
//! refused it and why, and says what to do; the router's log says each
//! refusal in words and counts the rest, never zenoh's "increase the
//! system open file limit".

mod common;

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{Proc, fixture, port, repo, text, twindrive};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Waits (bounded) for `file` to hold `needle`.
fn wait_for(file: &Path, needle: &str, limit: Duration) -> String {
    let start = Instant::now();
    loop {
        let got = std::fs::read_to_string(file).unwrap_or_default();
        if got.contains(needle) {
            return got;
        }
        assert!(
            start.elapsed() < limit,
            "{} never said {needle:?}: {got}",
            file.display()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// `twindrive ARGS` to its end (bounded): exit code, stderr, how long.
fn run(args: &[String]) -> (Option<i32>, String, Duration) {
    let started = Instant::now();
    let (code, err) = common::finish(
        Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        ),
        90.0,
    );
    (code, err, started.elapsed())
}

#[test]
fn clients_a_tls_router_refuses_say_why_within_15_s_and_its_log_stays_short() {
    let f = fixture();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let tls_port = port();
    let certs = d.join("certs");
    let other = d.join("other");
    for dir in [&certs, &other] {
        let o = twindrive(&[
            "certs",
            "--out",
            s(dir),
            "--robot",
            "rover",
            "--port",
            &tls_port.to_string(),
        ]);
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    // A client configuration that trusts the fleet's CA and shows no
    // certificate, and one with the fleet's CA but the other fleet's
    // master certificate.
    let tls = format!("tls/localhost:{tls_port}");
    std::fs::write(
        certs.join("no-cert.json5"),
        format!(
            r#"{{ mode: "client", connect: {{ endpoints: ["{tls}"] }},
                 scouting: {{ multicast: {{ enabled: false }} }},
                 transport: {{ link: {{ tls: {{ root_ca_certificate: "ca.pem" }} }} }} }}"#
        ),
    )
    .unwrap();
    for name in ["master.pem", "master.key"] {
        std::fs::copy(other.join(name), certs.join(format!("other-{name}"))).unwrap();
    }
    std::fs::write(
        certs.join("other-cert.json5"),
        std::fs::read_to_string(certs.join("master.json5"))
            .unwrap()
            .replace("\"master.pem\"", "\"other-master.pem\"")
            .replace("\"master.key\"", "\"other-master.key\""),
    )
    .unwrap();
    let router_log = d.join("router.log");
    let router = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args(["router", "--zenoh-config", s(&certs.join("router.json5"))])
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&router_log).unwrap())
            .spawn()
            .unwrap(),
    );
    wait_for(&router_log, "router: listening on", Duration::from_secs(60));
    let router_up = Instant::now();

    let master = |out: &str, endpoint: &[&str]| -> Vec<String> {
        let mut args: Vec<String> = [
            "master",
            "--plan",
            s(&f.path("plan/plan.json")),
            "--key",
            s(&f.path("keys/master.key")),
            "--trust-robot",
            s(&f.path("keys/rover.pub")),
            "--link-state",
            s(&d.join(format!("link-{out}"))),
            "--robot",
            "rover",
            "--out",
            s(&d.join(out)),
        ]
        .map(String::from)
        .to_vec();
        args.extend(endpoint.iter().map(|e| e.to_string()));
        args
    };
    let robot = |endpoint: &[&str]| -> Vec<String> {
        let mut args: Vec<String> = [
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
            s(&d.join("robot")),
        ]
        .map(String::from)
        .to_vec();
        args.extend(endpoint.iter().map(|e| e.to_string()));
        args
    };
    let plain = format!("tcp/127.0.0.1:{tls_port}");
    let cases: Vec<(&str, Vec<String>, &str, String)> = vec![
        (
            "a master with no client certificate",
            master("m1", &["--zenoh-config", s(&certs.join("no-cert.json5"))]),
            "offered none",
            tls.clone(),
        ),
        (
            "a master with another fleet's files",
            master("m2", &["--zenoh-config", s(&other.join("master.json5"))]),
            "the router's certificate is not signed by the CA this process trusts",
            tls.clone(),
        ),
        (
            "a master with this fleet's CA and another fleet's certificate",
            master(
                "m3",
                &["--zenoh-config", s(&certs.join("other-cert.json5"))],
            ),
            "the router rejected this process's certificate",
            tls.clone(),
        ),
        (
            "a master over plain TCP",
            master("m4", &["--connect", &plain]),
            "the peer speaks TLS and this process spoke plain TCP",
            plain.clone(),
        ),
        (
            "a master with its fleet's configuration over plain TCP",
            master(
                "m5",
                &[
                    "--zenoh-config",
                    s(&certs.join("master.json5")),
                    "--connect",
                    &plain,
                ],
            ),
            "the peer speaks TLS and this process spoke plain TCP",
            plain.clone(),
        ),
        (
            "a robot over plain TCP",
            robot(&["--connect", &plain]),
            "the peer speaks TLS and this process spoke plain TCP",
            plain.clone(),
        ),
        (
            "a robot with another fleet's files",
            robot(&["--zenoh-config", s(&other.join("rover.json5"))]),
            "the router's certificate is not signed by the CA this process trusts",
            tls.clone(),
        ),
    ];
    for (how, args, reason, endpoint) in &cases {
        // The default --connect-timeout (60 s) stands: a refusal is not
        // waited out.
        let (code, err, took) = run(args);
        eprintln!("{how}: exit {code:?} after {:.1} s", took.as_secs_f64());
        assert_eq!(code, Some(1), "{how}: {err}");
        assert!(
            took < Duration::from_secs(15),
            "{how}: {:.1} s: {err}",
            took.as_secs_f64()
        );
        assert!(
            err.contains(&format!(
                "connecting to {endpoint}: TLS refused this process: "
            )),
            "{how}: {err}"
        );
        assert!(err.contains(reason), "{how}: {err}");
        assert!(err.contains("twindrive certs"), "{how}: no fix: {err}");
        assert!(
            !err.contains("nothing answered") && !err.contains("is the router running"),
            "{how}: {err}"
        );
        assert!(
            !err.contains(".rs:") && !err.contains('\u{1b}'),
            "{how}: {err}"
        );
    }
    // And a client hammering the TLS port with plain TCP.
    for _ in 0..40 {
        if let Ok(mut c) = std::net::TcpStream::connect(("127.0.0.1", tls_port)) {
            let _ = c.write_all(b"\x00\x01not tls at all\r\n");
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    // The line said at once for a refusal after a quiet while, the counts
    // at most every 10 s: wait for a summary to be due.
    std::thread::sleep(Duration::from_secs(11));
    let up_s = router_up.elapsed().as_secs_f64();
    drop(router);
    let log = std::fs::read_to_string(&router_log).unwrap();
    assert!(!log.contains("open file limit"), "{log}");
    let said: Vec<&str> = log.lines().filter(|l| l.contains("TLS refused")).collect();
    assert!(
        said.iter().any(|l| l.contains("spoke plain TCP")),
        "the router never said why: {log}"
    );
    assert!(
        said.len() as f64 <= 2.0 + up_s / 10.0,
        "{} lines about refusals in {up_s:.0} s: {log}",
        said.len()
    );
    assert!(
        log.lines().count() as f64 <= 4.0 + up_s / 10.0,
        "the router's log: {log}"
    );
}
