//! The console serving a fleet's telemetry to several open pages: CPU,
//! memory and message rates. Run by `bench/console_fleet.sh`:
//!
//! ```sh
//! console_fleet --twindrive target/release/twindrive --rehearsal DIR [--robots 20] [--pages 3] [--seconds 20]
//! ```
//!
//! Starts a zenoh router, N robot agents (zenoh clients of the router, each
//! its own simulated site at real time) and one `twindrive console
//! --robot …` (a client too); K WebSocket clients open the page's socket as
//! a browser would (token, Origin) and count what arrives. One of them makes
//! the plan and uploads it to every robot; once all are executing, the
//! console's CPU time (from /proc) and every page's message and byte rates
//! are measured over a window.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use futures::{SinkExt, StreamExt};
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

mod common;

use common::{Proc, arg, free_port};

/// User + system CPU seconds and resident bytes of process `pid`.
fn usage(pid: u32) -> anyhow::Result<(f64, u64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    let fields: Vec<&str> = stat
        .rsplit_once(") ")
        .map(|(_, rest)| rest.split(' ').collect())
        .unwrap_or_default();
    // Fields after the command: state is index 0; utime 11, stime 12, rss 21.
    let ticks: f64 = fields[11].parse::<f64>()? + fields[12].parse::<f64>()?;
    let rss_pages: u64 = fields[21].parse()?;
    Ok((ticks / 100.0, rss_pages * 4096))
}

#[derive(Default)]
struct Counts {
    messages: AtomicU64,
    bytes: AtomicU64,
}

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

async fn open_page(http: u16, token: &str) -> anyhow::Result<Socket> {
    let mut request = format!("ws://127.0.0.1:{http}/ws?token={token}").into_client_request()?;
    request
        .headers_mut()
        .insert("Origin", format!("http://127.0.0.1:{http}").parse()?);
    let (socket, _) = tokio_tungstenite::connect_async(request).await?;
    Ok(socket)
}

