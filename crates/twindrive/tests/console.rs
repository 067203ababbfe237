//! The operator's console in a real browser: Debian's chromium, headless,
//! driven over WebDriver (chromedriver) by fantoccini, against `twindrive
//! console` (and `twindrive robot` where a robot is needed) on loopback.
//! `scripts/browser-deps.sh` installs chromium and chromium-driver (the
//! test script runs it). Every test saves screenshots under
//! `target/console-screenshots/`; every wait is bounded and every child is
//! killed by its process id.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{Proc, fixture, port, repo};
use fantoccini::actions::{InputSource, KeyAction, KeyActions, MouseActions, PointerAction};
use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{Value, json};

const ARROW_UP: char = '\u{e013}';

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn screenshots() -> PathBuf {
    let dir = repo().join("target/console-screenshots");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `twindrive console` with `args`, once it has printed its address.
struct Console {
    _proc: Proc,
    url: String,
}

fn console(http_port: u16, out: &Path, args: &[&str]) -> Console {
    // Plans need a robot model: the case study's calibration, as the book's
    // console chapter gives it.
    let calibration = fixture().path("calib.json");
    let model: &[&str] = if args.contains(&"--calibration") {
        &[]
    } else {
        &["--calibration", s(&calibration)]
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_twindrive"))
        .args([
            "console",
            "--listen",
            &format!("127.0.0.1:{http_port}"),
            "--out",
            s(out),
        ])
        .args(model)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let proc = Proc(child);
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(url) = line.strip_prefix("console: open ") {
                let _ = tx.send(url.to_owned());
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the console prints its address within 60 s");
    assert!(url.starts_with(&format!("http://127.0.0.1:{http_port}/?token=")));
    Console { _proc: proc, url }
}

fn robot(site: &Path, zenoh_port: u16, state: &Path) -> Proc {
    let child = Command::new(env!("CARGO_BIN_EXE_twindrive"))
        .args([
            "robot",
            "--id",
            "rover",
            "--site",
            s(site),
            "--trust",
            s(&fixture().path("keys/master.pub")),
            "--key",
            s(&fixture().path("keys/rover.key")),
            "--state-dir",
            s(state),
            "--listen",
            &format!("tcp/127.0.0.1:{zenoh_port}"),
            "--time-scale",
            "5",
            "--run-for",
            "300",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    Proc(child)
}

/// chromedriver on a free port, and a headless chromium session through it.
struct Browser {
    client: Client,
    _driver: Proc,
    _profile: tempfile::TempDir,
}

async fn browser() -> Browser {
    // Two TLS providers are linked (zenoh's and fantoccini's): choose one.
    let _ = rustls::crypto::ring::default_provider().install_default();
    for exe in ["/usr/bin/chromium", "/usr/bin/chromedriver"] {
        assert!(
            Path::new(exe).exists(),
            "{exe} is missing: run scripts/browser-deps.sh (scripts/test.sh does)"
        );
    }
    let port = port();
    let driver = Proc(
        Command::new("/usr/bin/chromedriver")
            .args([format!("--port={port}"), "--allowed-ips=127.0.0.1".into()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "chromedriver did not listen within 30 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let profile = tempfile::tempdir().unwrap();
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": "/usr/bin/chromium",
            "args": [
                "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync",
                "--disable-dev-shm-usage", "--window-size=1400,900",
                format!("--user-data-dir={}", profile.path().display()),
            ],
        }),
    );
    let client = tokio::time::timeout(Duration::from_secs(60), async {
        ClientBuilder::rustls()
            .unwrap()
            .capabilities(caps)
            .connect(&format!("http://127.0.0.1:{port}"))
            .await
    })
    .await
    .expect("chromium starts within 60 s")
    .expect("a WebDriver session");
    Browser {
        client,
        _driver: driver,
        _profile: profile,
    }
}

async fn js(c: &Client, script: &str) -> Value {
    c.execute(script, vec![]).await.unwrap()
}

/// Waits (at most `limit_s`) until `script` returns true.
async fn wait_js(c: &Client, script: &str, limit_s: f64, what: &str) {
    let started = Instant::now();
    loop {
        if js(c, script).await == Value::Bool(true) {
            return;
        }
        if started.elapsed().as_secs_f64() > limit_s {
            let state = js(c, "return JSON.stringify(window.twindrive && window.twindrive.S.state && window.twindrive.S.state.robots)").await;
            let events = js(c, "return document.getElementById('events').innerText").await;
            panic!("waited {limit_s} s for {what}; robots: {state}; events: {events}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

async fn shot(c: &Client, name: &str) {
    let png = c.screenshot().await.unwrap();
    std::fs::write(screenshots().join(format!("{name}.png")), png).unwrap();
}

async fn click(c: &Client, id: &str) {
    c.find(Locator::Id(id))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
}

async fn pose(c: &Client) -> [f64; 3] {
    serde_json::from_value(js(c, "return window.twindrive.S.state.twin.pose").await).unwrap()
}

async fn loaded(c: &Client, url: &str) {
    c.goto(url).await.unwrap();
    wait_js(
        c,
        "return !!(window.twindrive && window.twindrive.S.connected && window.twindrive.S.state && window.twindrive.S.world)",
        30.0,
        "the page to connect",
    )
    .await;
}

/// Opens the page again (the cookie carries the token) and waits for it.
async fn reload(c: &Client) {
    c.refresh().await.unwrap();
    wait_js(
        c,
        "return !!(window.twindrive && window.twindrive.S.connected && window.twindrive.S.state && window.twindrive.S.world)",
        30.0,
        "the page to connect again",
    )
    .await;
}

/// The route status (where a goals refusal shows) is right under the row
/// of Show the way and Drive it, in the twin's panel.
async fn beside_the_goals_buttons(c: &Client) {
    let [route, drive, status] =
        rects(c, &["#btn-route", "#btn-drive-route", "#route-status"]).await[..]
    else {
        unreachable!()
    };
    let below = status[1] - route[3].max(drive[3]);
    assert!(
        (0.0..24.0).contains(&below) && status[3] > status[1],
        "the status {status:?} is not right under the buttons {route:?} {drive:?}"
    );
    assert_eq!(
        js(c, "return document.getElementById('twin-panel').contains(document.getElementById('route-status'))").await,
        true
    );
}

/// The text of the element `id`.
async fn text(c: &Client, id: &str) -> String {
    c.find(Locator::Id(id)).await.unwrap().text().await.unwrap()
}

/// The page's state of its (first) robot.
async fn rover(c: &Client) -> Value {
    js(c, "return window.twindrive.S.state.robots[0]").await
}

/// The plan time in a line saying "… 12.3 s into …".
fn plan_time(line: &str) -> f64 {
    let head = &line[..line
        .find(" s into")
        .unwrap_or_else(|| panic!("no plan time in {line:?}"))];
    head.rsplit(' ').next().unwrap().parse().unwrap()
}

/// Draws the map now; what it drew of the robots ({id, pose, color}).
async fn drawn_robots(c: &Client) -> Vec<Value> {
    let v = js(
        c,
        "window.twindrive.map.draw(); return window.twindrive.S.drawn.robots",
    )
    .await;
    v.as_array().unwrap().clone()
}

/// The map's colours as the browser computes them: the legend's entries
/// by their text, the layers by name, the robots just drawn.
async fn map_colours(c: &Client) -> Value {
    js(
        c,
        r#"const { S, map } = window.twindrive;
        const rgb = (c) => { const e = document.createElement('i'); e.style.color = c; document.body.append(e);
          const v = getComputedStyle(e).color; e.remove(); return v; };
        const legend = {};
        for (const e of document.getElementById('legend').children) {
          legend[e.textContent.trim()] = getComputedStyle(e.querySelector('i')).backgroundColor;
        }
        const layers = {};
        for (const [n, l] of map.layers) layers[n] = rgb(l.style.color);
        map.draw();
        return { legend, layers, robots: S.drawn.robots.map((r) => rgb(r.color)) };"#,
    )
    .await
}

/// The uncovered route, the robot and its logs are drawn in the colours
/// the legend gives them, and the uncovered route's differs from the
/// robot's.
fn assert_colours_agree_with_the_legend(colours: &Value) {
    let legend = &colours["legend"];
    let uncovered = legend["uncovered"]
        .as_str()
        .expect("`uncovered` in the legend");
    let robot = legend
        .as_object()
        .unwrap()
        .iter()
        .find(|(k, _)| k.starts_with("robot"))
        .map(|(_, v)| v.as_str().unwrap())
        .unwrap_or_else(|| panic!("the robot in the legend: {colours}"));
    assert_ne!(uncovered, robot, "{colours}");
    let layers = colours["layers"].as_object().unwrap();
    for (name, c) in layers {
        let want = match name.as_str() {
            "uncovered" => uncovered,
            n if n.starts_with("robot:log") => robot,
            _ => continue,
        };
        assert_eq!(c, want, "layer {name}: {colours}");
    }
    for c in colours["robots"].as_array().unwrap() {
        assert_eq!(c, robot, "a robot drawn: {colours}");
    }
}

/// Page rectangles [left, top, right, bottom] by CSS selector.
async fn rects(c: &Client, selectors: &[&str]) -> Vec<[f64; 4]> {
    let v = c
        .execute(
            "return arguments[0].map((q) => { const b = document.querySelector(q).getBoundingClientRect(); \
             return [b.left, b.top, b.right, b.bottom]; })",
            vec![json!(selectors)],
        )
        .await
        .unwrap();
    serde_json::from_value(v).unwrap()
}

fn overlap(a: [f64; 4], b: [f64; 4]) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

/// A raw HTTP/1.1 request to the console; the status code.
fn http_status(port: u16, request: &str) -> u16 {
    let mut stream = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    stream.write_all(request.as_bytes()).unwrap();
    let mut head = [0u8; 12];
    stream.read_exact(&mut head).unwrap();
    std::str::from_utf8(&head[9..12]).unwrap().parse().unwrap()
}

fn token_of(url: &str) -> &str {
    url.split("token=").nth(1).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_needs_its_token_and_its_own_origin() {
    let tmp = tempfile::tempdir().unwrap();
    let http = port();
    let con = console(http, tmp.path(), &[]);
    let token = token_of(&con.url);
    let get = |path: &str, extra: &str| {
        http_status(
            http,
            &format!(
                "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{http}\r\n{extra}Connection: close\r\n\r\n"
            ),
        )
    };
    assert_eq!(get("/", ""), 401);
    assert_eq!(get("/?token=wrong", ""), 401);
    assert_eq!(get("/assets/app.js", ""), 401);
    assert_eq!(get("/api/state", ""), 401);
    assert_eq!(get(&format!("/?token={token}"), ""), 200);
    assert_eq!(
        get("/", &format!("Cookie: twindrive_token={token}\r\n")),
        200
    );
    let upgrade = |origin: &str| {
        get(
            &format!("/ws?token={token}"),
            &format!(
                "Origin: {origin}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
                 Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            ),
        )
    };
    assert_eq!(upgrade("http://evil.example"), 403);
    assert_eq!(upgrade(&format!("http://127.0.0.1:{http}")), 101);

    let b = browser().await;
    let c = &b.client;
    c.goto(&format!("http://127.0.0.1:{http}/")).await.unwrap();
    let body = c.source().await.unwrap();
    assert!(body.contains("Access token needed"), "{body}");
    shot(c, "01_refused_without_token").await;
    loaded(c, &con.url).await;
    // The token left the address bar; the cookie carries it.
    let here = c.current_url().await.unwrap();
    assert!(!here.as_str().contains("token"), "{here}");
    let walls = js(c, "return window.twindrive.S.world.segments.length").await;
    assert!(walls.as_u64().unwrap() >= 4, "{walls}");
    shot(c, "02_loaded").await;
    c.clone().close().await.unwrap();
    drop(con);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keys_and_the_joystick_drive_the_twin_and_it_stops_on_release() {
    let tmp = tempfile::tempdir().unwrap();
    let con = console(port(), tmp.path(), &[]);
    let b = browser().await;
    let c = &b.client;
    loaded(c, &con.url).await;
    c.find(Locator::Id("map"))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    let start = pose(c).await;
    let keys = |a: KeyAction| KeyActions::new("keyboard".into()).then(a);
    c.perform_actions(keys(KeyAction::Down { value: ARROW_UP }))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let moving = pose(c).await;
    shot(c, "03_driving_with_keys").await;
    c.perform_actions(keys(KeyAction::Up { value: ARROW_UP }))
        .await
        .unwrap();
    let dist = |a: [f64; 3], b: [f64; 3]| (a[0] - b[0]).hypot(a[1] - b[1]);
    assert!(dist(start, moving) > 0.1, "{start:?} -> {moving:?}");
    // Released: it stops (the stop, or at worst the dead-man, 0.4 s).
    tokio::time::sleep(Duration::from_millis(700)).await;
    let stopped = pose(c).await;
    tokio::time::sleep(Duration::from_millis(1000)).await;
    let later = pose(c).await;
    assert!(dist(stopped, later) < 1e-6, "{stopped:?} -> {later:?}");
    assert_eq!(
        js(c, "return window.twindrive.S.state.twin.drive").await,
        "idle"
    );

    // The joystick: pushed up, the robot drives; released, it stops.
    let stick = c.find(Locator::Id("joystick")).await.unwrap();
    let mouse = MouseActions::new("mouse".into())
        .then(PointerAction::MoveToElement {
            element: stick.clone(),
            duration: None,
            x: 0.0,
            y: 0.0,
        })
        .then(PointerAction::Down { button: 0 })
        .then(PointerAction::MoveToElement {
            element: stick,
            duration: Some(Duration::from_millis(100)),
            x: 0.0,
            y: -50.0,
        });
    c.perform_actions(mouse).await.unwrap();
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let pushed = pose(c).await;
    assert!(dist(later, pushed) > 0.1, "{later:?} -> {pushed:?}");
    c.perform_actions(MouseActions::new("mouse".into()).then(PointerAction::Up { button: 0 }))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(700)).await;
    let released = pose(c).await;
    tokio::time::sleep(Duration::from_millis(1000)).await;
    assert!(dist(released, pose(c).await) < 1e-6);
    shot(c, "04_stopped_after_release").await;
    c.clone().close().await.unwrap();
}

/// Where the map shows world point (`x`, `y`), in the viewport's pixels.
async fn screen(c: &Client, x: f64, y: f64) -> (f64, f64) {
    let v = c
        .execute(
            "const m = window.twindrive.map; const r = m.canvas.getBoundingClientRect(); \
             const w = m.canvas.width / m.dpr, h = m.canvas.height / m.dpr; \
             return [r.left + w / 2 + (arguments[0] - m.cx) * m.scale, r.top + h / 2 - (arguments[1] - m.cy) * m.scale];",
            vec![json!(x), json!(y)],
        )
        .await
        .unwrap();
    let [px, py]: [f64; 2] = serde_json::from_value(v).unwrap();
    (px.round(), py.round())
}

/// Presses the mouse at world point `from` on the map, moves it to `to`
/// and releases it there (a click when they are the same).
async fn drag_on_map(c: &Client, from: (f64, f64), to: (f64, f64)) {
    let a = screen(c, from.0, from.1).await;
    let b = screen(c, to.0, to.1).await;
    let mouse = MouseActions::new("mouse".into())
        .then(PointerAction::MoveTo {
            duration: None,
            x: a.0,
            y: a.1,
        })
        .then(PointerAction::Down { button: 0 })
        .then(PointerAction::MoveTo {
            duration: Some(Duration::from_millis(100)),
            x: b.0,
            y: b.1,
        })
        .then(PointerAction::Up { button: 0 });
    c.perform_actions(mouse).await.unwrap();
}

/// Runs the twin at 32 times real time.
async fn speed_32(c: &Client) {
    c.find(Locator::Css("#speed option[value='32']"))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    wait_js(
        c,
        "return window.twindrive.S.state.twin.speed === 32",
        10.0,
        "32x",
    )
    .await;
}

/// Records a wall-following rehearsal on the page, makes a plan, verifies it.
async fn rehearse_and_plan(c: &Client) {
    click(c, "btn-wall").await;
    speed_32(c).await;
    click(c, "btn-record").await;
    wait_js(
        c,
        "return window.twindrive.S.state.twin.recording_s > 45",
        30.0,
        "45 s recorded",
    )
    .await;
    click(c, "btn-record").await;
    wait_js(
        c,
        "return window.twindrive.S.state.twin.has_rehearsal",
        10.0,
        "the rehearsal",
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rehearsal_becomes_a_plan_with_its_stages_drawn_and_verified() {
    let tmp = tempfile::tempdir().unwrap();
    let con = console(port(), tmp.path(), &[]);
    let b = browser().await;
    let c = &b.client;
    loaded(c, &con.url).await;
    rehearse_and_plan(c).await;
    click(c, "btn-stop").await;
    // The operator draws the robot's freedom on the map: a keep-out zone
    // dragged as a rectangle in a corner the route keeps away from, a
    // corridor region of 0.45 m clicked corner by corner around where the
    // rehearsal was 10 s in (closed on its first corner), then one of the
    // zone's corners dragged on.
    click(c, "btn-zone").await;
    drag_on_map(c, (0.3, 4.0), (0.9, 4.6)).await;
    let width = c.find(Locator::Id("corridor-width")).await.unwrap();
    width.clear().await.unwrap();
    width.send_keys("0.45").await.unwrap();
    click(c, "btn-corridor").await;
    let mid: [f64; 2] = serde_json::from_value(
        js(c, "const r = window.twindrive.S.rehearsal.track; const i = r.t.findIndex((t) => t >= r.t[0] + 10); return [r.x[i], r.y[i]]").await,
    )
    .unwrap();
    let square = [[mid[0] - 0.3, mid[1] - 0.3], [mid[0] + 0.3, mid[1] + 0.3]];
    for p in [
        (square[0][0], square[0][1]),
        (square[1][0], square[0][1]),
        (square[1][0], square[1][1]),
        (square[0][0], square[1][1]),
        (square[0][0], square[0][1]),
    ] {
        drag_on_map(c, p, p).await;
    }
    drag_on_map(c, (0.9, 4.6), (1.0, 4.7)).await;
    let zones = js(c, "return window.twindrive.S.zones").await;
    let zones = zones.as_array().unwrap();
    assert_eq!(zones.len(), 2, "{zones:?}");
    assert_eq!(zones[0]["kind"], "keep_out");
    assert_eq!(zones[1]["kind"], "corridor");
    assert_eq!(
        zones[1]["polygon"].as_array().unwrap().len(),
        4,
        "{zones:?}"
    );
    let near = |v: &Value, x: f64, y: f64| {
        v.as_array()
            .unwrap()
            .iter()
            .any(|p| (p[0].as_f64().unwrap() - x).hypot(p[1].as_f64().unwrap() - y) < 0.03)
    };
    assert!(
        near(&zones[0]["polygon"], 1.0, 4.7),
        "the corner moved: {zones:?}"
    );
    assert!(!near(&zones[0]["polygon"], 0.9, 4.6), "{zones:?}");
    shot(c, "05a_freedom_drawn").await;
    click(c, "btn-plan").await;
    wait_js(c, "return !!window.twindrive.S.plan", 60.0, "the plan").await;
    // The plan is signed with them: the zone as drawn, the corridor set by
    // the region where the path starts.
    let freedom = js(c, "return window.twindrive.S.plan.freedom").await;
    let zone = &freedom["keep_out"][0];
    assert_eq!(zone["name"], "zone 1", "{zone}");
    assert!(near(&zone["polygon"], 1.0, 4.7), "{zone}");
    let widths = freedom["corridor_half_width_m"].as_array().unwrap();
    assert_eq!(
        widths.len() as u64,
        js(c, "return window.twindrive.S.plan.samples")
            .await
            .as_u64()
            .unwrap()
    );
    let path = js(c, "return window.twindrive.S.plan.plan").await;
    let (xs, ys) = (path["x"].as_array().unwrap(), path["y"].as_array().unwrap());
    let mut inside = 0;
    for ((x, y), w) in xs.iter().zip(ys).zip(widths) {
        let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
        // Clear of the square's edges by more than a pixel's worth.
        let within = |v: f64, lo: f64, hi: f64| v > lo + 0.02 && v < hi - 0.02;
        if within(x, square[0][0], square[1][0]) && within(y, square[0][1], square[1][1]) {
            assert_eq!(w.as_f64().unwrap(), 0.45, "at ({x}, {y})");
            inside += 1;
        }
    }
    assert!(inside > 10, "{inside} plan samples in the region");
    assert!(widths.iter().any(|w| w.as_f64().unwrap() > 0.45));
    let layers = js(c, "return [...window.twindrive.map.layers.keys()]").await;
    for l in ["executed", "plan", "rehearsal", "corridor"] {
        assert!(
            layers.as_array().unwrap().iter().any(|v| v == l),
            "{l} in {layers}"
        );
    }
    let summary = text(c, "plan-summary").await;
    assert!(
        summary.contains("100.00 %") || summary.contains("99."),
        "{summary}"
    );
    let covered = js(c, "return window.twindrive.S.plan.summary.coverage_percent").await;
    assert!(covered.as_f64().unwrap() >= 99.0, "{covered}");
    // The plan document is on disk under its hash.
    let sha = js(c, "return window.twindrive.S.plan.sha256").await;
    let sha = sha.as_str().unwrap();
    let doc = tmp.path().join(format!("plans/{sha}.json"));
    let plan: Value = serde_json::from_slice(&std::fs::read(&doc).unwrap()).unwrap();
    assert_eq!(plan["sha256"], sha);
    assert_eq!(plan["header"]["freedom"]["keep_out"], freedom["keep_out"]);
    shot(c, "05_plan_stages").await;
    click(c, "btn-verify").await;
    wait_js(
        c,
        "return !!window.twindrive.S.verify",
        120.0,
        "the replays",
    )
    .await;
    assert_eq!(
        js(c, "return window.twindrive.S.verify.verdict.passed").await,
        true
    );
    // The time cursor scrubs the rehearsal and the plan together.
    let cursor = c.find(Locator::Id("cursor")).await.unwrap();
    let max = cursor.attr("max").await.unwrap().unwrap();
    assert!(max.parse::<f64>().unwrap() > 40.0, "{max}");
    js(
        c,
        "const c = document.getElementById('cursor'); c.value = 20; c.dispatchEvent(new Event('input')); return true",
    )
    .await;
    shot(c, "06_verified_with_time_cursor").await;
    c.clone().close().await.unwrap();
}

/// A console with a robot over an emulated link; the rehearsal is the
/// fixture's 30 s run.
struct WithRobot {
    _tmp: tempfile::TempDir,
    out: PathBuf,
    robot_state: PathBuf,
    console: Console,
    _robot: Proc,
}

fn with_robot(site: &Path, link: &str) -> WithRobot {
    let f = fixture();
    let tmp = tempfile::tempdir().unwrap();
    let zenoh = port();
    let robot_state = tmp.path().join("robot");
    let robot = robot(site, zenoh, &robot_state);
    let out = tmp.path().join("console");
    let console = console(
        port(),
        &out,
        &[
            "--key",
            s(&f.path("keys/master.key")),
            "--trust-robot",
            s(&f.path("keys/rover.pub")),
            "--link-state",
            s(&tmp.path().join("console-link")),
            "--calibration",
            s(&f.path("calib.json")),
            "--robot",
            "rover",
            "--connect",
            &format!("tcp/127.0.0.1:{zenoh}"),
            "--link",
            link,
            "--rehearsal",
            s(&f.path("wf")),
        ],
    );
    WithRobot {
        _tmp: tmp,
        out,
        robot_state,
        console,
        _robot: robot,
    }
}

async fn plan_and_upload(c: &Client) {
    wait_js(
        c,
        "return window.twindrive.S.state.twin.has_rehearsal",
        10.0,
        "the rehearsal",
    )
    .await;
    click(c, "btn-plan").await;
    wait_js(c, "return !!window.twindrive.S.plan", 60.0, "the plan").await;
    wait_js(
        c,
        "return !document.getElementById('btn-upload').disabled",
        10.0,
        "the upload button",
    )
    .await;
    click(c, "btn-upload").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plan_uploaded_over_a_lossy_link_reaches_100_percent_and_runs() {
    let m = with_robot(
        &repo().join("scenarios/wall_following.toml"),
        "wifi,loss=0.2",
    );
    let b = browser().await;
    let c = &b.client;
    loaded(c, &m.console.url).await;
    // Before any status the robot is not drawn anywhere (never at the
    // origin). Its first status, before any plan ran, says where it
    // believes it is: the site's start, where it is then drawn.
    let r = rover(c).await;
    if r["status"].is_null() {
        assert!(
            drawn_robots(c).await.is_empty(),
            "a robot that has not reported drawn"
        );
    }
    wait_js(
        c,
        "return !!window.twindrive.S.state.robots[0].status",
        60.0,
        "the robot's first status",
    )
    .await;
    let r = rover(c).await;
    let pose = r["status"]["pose"].as_array().unwrap().clone();
    let site = std::fs::read_to_string(repo().join("scenarios/wall_following.toml")).unwrap();
    let start = site
        .lines()
        .find(|l| l.trim_start().starts_with("start"))
        .unwrap();
    for v in &pose[..2] {
        let text = format!("{}", v.as_f64().unwrap());
        assert!(start.contains(&text), "status pose {pose:?}, site {start}");
    }
    let drawn = drawn_robots(c).await;
    assert_eq!(drawn.len(), 1, "{drawn:?}");
    assert_eq!(
        drawn[0]["pose"], r["status"]["pose"],
        "drawn where it reports"
    );
    plan_and_upload(c).await;
    // (On loopback the upload may be whole before a frame shows it midway.)
    wait_js(
        c,
        "return !!window.twindrive.S.state.robots[0].upload",
        60.0,
        "the upload under way",
    )
    .await;
    shot(c, "07_upload_started").await;
    wait_js(
        c,
        "return document.getElementById('upload-text').textContent.startsWith('100 %')",
        120.0,
        "100 % acknowledged",
    )
    .await;
    let up = js(c, "return window.twindrive.S.state.robots[0].upload").await;
    assert_eq!(up["confirmed"], up["chunks"], "{up}");
    assert!(
        up["resent"].as_u64().unwrap() + up["repairs"].as_u64().unwrap() > 0,
        "a lossy link: {up}"
    );
    // Whole, the upload's clock stops: it shows how long it took.
    let took = up["elapsed_s"].as_f64().unwrap();
    assert!(took > 0.0, "{up}");
    let shown = text(c, "upload-text").await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let later = rover(c).await;
    assert_eq!(later["upload"]["elapsed_s"].as_f64(), Some(took), "{later}");
    assert_eq!(text(c, "upload-text").await, shown);
    // Running, the robot is drawn where it reports itself, and the fleet
    // list names its plan.
    let sha = js(c, "return window.twindrive.S.plan.sha256").await;
    let sha = sha.as_str().unwrap().to_owned();
    wait_js(
        c,
        "const r = window.twindrive.S.state.robots[0]; return !!(r.status && r.status.pose && r.plan && r.plan.phase === 'executing')",
        60.0,
        "the plan executing",
    )
    .await;
    // The robot's panel says how long its logs take to come home.
    let status = text(c, "robot-status").await;
    assert!(
        status.contains("log comes home") && status.contains("4 kB per second of plan"),
        "{status}"
    );
    let drawn = drawn_robots(c).await;
    let reported = js(c, "return window.twindrive.S.state.robots[0].status.pose").await;
    assert_eq!(drawn.len(), 1, "{drawn:?}");
    assert_eq!(drawn[0]["id"], "rover");
    assert_eq!(drawn[0]["pose"], reported, "drawn where it reports itself");
    let fleet = text(c, "fleet").await;
    assert!(
        fleet.contains(&sha[..12]),
        "the plan in the fleet list: {fleet}"
    );
    assert_colours_agree_with_the_legend(&map_colours(c).await);
    wait_js(
        c,
        "const r = window.twindrive.S.state.robots[0]; return r.state === 'completed'",
        120.0,
        "the mission to complete",
    )
    .await;
    // The event list tells the upload, the run and the mission's end.
    wait_js(
        c,
        "return document.getElementById('events').innerText.includes('mission over: completed')",
        30.0,
        "the mission's end in the events",
    )
    .await;
    let events = text(c, "events").await;
    for line in [
        "robot rover: upload finished".to_owned(),
        format!("robot rover: executing plan {}", &sha[..12]),
        format!("robot rover: plan {} finished", &sha[..12]),
    ] {
        assert!(events.contains(&line), "{line:?} in {events}");
    }
    shot(c, "08_completed").await;
    // The robot holds the plan byte for byte.
    let ours = std::fs::read(m.out.join(format!("rover/plans/{sha}.json"))).unwrap();
    let theirs = std::fs::read(m.robot_state.join(format!("plans/{sha}.json"))).unwrap();
    assert!(ours == theirs, "the robot's copy differs");
    c.clone().close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_obstacle_the_twin_lacks_raises_the_hand_back_banner() {
    let m = with_robot(&fixture().path("site_box.toml"), "lan");
    let b = browser().await;
    let c = &b.client;
    loaded(c, &m.console.url).await;
    plan_and_upload(c).await;
    wait_js(
        c,
        "return !document.getElementById('banner').hidden",
        120.0,
        "the hand-back banner",
    )
    .await;
    let banner = text(c, "banner-text").await;
    assert!(banner.contains("handed control back"), "{banner}");
    // The banner covers no control: it sits inside the map's pane, clear
    // of the side panel and the legend.
    let [banner_box, aside, pane, legend] =
        rects(c, &["#banner", "aside", "#map-pane", "#legend"]).await[..]
    else {
        unreachable!()
    };
    assert!(!overlap(banner_box, aside), "{banner_box:?} over {aside:?}");
    assert!(
        !overlap(banner_box, legend),
        "{banner_box:?} over {legend:?}"
    );
    assert!(
        banner_box[0] >= pane[0] && banner_box[2] <= pane[2] && banner_box[1] >= pane[1],
        "{banner_box:?} outside the map {pane:?}"
    );
    let r = js(c, "return window.twindrive.S.state.robots[0]").await;
    assert_eq!(r["state"], "awaiting_decision", "{r}");
    // Once the robot's statuses speak of the stopped plan, the panel puts
    // it where the hand-back does.
    wait_js(
        c,
        "const r = window.twindrive.S.state.robots[0]; return !!(r.status && r.status.phase === 'stopped')",
        30.0,
        "a status after the stop",
    )
    .await;
    let at = plan_time(&banner);
    assert!(at > 1.0, "{banner}");
    let status = text(c, "robot-status").await;
    assert_eq!(plan_time(&status), at, "{status} / {banner}");
    let first = js(c, "return window.twindrive.S.plan.sha256").await;
    let first = first.as_str().unwrap()[..12].to_owned();
    assert!(status.contains(&first), "{status}");
    // The event list tells the hand-back with its reason.
    let reason = r["awaiting"]["reason"].as_str().unwrap().replace('_', " ");
    let events = text(c, "events").await;
    assert!(
        events.contains(&format!("robot rover: hand-back: {reason} at ")),
        "{events}"
    );
    assert!(events.contains("waiting for you"), "{events}");
    assert!(
        !r["learnt"].as_array().unwrap().is_empty(),
        "the twin learnt the box: {r}"
    );
    wait_js(
        c,
        "return !!(window.twindrive.S.detail && window.twindrive.S.detail.window)",
        30.0,
        "the hand-back's readings",
    )
    .await;
    shot(c, "09_handback_banner").await;
    // Continue: a continuation is rehearsed on the updated twin and sent.
    click(c, "banner-replan").await;
    wait_js(
        c,
        "return window.twindrive.S.state.robots[0].uploads >= 2",
        60.0,
        "the continuation's upload",
    )
    .await;
    // The fleet list names the continuation, the event list tells it.
    let next = rover(c).await["plan"]["sha256"].as_str().unwrap()[..12].to_owned();
    assert_ne!(next, first);
    let fleet = text(c, "fleet").await;
    assert!(fleet.contains(&next), "{fleet}");
    let events = text(c, "events").await;
    assert!(
        events.contains("robot rover: continuation uploading") && events.contains(&next),
        "{events}"
    );
    shot(c, "10_continuation").await;
    // The mission ends (the continuation completes, or the person ends it
    // at a further hand-back), and the event list says so.
    let started = Instant::now();
    while !text(c, "events")
        .await
        .contains("robot rover: mission over:")
    {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "{}",
            text(c, "events").await
        );
        if js(c, "return !document.getElementById('banner').hidden").await == true {
            click(c, "banner-end").await;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    // The robot's logs come home after the mission is decided: the
    // console's report.json lists each one that arrived.
    let started = Instant::now();
    loop {
        let listed = reports_under(&m.out).into_iter().find_map(|(dir, report)| {
            let logs = report["robot_logs"].as_array()?.clone();
            (!logs.is_empty()).then_some((dir, logs))
        });
        if let Some((dir, logs)) = listed {
            for log in logs {
                let log = dir.join(log.as_str().unwrap());
                assert!(log.join("log.mcap").is_file(), "{}", log.display());
            }
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no report.json under {} lists a robot log",
            m.out.display()
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    c.clone().close().await.unwrap();
}

/// Every report.json under `dir`: its directory and its content.
fn reports_under(dir: &Path) -> Vec<(PathBuf, serde_json::Value)> {
    let mut found = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return found;
    };
    for e in entries.flatten() {
        let path = e.path();
        if path.is_dir() {
            found.extend(reports_under(&path));
        } else if path.file_name().is_some_and(|n| n == "report.json")
            && let Ok(bytes) = std::fs::read(&path)
            && let Ok(report) = serde_json::from_slice(&bytes)
        {
            found.push((dir.to_path_buf(), report));
        }
    }
    found
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_recovers_after_the_console_restarts() {
    let tmp = tempfile::tempdir().unwrap();
    let http = port();
    let first = console(http, tmp.path(), &[]);
    let b = browser().await;
    let c = &b.client;
    loaded(c, &first.url).await;
    let instance = js(c, "return window.twindrive.S.instance").await;
    drop(first);
    wait_js(
        c,
        "return document.getElementById('conn').textContent.includes('reconnecting')",
        20.0,
        "the page to say it lost the console",
    )
    .await;
    shot(c, "11_console_gone").await;
    let second = console(http, tmp.path(), &[]);
    wait_js(
        c,
        "return window.twindrive.S.connected && document.getElementById('conn').textContent === 'reconnected'",
        30.0,
        "the page to reconnect",
    )
    .await;
    wait_js(
        c,
        &format!("return window.twindrive.S.instance !== {instance}"),
        10.0,
        "the new console's state",
    )
    .await;
    shot(c, "12_reconnected").await;
    c.clone().close().await.unwrap();
    drop(second);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn foxglove_clients_get_the_map_the_twin_and_the_robots() {
    use futures::{SinkExt, StreamExt};
    use tokio_tungstenite::tungstenite::Message;
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;

    let tmp = tempfile::tempdir().unwrap();
    let fox = port();
    let _con = console(
        port(),
        tmp.path(),
        &[
            "--foxglove",
            &format!("127.0.0.1:{fox}"),
            "--robot",
            "rover",
            "--key",
            s(&fixture().path("keys/master.key")),
            "--trust-robot",
            s(&fixture().path("keys/rover.pub")),
            "--link-state",
            s(&tmp.path().join("link")),
        ],
    );
    let mut request = format!("ws://127.0.0.1:{fox}/")
        .into_client_request()
        .unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let (mut ws, _) = tokio::time::timeout(
        Duration::from_secs(20),
        tokio_tungstenite::connect_async(request),
    )
    .await
    .expect("connects within 20 s")
    .unwrap();
    // serverInfo, then the channels advertised.
    let mut channels: Vec<Value> = Vec::new();
    let started = Instant::now();
    // /map, /twin/pose, /twin/scan/side_ir, and the robot's two poses.
    while channels.len() < 5 {
        assert!(started.elapsed() < Duration::from_secs(20), "{channels:?}");
        let m = tokio::time::timeout(Duration::from_secs(20), ws.next())
            .await
            .unwrap()
            .unwrap()
            .unwrap();
        if let Message::Text(t) = m {
            let v: Value = serde_json::from_str(&t).unwrap();
            if v["op"] == "advertise" {
                channels.extend(v["channels"].as_array().unwrap().iter().cloned());
            }
        }
    }
    let find = |topic: &str| {
        channels
            .iter()
            .find(|c| c["topic"] == topic)
            .unwrap_or_else(|| panic!("no {topic} in {channels:?}"))
            .clone()
    };
    assert_eq!(find("/map")["schemaName"], "foxglove.SceneUpdate");
    assert_eq!(find("/twin/pose")["schemaName"], "foxglove.PoseInFrame");
    assert_eq!(
        find("/twin/scan/side_ir")["schemaName"],
        "foxglove.LaserScan"
    );
    assert_eq!(
        find("/robots/rover/pose")["schemaName"],
        "foxglove.PoseInFrame"
    );
    assert_eq!(
        find("/robots/rover/predicted")["schemaName"],
        "foxglove.PoseInFrame"
    );
    // Subscribed, the twin's pose and the map arrive (binary message data:
    // opcode 1, then the subscription id).
    let subscribe = json!({"op": "subscribe", "subscriptions": [
        {"id": 7, "channelId": find("/twin/pose")["id"]},
        {"id": 8, "channelId": find("/map")["id"]},
    ]});
    ws.send(Message::Text(subscribe.to_string().into()))
        .await
        .unwrap();
    let mut seen = std::collections::BTreeSet::new();
    let started = Instant::now();
    while seen.len() < 2 {
        assert!(started.elapsed() < Duration::from_secs(20), "only {seen:?}");
        let m = tokio::time::timeout(Duration::from_secs(20), ws.next())
            .await
            .unwrap()
            .unwrap()
            .unwrap();
        if let Message::Binary(b) = m {
            assert_eq!(b[0], 1, "message data");
            let id = u32::from_le_bytes(b[1..5].try_into().unwrap());
            assert!(b.len() > 13, "a payload after the header");
            seen.insert(id);
        }
    }
    assert_eq!(seen.into_iter().collect::<Vec<_>>(), [7, 8]);
}

/// The goal workflow in the page: a goal on a wall is refused with the
/// reason (the blocking cell on the map) beside the goals' buttons and in
/// the event list, and a page opened again shows the same; a keep-out zone
/// that crosses itself is refused by its name; Clear forgets the refusal,
/// on this page and on one opened again; waypoints clicked on the map (the
/// last dragged for its heading) give the way, drawn with its length and
/// clearance, and with "come home" one more stop; the twin drives it
/// recording the rehearsal, which ends at the goal; the plan made from it
/// says the goals it keeps, verifies, goes to the robot and the mission
/// completes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn goals_clicked_on_the_map_become_a_mission_the_robot_completes() {
    let m = with_robot(&repo().join("scenarios/wall_following.toml"), "lan");
    let b = browser().await;
    let c = &b.client;
    loaded(c, &m.console.url).await;
    speed_32(c).await;
    let rev = js(c, "return window.twindrive.S.state.twin.rehearsal_rev").await;
    click(c, "btn-waypoint").await;
    drag_on_map(c, (4.5, 1.5), (4.5, 1.5)).await;
    click(c, "btn-route").await;
    wait_js(
        c,
        "const r = window.twindrive.S.state.route; return !!(r && r.unreachable)",
        10.0,
        "the refusal",
    )
    .await;
    let status = text(c, "route-status").await;
    assert!(
        status.contains("no way: waypoint 1 at (4.50, 1.50)"),
        "{status}"
    );
    beside_the_goals_buttons(c).await;
    wait_js(
        c,
        "return document.getElementById('events').innerText.includes('waypoint 1 at (4.50, 1.50)')",
        5.0,
        "the refusal in the event list",
    )
    .await;
    // A page opened again shows what the console has: the same refusal.
    reload(c).await;
    assert_eq!(text(c, "route-status").await, status);
    assert_eq!(
        js(c, "return window.twindrive.S.waypoints.length").await,
        1,
        "the page takes the goals up"
    );
    // A keep-out zone clicked corner by corner across itself, named
    // "flowers": the goals are refused by the zone's name, not its index.
    click(c, "btn-zone").await;
    for p in [(0.5, 3.5), (1.5, 4.5), (1.5, 3.5), (0.5, 4.5), (0.5, 3.5)] {
        drag_on_map(c, p, p).await;
    }
    js(
        c,
        "const e = document.querySelector('#zones input[data-f=name]'); e.value = 'flowers'; \
         e.dispatchEvent(new Event('change', { bubbles: true })); return true",
    )
    .await;
    click(c, "btn-route").await;
    wait_js(
        c,
        "return document.getElementById('route-status').innerText.includes('flowers')",
        10.0,
        "the zone's refusal",
    )
    .await;
    let status = text(c, "route-status").await;
    assert!(
        status.contains("the outline of the keep-out zone 'flowers': its sides 1 and 3 cross"),
        "{status}"
    );
    assert!(
        !status.contains('`') && !status.contains("keep_out"),
        "{status}"
    );
    beside_the_goals_buttons(c).await;
    js(
        c,
        "document.querySelector('#zones button[data-remove]').click(); return true",
    )
    .await;
    // Clear: the refusal goes, and stays gone on a page opened again.
    click(c, "btn-goals-clear").await;
    wait_js(
        c,
        "const s = window.twindrive.S.state; return !s.route && !s.refusals.goals && \
         document.getElementById('route-status').innerText === ''",
        5.0,
        "the route status cleared",
    )
    .await;
    reload(c).await;
    assert_eq!(text(c, "route-status").await, "");
    assert_eq!(
        js(c, "return window.twindrive.S.state.route").await,
        Value::Null
    );
    click(c, "btn-waypoint").await;
    drag_on_map(c, (1.5, 1.0), (1.5, 1.0)).await;
    drag_on_map(c, (1.1, 2.2), (1.1, 2.6)).await;
    let waypoints = js(c, "return window.twindrive.S.waypoints").await;
    assert_eq!(waypoints.as_array().unwrap().len(), 2, "{waypoints}");
    let heading = waypoints[1]["heading_rad"].as_f64().unwrap();
    assert!(
        (heading - std::f64::consts::FRAC_PI_2).abs() < 0.1,
        "{heading}"
    );
    click(c, "btn-route").await;
    wait_js(
        c,
        "const r = window.twindrive.S.state.route; return !!(r && r.points)",
        10.0,
        "the way",
    )
    .await;
    let status = text(c, "route-status").await;
    assert!(status.starts_with("way: "), "{status}");
    let route = js(c, "return window.twindrive.S.state.route").await;
    assert!(route["min_clearance_m"].as_f64().unwrap() >= 0.1, "{route}");
    assert_eq!(route["waypoints"].as_array().unwrap().len(), 2, "{route}");
    // Come home: the goals say so, and home is one more stop.
    click(c, "goal-home").await;
    click(c, "btn-route").await;
    wait_js(
        c,
        "const r = window.twindrive.S.state.route; return !!(r && r.points && r.goals.return_home)",
        10.0,
        "the way home",
    )
    .await;
    let home = js(c, "return window.twindrive.S.state.route").await;
    assert_eq!(home["waypoints"].as_array().unwrap().len(), 3, "{home}");
    assert!(
        home["length_m"].as_f64().unwrap() > route["length_m"].as_f64().unwrap() + 0.5,
        "{home}"
    );
    click(c, "goal-home").await;
    click(c, "btn-route").await;
    wait_js(
        c,
        "const r = window.twindrive.S.state.route; return !!(r && r.points && !r.goals.return_home)",
        10.0,
        "the way without home",
    )
    .await;
    shot(c, "11_way_to_the_goals").await;
    click(c, "btn-drive-route").await;
    wait_js(
        c,
        &format!(
            "const t = window.twindrive.S.state.twin; return t.rehearsal_rev > {rev} && t.drive === 'idle'"
        ),
        60.0,
        "the rehearsal driven to the goal",
    )
    .await;
    let pose = pose(c).await;
    assert!((pose[0] - 1.1).hypot(pose[1] - 2.2) < 0.05, "{pose:?}");
    click(c, "btn-plan").await;
    wait_js(
        c,
        "const v = window.twindrive.S.state.verdict; return !!(window.twindrive.S.plan && v && v.passed)",
        60.0,
        "a plan that verified",
    )
    .await;
    // The plan says the goals it keeps.
    let kept = text(c, "plan-goals").await;
    assert!(
        kept.contains("waypoint 1 within") && kept.contains("waypoint 2 within"),
        "{kept}"
    );
    wait_js(
        c,
        "return !document.getElementById('btn-upload').disabled",
        10.0,
        "the upload button",
    )
    .await;
    click(c, "btn-upload").await;
    let started = Instant::now();
    while !text(c, "events")
        .await
        .contains("robot rover: mission over: completed")
    {
        assert!(
            started.elapsed() < Duration::from_secs(90),
            "{}",
            text(c, "events").await
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    shot(c, "12_goal_mission_completed").await;
    c.clone().close().await.unwrap();
}

/// Sets the page's viewport (the window less the browser's own) to
/// `width` x `height` CSS pixels.
async fn viewport(c: &Client, width: u32, height: u32) {
    c.set_window_size(width, height).await.unwrap();
    let inner: [f64; 2] =
        serde_json::from_value(js(c, "return [innerWidth, innerHeight]").await).unwrap();
    c.set_window_size(
        width + (width as f64 - inner[0]).max(0.0) as u32,
        height + (height as f64 - inner[1]).max(0.0) as u32,
    )
    .await
    .unwrap();
    wait_js(
        c,
        &format!("return innerWidth === {width} && innerHeight === {height}"),
        10.0,
        &format!("a {width} x {height} viewport"),
    )
    .await;
}

/// Nothing covers the map: the joystick, the legend and the time cursor
/// lie outside the map's canvas and inside the window.
async fn nothing_over_the_map(c: &Client, size: &str) {
    let boxes = rects(c, &["#map", "#joystick", "#legend", "#cursor-bar"]).await;
    let inner: [f64; 2] =
        serde_json::from_value(js(c, "return [innerWidth, innerHeight]").await).unwrap();
    let map = boxes[0];
    assert!(
        map[2] - map[0] > 300.0 && map[3] - map[1] > 300.0,
        "{size}: the map is {map:?}"
    );
    for (name, b) in ["joystick", "legend", "time cursor"]
        .iter()
        .zip(&boxes[1..])
    {
        assert!(
            !overlap(map, *b),
            "{size}: the {name} {b:?} covers the map {map:?}"
        );
        assert!(
            b[0] >= 0.0 && b[1] >= 0.0 && b[2] <= inner[0] + 0.5 && b[3] <= inner[1] + 0.5,
            "{size}: the {name} {b:?} is not all in the window {inner:?}"
        );
    }
}

/// Whether segments ab and cd cross (touching at an end does not count).
fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let side = |o: [f64; 2], p: [f64; 2], q: [f64; 2]| {
        (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])
    };
    side(c, d, a) * side(c, d, b) < 0.0 && side(a, b, c) * side(a, b, d) < 0.0
}

/// The page shows the state the console has, where the operator looks:
/// at 1280 x 800, 1920 x 1080 and 1024 x 768 nothing covers the map; a
/// plan made before a rehearsal and a robot placed on a wall are refused
/// beside their buttons, a corridor narrower than the robot beside the
/// freedom's; on the office's occupancy map, a plan from goals through its
/// door says the goals it keeps, and its corridor (1.5 m wide each side
/// where the rooms are open) is
/// drawn only where its path sees: every spoke of the band the page got
/// starts on the plan's path within its half width and crosses no wall nor
/// ends in an occupied cell, and no occupied cell on screen is drawn in
/// the corridor's colour.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_shows_refusals_beside_their_controls_and_the_corridor_in_free_space() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = repo().join("scenarios/office_drive.toml");
    let con = console(port(), tmp.path(), &["--scenario", s(&scenario)]);
    let b = browser().await;
    let c = &b.client;
    loaded(c, &con.url).await;
    for (w, h) in [(1280, 800), (1920, 1080), (1024, 768)] {
        viewport(c, w, h).await;
        nothing_over_the_map(c, &format!("{w} x {h}")).await;
        shot(c, &format!("13_layout_{w}x{h}")).await;
    }
    viewport(c, 1280, 800).await;

    // Refusals beside the buttons that caused them, and in the event list.
    click(c, "btn-plan").await;
    wait_js(
        c,
        "return document.getElementById('refusal-plan').innerText.includes('record a rehearsal first')",
        10.0,
        "the plan's refusal beside its button",
    )
    .await;
    let [plan_button, plan_refusal] = rects(c, &["#btn-plan", "#refusal-plan"]).await[..] else {
        unreachable!()
    };
    assert!(
        (0.0..24.0).contains(&(plan_refusal[1] - plan_button[3])),
        "{plan_refusal:?} under {plan_button:?}"
    );
    click(c, "btn-place").await;
    drag_on_map(c, (4.5, 5.0), (4.5, 5.0)).await;
    wait_js(
        c,
        "return document.getElementById('refusal-twin').innerText.includes('inside an obstacle')",
        10.0,
        "the placing's refusal in the twin's panel",
    )
    .await;
    let events = text(c, "events").await;
    assert!(
        events.contains("record a rehearsal first") && events.contains("inside an obstacle"),
        "{events}"
    );

    // Through the door, on to the far room: the rehearsal, then the plan.
    speed_32(c).await;
    for (i, (x, y)) in [(2.5, 2.5), (5.0, 2.4), (6.8, 3.5)].iter().enumerate() {
        js(
            c,
            &format!("window.twindrive.S.waypoints.push({{x_m: {x}, y_m: {y}, dwell_s: {}}}); return true", i + 1),
        )
        .await;
    }
    click(c, "btn-drive-route").await;
    wait_js(
        c,
        "const t = window.twindrive.S.state.twin; return t.rehearsal_rev > 0 && t.drive === 'idle'",
        90.0,
        "the rehearsal through the door",
    )
    .await;
    click(c, "btn-plan").await;
    wait_js(c, "return !!window.twindrive.S.plan", 90.0, "the plan").await;
    assert_eq!(
        text(c, "refusal-plan").await,
        "",
        "a plan made clears the refusal"
    );
    // The plan from a goals rehearsal says the goals it keeps.
    let kept = text(c, "plan-goals").await;
    assert!(
        [
            "waypoint 1 within",
            "waypoint 2 within",
            "waypoint 3 within",
            "standing"
        ]
        .iter()
        .all(|w| kept.contains(w)),
        "{kept}"
    );
    let plan = js(c, "return window.twindrive.S.plan").await;
    let world = js(c, "return window.twindrive.S.world").await;
    let col = |k: &str| -> Vec<f64> {
        plan["plan"][k]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (xs, ys) = (col("x"), col("y"));
    let widths: Vec<f64> = plan["freedom"]["corridor_half_width_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        widths.iter().any(|&w| w >= 1.0),
        "a corridor wide enough to reach the walls: {widths:?}"
    );
    let walls: Vec<[f64; 4]> = serde_json::from_value(world["segments"].clone()).unwrap();
    assert!(
        walls.len() > 10,
        "the map's cells as walls: {}",
        walls.len()
    );
    let grid = &world["grid"];
    let (gw, res) = (
        grid["width"].as_u64().unwrap() as i64,
        grid["resolution_m"].as_f64().unwrap(),
    );
    let (gh, origin) = (
        grid["height"].as_u64().unwrap() as i64,
        [
            grid["origin"][0].as_f64().unwrap(),
            grid["origin"][1].as_f64().unwrap(),
        ],
    );
    let cells = grid["cells"].as_str().unwrap().as_bytes();
    let occupied = |p: [f64; 2]| {
        let (col, row) = (
            ((p[0] - origin[0]) / res).floor() as i64,
            ((p[1] - origin[1]) / res).floor() as i64,
        );
        (0..gw).contains(&col) && (0..gh).contains(&row) && cells[(row * gw + col) as usize] == b'1'
    };
    let band: Vec<f64> = plan["freedom"]["corridor_band"]
        .as_array()
        .expect("the corridor's band")
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(band.len() >= 400, "{} numbers in the band", band.len());
    let mut clipped = 0;
    for spoke in band.chunks(4) {
        let (from, to) = ([spoke[0], spoke[1]], [spoke[2], spoke[3]]);
        let length = (to[0] - from[0]).hypot(to[1] - from[1]);
        let from_path = (0..xs.len())
            .any(|i| xs[i] == from[0] && ys[i] == from[1] && length <= widths[i] + 2e-4);
        assert!(
            from_path,
            "the spoke {spoke:?} does not start on the path within its half width"
        );
        // Short of its end by 1 mm (it may end on a wall).
        let t = ((length - 1e-3) / length).max(0.0);
        let short = [
            from[0] + (to[0] - from[0]) * t,
            from[1] + (to[1] - from[1]) * t,
        ];
        for w in &walls {
            assert!(
                !cross(from, short, [w[0], w[1]], [w[2], w[3]]),
                "the spoke {spoke:?} crosses the wall {w:?}"
            );
        }
        assert!(
            !occupied(short),
            "the spoke {spoke:?} ends in an occupied cell"
        );
        let (i, _) = xs
            .iter()
            .enumerate()
            .find(|(i, x)| **x == from[0] && ys[*i] == from[1])
            .unwrap();
        if length < widths[i] - 0.01 {
            clipped += 1;
        }
    }
    assert!(
        clipped > 20,
        "{clipped} spokes cut short by the walls: the walls are within reach"
    );
    // On screen: no occupied cell in the corridor's colour, and the
    // corridor there.
    let drawn = js(
        c,
        r#"const { S, map, COLORS } = window.twindrive;
        map.renderStatic(); map.draw();
        const cv = map.canvas, d = map.dpr, img = cv.getContext('2d').getImageData(0, 0, cv.width, cv.height).data;
        const hex = COLORS.corridor, want = [1, 3, 5].map((k) => parseInt(hex.slice(k, k + 2), 16));
        const is = (k) => Math.abs(img[k] - want[0]) <= 2 && Math.abs(img[k + 1] - want[1]) <= 2 && Math.abs(img[k + 2] - want[2]) <= 2;
        let corridor = 0;
        for (let k = 0; k < img.length; k += 4) if (is(k)) corridor++;
        const g = S.world.grid, w = cv.width / d, h = cv.height / d;
        let cellsOnScreen = 0, covered = [];
        for (let row = 0; row < g.height; row++) for (let col = 0; col < g.width; col++) {
          if (g.cells[row * g.width + col] !== '1') continue;
          const x = g.origin[0] + (col + 0.5) * g.resolution_m, y = g.origin[1] + (row + 0.5) * g.resolution_m;
          const px = Math.round((w / 2 + (x - map.cx) * map.scale) * d), py = Math.round((h / 2 - (y - map.cy) * map.scale) * d);
          if (px < 0 || py < 0 || px >= cv.width || py >= cv.height) continue;
          cellsOnScreen++;
          if (is((py * cv.width + px) * 4)) covered.push([col, row]);
        }
        return { corridor, cellsOnScreen, covered };"#,
    )
    .await;
    assert!(drawn["corridor"].as_u64().unwrap() > 5000, "{drawn}");
    assert!(drawn["cellsOnScreen"].as_u64().unwrap() > 500, "{drawn}");
    assert_eq!(
        drawn["covered"],
        json!([]),
        "occupied cells under the corridor"
    );
    shot(c, "14_corridor_in_free_space").await;

    // A corridor region narrower than the robot: refused beside the
    // freedom's controls, in words.
    let width = c.find(Locator::Id("corridor-width")).await.unwrap();
    width.clear().await.unwrap();
    width.send_keys("0.05").await.unwrap();
    click(c, "btn-corridor").await;
    drag_on_map(c, (2.0, 2.0), (3.0, 3.0)).await;
    click(c, "btn-plan").await;
    wait_js(
        c,
        "return document.getElementById('refusal-freedom').innerText.includes('the half width of corridor region 1')",
        10.0,
        "the freedom's refusal beside it",
    )
    .await;
    let refusal = text(c, "refusal-freedom").await;
    assert!(
        !refusal.contains('`') && !refusal.contains("corridor[0]"),
        "{refusal}"
    );
    let [zones, freedom_refusal] = rects(c, &["#zones", "#refusal-freedom"]).await[..] else {
        unreachable!()
    };
    assert!(
        (0.0..24.0).contains(&(freedom_refusal[1] - zones[3])),
        "{freedom_refusal:?} under the zones {zones:?}"
    );
    shot(c, "15_freedom_refused").await;
    c.clone().close().await.unwrap();
}
