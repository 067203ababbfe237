//! Frame time of the console's map while panning, measured in the browser,
//! with a long rehearsal (a one-hour mission: 360,000 samples) and its plan
//! drawn. Run by `bench/console_frame_time.sh`, which builds the release
//! binary and the mission first:
//!
//! ```sh
//! console_frame_time --twindrive target/release/twindrive --rehearsal DIR [--frames 300] [--screenshot PNG]
//! ```
//!
//! Starts `twindrive console` on a free loopback port, chromedriver and a
//! headless Debian chromium, loads the page, makes the plan on it (the
//! pipeline on the whole mission), then pans the map one step per animation
//! frame and reads the map's own draw times (`performance.now()` around
//! each draw) and the intervals between animation frames.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::{Client, ClientBuilder};
use serde_json::{Value, json};

mod common;

use common::{Proc, arg, free_port};

async fn wait_js(c: &Client, script: &str, limit: Duration, what: &str) -> anyhow::Result<()> {
    let started = Instant::now();
    while c.execute(script, vec![]).await? != Value::Bool(true) {
        if started.elapsed() > limit {
            anyhow::bail!("waited {limit:?} for {what}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    Ok(())
}

fn stats(label: &str, v: &[f64]) -> String {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let q = |p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
    format!(
        "{label}: median {:.2} ms, p95 {:.2} ms, max {:.2} ms over {} frames",
        q(0.5),
        q(0.95),
        s[s.len() - 1],
        s.len()
    )
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let _ = rustls::crypto::ring::default_provider().install_default();
    let twindrive = PathBuf::from(arg("--twindrive").unwrap_or("target/release/twindrive".into()));
    let rehearsal = arg("--rehearsal").ok_or_else(|| anyhow::anyhow!("--rehearsal DIR"))?;
    let frames: usize = arg("--frames").map_or(Ok(300), |f| f.parse())?;
    let out = tempfile::tempdir()?;
    // The console plans only with the robot's model: the case study's
    // robot as calibrated (its true kinematics to 0.01 %).
    let calib = out.path().join("calib.json");
    std::fs::write(
        &calib,
        r#"{"left_diameter_m": 0.0652, "right_diameter_m": 0.0665, "wheelbase_m": 0.2678}"#,
    )?;
    let http = free_port();
    let mut console = Command::new(&twindrive)
        .args(["console", "--listen", &format!("127.0.0.1:{http}")])
        .arg("--calibration")
        .arg(&calib)
        .args(["--rehearsal", &rehearsal, "--out"])
        .arg(out.path().join("console"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()?;
    let stdout = console.stdout.take().expect("piped");
    let _console = Proc(console);
    let url = common::console_url(stdout)?;
    let driver_port = free_port();
    let _driver = Proc(
        Command::new("/usr/bin/chromedriver")
            .arg(format!("--port={driver_port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()?,
    );
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", driver_port)).is_err() {
        anyhow::ensure!(started.elapsed() < Duration::from_secs(30), "chromedriver");
        std::thread::sleep(Duration::from_millis(50));
    }
    let profile = tempfile::tempdir()?;
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": "/usr/bin/chromium",
            "args": ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                     "--no-first-run", "--disable-background-networking",
                     "--disable-component-update", "--disable-sync", "--window-size=1400,900",
                     format!("--user-data-dir={}", profile.path().display())],
        }),
    );
    let c = ClientBuilder::rustls()?
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{driver_port}"))
        .await?;
    let result = measure(&c, &url, frames).await;
    c.close().await?;
    result
}

async fn measure(c: &Client, url: &str, frames: usize) -> anyhow::Result<()> {
    c.goto(url).await?;
    wait_js(
        c,
        "return !!(window.twindrive && window.twindrive.S.rehearsal)",
        Duration::from_secs(120),
        "the rehearsal on the page",
    )
    .await?;
    let samples = c
        .execute("return window.twindrive.S.rehearsal.track.t.length", vec![])
        .await?;
    let asked = Instant::now();
    c.execute(
        "window.twindrive.S.ws.send(JSON.stringify({cmd: 'plan'})); return true",
        vec![],
    )
    .await?;
    wait_js(
        c,
        "return !!window.twindrive.S.plan",
        Duration::from_secs(600),
        "the plan",
    )
    .await?;
    let plan_s = asked.elapsed().as_secs_f64();
    let info = c
        .execute(
            "const S = window.twindrive.S; return [S.plan.executed.t.length, S.plan.plan.t.length, S.timings]",
            vec![],
        )
        .await?;
    // Zoom to the whole room, then pan around a circle, one step a frame.
    let r = c
        .execute_async(
            &format!(
                r#"const done = arguments[arguments.length - 1];
                const map = window.twindrive.map;
                if (window.twindrive.S.world.bounds) map.fit(window.twindrive.S.world.bounds);
                map.syncMeasure = true;
                map.frameTimes.length = 0;
                const gaps = []; let last = null; let k = 0;
                function step(t) {{
                  if (last !== null) gaps.push(t - last);
                  last = t;
                  const a = 2 * Math.PI * k / 120;
                  map.pan(6 * Math.cos(a), 6 * Math.sin(a));
                  if (++k <= {frames}) requestAnimationFrame(step);
                  else done([map.frameTimes.slice(), gaps, map.staticTimes.slice()]);
                }}
                requestAnimationFrame(step);"#
            ),
            vec![],
        )
        .await?;
    if let Some(path) = arg("--screenshot") {
        std::fs::write(&path, c.screenshot().await?)?;
    }
    // A zoom step (the static picture is drawn anew once it settles).
    let zoom = c
        .execute_async(
            r#"const done = arguments[arguments.length - 1];
            const map = window.twindrive.map;
            map.staticTimes.length = 0;
            map.zoomAt(500, 400, 1.5);
            setTimeout(() => done(map.staticTimes.slice()), 600);"#,
            vec![],
        )
        .await?;
    let zoom: Vec<f64> = serde_json::from_value(zoom)?;
    let draws: Vec<f64> = serde_json::from_value(r[0].clone())?;
    let gaps: Vec<f64> = serde_json::from_value(r[1].clone())?;
    let statics: Vec<f64> = serde_json::from_value(r[2].clone())?;
    anyhow::ensure!(!draws.is_empty(), "no frame was drawn");
    println!(
        "console map, one-hour mission: {} rehearsal samples on the page; the plan: executed path {} samples, plan {} samples (made in {plan_s:.1} s, page timings {})",
        samples, info[0], info[1], info[2]
    );
    println!(
        "{}",
        stats("draw time while panning (raster included)", &draws)
    );
    println!("{}", stats("interval between animation frames", &gaps));
    if let Some(ms) = zoom.first() {
        println!(
            "redraw of the static picture after a zoom step (raster included): {ms:.1} ms, once"
        );
    }
    if !statics.is_empty() {
        println!(
            "{}",
            stats(
                "redraws of the static picture (layers changed, view left the bitmap, zoom settled)",
                &statics
            )
        );
    }
    let mut sorted = draws.clone();
    sorted.sort_by(f64::total_cmp);
    let p95 = sorted[((sorted.len() - 1) as f64 * 0.95).round() as usize];
    println!(
        "target: draw time under 16 ms: {}",
        if p95 < 16.0 {
            "met (p95)"
        } else {
            "NOT met (p95)"
        }
    );
    Ok(())
}