fn spawn(twindrive: &Path, args: &[&str]) -> anyhow::Result<Proc> {
    Ok(Proc(
        Command::new(twindrive)
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()?,
    ))
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let twindrive = PathBuf::from(arg("--twindrive").unwrap_or("target/release/twindrive".into()));
    let rehearsal = arg("--rehearsal").ok_or_else(|| anyhow::anyhow!("--rehearsal DIR"))?;
    let robots: usize = arg("--robots").map_or(Ok(20), |v| v.parse())?;
    let pages: usize = arg("--pages").map_or(Ok(3), |v| v.parse())?;
    let seconds: f64 = arg("--seconds").map_or(Ok(20.0), |v| v.parse())?;
    let tmp = tempfile::tempdir()?;
    let d = tmp.path();
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_owned();
    let keys = d.join("keys");
    anyhow::ensure!(
        Command::new(&twindrive)
            .args(["keygen", "--out", &s(&keys)])
            .stdout(Stdio::null())
            .status()?
            .success(),
        "keygen"
    );
    // The site's robot as calibrated (near its true kinematics), so plans
    // run without a hand-back.
    let calib = d.join("calib.json");
    std::fs::write(
        &calib,
        r#"{"left_diameter_m": 0.0652, "right_diameter_m": 0.0665, "wheelbase_m": 0.2678}"#,
    )?;
    let client = d.join("client.json5");
    std::fs::write(
        &client,
        "{ mode: \"client\", scouting: { multicast: { enabled: false } } }\n",
    )?;
    let router_port = free_port();
    let router = format!("tcp/127.0.0.1:{router_port}");
    let _router = spawn(&twindrive, &["router", "--listen", &router])?;
    // A zenoh client that finds no router gives up: wait for it to listen.
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", router_port)).is_err() {
        anyhow::ensure!(
            started.elapsed() < Duration::from_secs(30),
            "the router did not listen within 30 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let site = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/wall_following.toml");
    let ids: Vec<String> = (1..=robots).map(|k| format!("r{k:03}")).collect();
    // Each robot's key pair: its messages are sealed with it.
    let robot_keys = d.join("robot_keys");
    for id in &ids {
        anyhow::ensure!(
            Command::new(&twindrive)
                .args(["keygen", "--out", &s(&robot_keys), "--robot", id])
                .stdout(Stdio::null())
                .status()?
                .success(),
            "keygen --robot {id}"
        );
    }
    let mut procs = Vec::new();
    for id in &ids {
        procs.push(spawn(
            &twindrive,
            &[
                "robot",
                "--id",
                id,
                "--site",
                &s(&site),
                "--trust",
                &s(&keys.join("master.pub")),
                "--key",
                &s(&robot_keys.join(format!("{id}.key"))),
                "--state-dir",
                &s(&d.join(id)),
                "--connect",
                &router,
                "--zenoh-config",
                &s(&client),
                "--run-for",
                "900",
            ],
        )?);
    }
    let http = free_port();
    let mut cmd = Command::new(&twindrive);
    cmd.args(["console", "--listen", &format!("127.0.0.1:{http}")])
        .args(["--key", &s(&keys.join("master.key"))])
        .args(["--trust-robot", &s(&robot_keys)])
        .args(["--link-state", &s(&d.join("console_link"))])
        .args(["--calibration", &s(&calib)])
        .args(["--rehearsal", &rehearsal, "--out", &s(&d.join("console"))])
        .args(["--connect", &router, "--zenoh-config", &s(&client)]);
    for id in &ids {
        cmd.args(["--robot", id]);
    }
    let mut console = cmd.stdout(Stdio::piped()).stderr(Stdio::null()).spawn()?;
    let pid = console.id();
    let stdout = console.stdout.take().expect("piped");
    let _console = Proc(console);
    let url = common::console_url(stdout)?;
    let token = url.split("token=").nth(1).expect("a token").to_owned();

    // The pages: each counts what it receives.
    let counts: Vec<Arc<Counts>> = (0..pages).map(|_| Arc::new(Counts::default())).collect();
    let latest: Arc<std::sync::Mutex<Value>> = Arc::default();
    let mut senders = Vec::new();
    for (k, c) in counts.iter().enumerate() {
        let socket = open_page(http, &token).await?;
        let (tx, mut rx) = socket.split();
        senders.push(tx);
        let c = c.clone();
        let latest = latest.clone();
        tokio::spawn(async move {
            while let Some(Ok(m)) = rx.next().await {
                if let Message::Text(t) = m {
                    c.messages.fetch_add(1, Ordering::Relaxed);
                    c.bytes.fetch_add(t.len() as u64, Ordering::Relaxed);
                    if k == 0
                        && let Ok(v) = serde_json::from_str::<Value>(&t)
                        && v["type"] == "state"
                    {
                        *latest.lock().unwrap() = v;
                    }
                }
            }
        });
    }
    let robots_in = |pred: &dyn Fn(&Value) -> bool| {
        let v = latest.lock().unwrap();
        v["robots"]
            .as_array()
            .map_or(0, |a| a.iter().filter(|r| pred(r)).count())
    };
    let wait = |what: &'static str, limit_s: f64| {
        let started = Instant::now();
        move |done: bool| -> anyhow::Result<bool> {
            anyhow::ensure!(
                started.elapsed().as_secs_f64() < limit_s,
                "waited {limit_s} s for {what}"
            );
            Ok(done)
        }
    };
    let first = &mut senders[0];
    first
        .send(Message::Text(r#"{"cmd":"plan"}"#.into()))
        .await?;
    let planned = wait("the plan", 120.0);
    while !planned(latest.lock().unwrap()["plan"].is_object())? {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let started = Instant::now();
    for id in &ids {
        first
            .send(Message::Text(
                format!(r#"{{"cmd":"upload","robot":"{id}"}}"#).into(),
            ))
            .await?;
    }
    let executing = wait("every robot executing", 120.0);
    loop {
        let all = robots_in(&|r| r["state"] == "executing") == robots;
        if let Err(e) = executing(all) {
            let v = latest.lock().unwrap();
            let states: Vec<String> = v["robots"]
                .as_array()
                .map(|a| {
                    a.iter()
                        .map(|r| format!("{}: {}", r["id"], r["state"]))
                        .collect()
                })
                .unwrap_or_default();
            let stuck: Vec<String> = v["robots"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|r| r["state"] != "executing" && r["state"] != "completed")
                .map(|r| r.to_string())
                .collect();
            anyhow::bail!("{e}; states: {}; {}", states.join(", "), stuck.join("\n"));
        }
        if all {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let upload_all_s = started.elapsed().as_secs_f64();
    // The window.
    let (cpu0, _) = usage(pid)?;
    let m0: Vec<(u64, u64)> = counts
        .iter()
        .map(|c| {
            (
                c.messages.load(Ordering::Relaxed),
                c.bytes.load(Ordering::Relaxed),
            )
        })
        .collect();
    let t0 = Instant::now();
    tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
    let window = t0.elapsed().as_secs_f64();
    let (cpu1, rss) = usage(pid)?;
    let still = robots_in(&|r| r["state"] == "executing");
    let end_states = {
        let v = latest.lock().unwrap();
        let mut counts = std::collections::BTreeMap::new();
        for r in v["robots"].as_array().into_iter().flatten() {
            *counts
                .entry(r["state"].as_str().unwrap_or("?").to_owned())
                .or_insert(0) += 1;
        }
        counts
    };
    let status_rate: f64 = {
        let v = latest.lock().unwrap();
        v["robots"].as_array().map_or(0.0, |a| {
            a.iter()
                .map(|r| r["link"]["rx_msgs_s"].as_f64().unwrap_or(0.0))
                .sum()
        })
    };
    println!(
        "console serving {robots} robots to {pages} pages: plan uploaded to all and executing in {upload_all_s:.1} s"
    );
    println!(
        "console CPU {:.1} % of one core over {window:.1} s ({:.3} s), RSS {:.0} MB; messages from the robots {status_rate:.1}/s; {still}/{robots} still executing at the end ({end_states:?})",
        100.0 * (cpu1 - cpu0) / window,
        cpu1 - cpu0,
        rss as f64 / 1e6
    );
    for (k, c) in counts.iter().enumerate() {
        let m = c.messages.load(Ordering::Relaxed) - m0[k].0;
        let b = c.bytes.load(Ordering::Relaxed) - m0[k].1;
        println!(
            "page {}: {:.1} messages/s, {:.1} kB/s",
            k + 1,
            m as f64 / window,
            b as f64 / window / 1e3
        );
    }
    drop(procs);
    Ok(())
}
