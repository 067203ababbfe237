//! Running the built binary from the integration tests (each test file
//! includes this module and uses what it needs).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output};

/// The repository root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Runs `twindrive ARGS` in `cwd`.
pub fn twindrive_in(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twindrive"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("twindrive runs")
}

/// Runs `twindrive ARGS` in the repository root.
pub fn twindrive(args: &[&str]) -> Output {
    twindrive_in(args, &repo())
}

/// A fixture built once per build of the binary and shared by every test
/// process (nextest runs each test in its own, and a `TempDir` in a
/// `static` is never dropped: each process would leave its copy behind).
/// It lives in cargo's scratch directory for tests (under `target/`),
/// named `name` and the binary's build time; `build` fills a staging
/// directory that is renamed into place when complete, so a process never
/// sees half a fixture. Earlier builds' copies are removed.
pub fn shared_fixture(name: &str, build: impl FnOnce(&Path)) -> PathBuf {
    let scratch = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let built = std::fs::metadata(env!("CARGO_BIN_EXE_twindrive"))
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    let dir = scratch.join(format!("{name}-{built}"));
    if dir.join(".complete").exists() {
        return dir;
    }
    std::fs::create_dir_all(scratch).unwrap();
    if let Ok(entries) = std::fs::read_dir(scratch) {
        for e in entries.flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            if n.starts_with(&format!("{name}-")) && e.path() != dir {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    }
    let staging = tempfile::tempdir_in(scratch).unwrap();
    build(staging.path());
    std::fs::write(staging.path().join(".complete"), "").unwrap();
    let staged = staging.keep();
    if std::fs::rename(&staged, &dir).is_err() {
        // Another process finished first: use its copy.
        let _ = std::fs::remove_dir_all(&staged);
    }
    assert!(dir.join(".complete").exists(), "{}", dir.display());
    dir
}

/// Process output as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A child process killed (by pid) when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Waits for `p` to exit (bounded: a test fails rather than hangs); its
/// exit code and stderr.
pub fn finish(mut p: Proc, limit_s: f64) -> (Option<i32>, String) {
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = p.0.try_wait().unwrap() {
            let mut err = String::new();
            if let Some(mut e) = p.0.stderr.take() {
                use std::io::Read;
                let _ = e.read_to_string(&mut err);
            }
            return (status.code(), err);
        }
        assert!(
            start.elapsed().as_secs_f64() < limit_s,
            "the process did not finish in {limit_s} s"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// The true [left diameter, right diameter, wheelbase] (m) of the built-in
/// scenarios' robot.
pub const TRUTH: [f64; 3] = [0.0652, 0.0665, 0.2678];

/// `calibrate`'s noise settings for the simulator's tracker and encoders.
pub const SIM_NOISE: [&str; 6] = [
    "--position-std-m",
    "0.001",
    "--heading-std-rad",
    "0.002",
    "--wheel-noise",
    "1e-6",
];

/// A free loopback port.
pub fn port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A box on the case study's route that the twin lacks.
pub const BOX: &str = "rectangles = [{ min = [1.9, 0.9], max = [2.1, 1.2] }]";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Made once per test binary: a 30 s case-study run (`wf/`), its
/// calibration (`calib.json`), a plan from them (`plan/plan.json`), two
/// sets of keys (`keys/`, `other/`: a master's, `master.key`, and robots
/// `rover`, `r1`, `r2` and `tb1`'s, `ID.key`) and a site with a box the twin
/// lacks (`site_box.toml`).
pub struct Fixture {
    dir: tempfile::TempDir,
}

pub fn fixture() -> &'static Fixture {
    static F: std::sync::OnceLock<Fixture> = std::sync::OnceLock::new();
    F.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let out = twindrive(&[
            "simulate",
            "scenarios/wall_following.toml",
            "--duration-s",
            "30",
            "--out",
            s(&d.join("wf")),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        std::fs::write(
            d.join("calib.json"),
            r#"{"left_diameter_m": 0.0652, "right_diameter_m": 0.0665, "wheelbase_m": 0.2678}"#,
        )
        .unwrap();
        let out = twindrive(&[
            "plan",
            s(&d.join("wf")),
            "--calibration",
            s(&d.join("calib.json")),
            "--out",
            s(&d.join("plan/plan.json")),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        for k in ["keys", "other"] {
            let out = twindrive(&["keygen", "--out", s(&d.join(k))]);
            assert!(out.status.success(), "{}", text(&out.stderr));
            for robot in ["rover", "r1", "r2", "tb1"] {
                let out = twindrive(&["keygen", "--out", s(&d.join(k)), "--robot", robot]);
                assert!(out.status.success(), "{}", text(&out.stderr));
            }
        }
        let site = std::fs::read_to_string(repo().join("scenarios/wall_following.toml")).unwrap();
        std::fs::write(
            d.join("site_box.toml"),
            site.replace("[world]\n", &format!("[world]\n{BOX}\n")),
        )
        .unwrap();
        Fixture { dir }
    })
}

impl Fixture {
    pub fn path(&self, p: &str) -> PathBuf {
        self.dir.path().join(p)
    }
}

/// The venv's python with the pinned peers, `eclipse-zenoh` among them
/// (installs them once).
pub fn python() -> &'static Path {
    static P: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    P.get_or_init(|| {
        let o = Command::new("bash")
            .arg(repo().join("scripts/ros-deps.sh"))
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "scripts/ros-deps.sh failed (it needs python3 with venv and pip, and network access to PyPI once):\n{}",
            text(&o.stderr)
        );
        PathBuf::from(text(&o.stdout).trim())
    })
}
