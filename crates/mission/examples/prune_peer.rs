//! The Rust side of `bench/prune_vs_distance_matrix.sh`, and the path
//! generator of `benches/redundancy.rs` (which includes this file).
//!
//! `--write N SEED PATH.csv CONFIG.json`: a wall-following-like path of N
//! samples (see [`wall_following_path`]) as
//! `t_s,x_m,y_m,heading_rad,v_m_s,omega_rad_s`, and the redundancy
//! definition the benchmark uses.
//!
//! `--run PATH.csv CONFIG.json OUT_DIR [--reference] [--repeat R]`: times
//! the fast pinch finder and the whole removal (best of R), and with
//! `--reference` the distance-matrix finder and the removal built on it
//! (once each), checking that they agree. Writes `pinches_fast.txt`
//! (`i j kind` per line) and `kept_fast.txt` (one index per line) to OUT_DIR
//! and prints `key value` lines.

use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_kinematics::Pose;
use twindrive_mission::PathSample;
use twindrive_mission::redundancy::{
    Pinch, PinchKind, RedundancyConfig, TimeWindow, find_pinches, find_pinches_reference,
    remove_redundancy, remove_redundancy_reference,
};

/// Sample spacing of the generated paths.
pub const STEP_M: f64 = 0.02;
const DT_S: f64 = 0.1;

/// A robot following long walls at 2 cm per sample: the proportional
/// controller's wobble, corners turning alternately left and right (so the
/// route never comes back), and now and then a "bump and back up" kink
/// (reverse, turn in place, go on), a stop, or a loop of one or two laps.
pub fn wall_following_path(samples: usize, seed: u64) -> Vec<PathSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(samples + 2_000);
    let (mut x, mut y, mut heading) = (0.0f64, 0.0f64, 0.0f64);
    let mut wall = 0.0f64; // direction of the wall being followed
    let mut phase = 0.0f64;
    let push = |x: f64, y: f64, heading: f64, v: f64, omega: f64, out: &mut Vec<PathSample>| {
        out.push(PathSample {
            t_s: out.len() as f64 * DT_S,
            pose: Pose::new(x, y, heading),
            v_m_s: v,
            omega_rad_s: omega,
        });
    };
    let mut corner_sign = 1.0;
    push(x, y, heading, 0.0, 0.0, &mut out);
    while out.len() < samples {
        match rng.random_range(0..1000) {
            // A corner: the wall turns by 90°.
            0..=1 => {
                wall += corner_sign * std::f64::consts::FRAC_PI_2;
                corner_sign = -corner_sign;
            }
            // Bump and back up: reverse 6-30 cm, turn left in place.
            2 => {
                for _ in 0..rng.random_range(3..15) {
                    x -= STEP_M * heading.cos();
                    y -= STEP_M * heading.sin();
                    push(x, y, heading, -STEP_M / DT_S, 0.0, &mut out);
                }
                let turn = rng.random_range(0.3..1.2);
                let steps = rng.random_range(4..12);
                for _ in 0..steps {
                    heading += turn / steps as f64;
                    push(x, y, heading, 0.0, turn / steps as f64 / DT_S, &mut out);
                }
            }
            // A stop.
            3 => {
                for _ in 0..rng.random_range(5..50) {
                    push(x, y, heading, 0.0, 0.0, &mut out);
                }
            }
            // A loop of one or two laps, radius 0.2-1 m, either way round.
            4 if rng.random_range(0..3) == 0 => {
                let radius = rng.random_range(0.2..1.0);
                let laps = rng.random_range(1..=2) as f64;
                let sign = if rng.random_range(0..2) == 0 {
                    1.0
                } else {
                    -1.0
                };
                let steps = (laps * std::f64::consts::TAU * radius / STEP_M).round() as usize;
                let dh = sign * laps * std::f64::consts::TAU / steps as f64;
                for _ in 0..steps {
                    x += STEP_M * (heading + dh / 2.0).cos();
                    y += STEP_M * (heading + dh / 2.0).sin();
                    heading += dh;
                    push(x, y, heading, STEP_M / DT_S, dh / DT_S, &mut out);
                }
            }
            // Follow the wall: steer back towards it, with a wobble.
            _ => {
                phase += rng.random_range(0.02..0.06);
                let target = wall + 0.15 * phase.sin();
                let error = (target - heading + std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                let dh = (0.1 * error).clamp(-0.05, 0.05) + rng.random_range(-0.005..0.005);
                x += STEP_M * (heading + dh / 2.0).cos();
                y += STEP_M * (heading + dh / 2.0).sin();
                heading += dh;
                push(x, y, heading, STEP_M / DT_S, dh / DT_S, &mut out);
            }
        }
    }
    out.truncate(samples);
    out
}

/// The benchmark's definition of redundancy: 10 cm pinch distance (five
/// samples), defaults otherwise, and two kept time windows.
pub fn bench_config(path: &[PathSample]) -> RedundancyConfig {
    let mut cfg = RedundancyConfig::with_pinch_distance(0.1);
    let t_end = path.last().map_or(0.0, |s| s.t_s);
    for f in [0.3, 0.7] {
        cfg.keep_windows.push(TimeWindow {
            start_s: f * t_end,
            end_s: f * t_end + 60.0,
        });
    }
    cfg
}

fn write_path(path: &[PathSample], file: &Path) -> std::io::Result<()> {
    let mut out = BufWriter::new(std::fs::File::create(file)?);
    writeln!(out, "t_s,x_m,y_m,heading_rad,v_m_s,omega_rad_s")?;
    for s in path {
        writeln!(
            out,
            "{},{},{},{},{},{}",
            s.t_s, s.pose.x_m, s.pose.y_m, s.pose.heading_rad, s.v_m_s, s.omega_rad_s
        )?;
    }
    out.flush()
}

fn read_path(file: &Path) -> Result<Vec<PathSample>, String> {
    let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
    text.lines()
        .skip(1)
        .enumerate()
        .map(|(k, line)| {
            let v: Vec<f64> = line
                .split(',')
                .map(str::parse)
                .collect::<Result<_, _>>()
                .map_err(|e| format!("line {}: {e}", k + 2))?;
            let [t_s, x, y, h, v_m_s, omega_rad_s] = v[..] else {
                return Err(format!("line {}: expected 6 fields", k + 2));
            };
            Ok(PathSample {
                t_s,
                pose: Pose::new(x, y, h),
                v_m_s,
                omega_rad_s,
            })
        })
        .collect()
}

fn write_pinches(pinches: &[Pinch], file: &Path) -> std::io::Result<()> {
    let mut out = BufWriter::new(std::fs::File::create(file)?);
    for p in pinches {
        let kind = match p.kind {
            PinchKind::Near => "near",
            PinchKind::Crossing => "crossing",
        };
        writeln!(out, "{} {} {kind}", p.i, p.j)?;
    }
    out.flush()
}

fn write_indices(kept: &[usize], file: &Path) -> std::io::Result<()> {
    let mut out = BufWriter::new(std::fs::File::create(file)?);
    for k in kept {
        writeln!(out, "{k}")?;
    }
    out.flush()
}

/// Best wall-clock time of `repeat` runs, in seconds, and the last result.
fn best_of<T>(repeat: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        let r = f();
        best = best.min(start.elapsed().as_secs_f64());
        last = Some(r);
    }
    (best, last.expect("ran at least once"))
}

fn run(args: &[String]) -> Result<(), String> {
    match args {
        [flag, n, seed, csv, json] if flag == "--write" => {
            let n: usize = n.parse().map_err(|e| format!("N: {e}"))?;
            let seed: u64 = seed.parse().map_err(|e| format!("SEED: {e}"))?;
            let path = wall_following_path(n, seed);
            write_path(&path, Path::new(csv)).map_err(|e| e.to_string())?;
            let cfg =
                serde_json::to_string_pretty(&bench_config(&path)).map_err(|e| e.to_string())?;
            std::fs::write(json, cfg).map_err(|e| e.to_string())
        }
        [flag, csv, json, out_dir, rest @ ..] if flag == "--run" => {
            let reference = rest.iter().any(|a| a == "--reference");
            let repeat = match rest.iter().position(|a| a == "--repeat") {
                Some(k) => rest
                    .get(k + 1)
                    .ok_or("--repeat needs a count")?
                    .parse()
                    .map_err(|e| format!("--repeat: {e}"))?,
                None => 20,
            };
            let path = read_path(Path::new(csv))?;
            let text = std::fs::read_to_string(json).map_err(|e| format!("{json}: {e}"))?;
            let cfg: RedundancyConfig =
                serde_json::from_str(&text).map_err(|e| format!("{json}: {e}"))?;
            let out = Path::new(out_dir);

            let (t_find, pinches) = best_of(repeat, || find_pinches(&path, &cfg));
            let pinches = pinches.map_err(|e| e.to_string())?;
            let (t_remove, pruned) = best_of(repeat, || remove_redundancy(&path, &cfg));
            let pruned = pruned.map_err(|e| e.to_string())?;
            write_pinches(&pinches, &out.join("pinches_fast.txt")).map_err(|e| e.to_string())?;
            write_indices(&pruned.kept, &out.join("kept_fast.txt")).map_err(|e| e.to_string())?;
            println!("samples {}", path.len());
            println!("pinches {}", pinches.len());
            println!("kept {}", pruned.kept.len());
            println!("deletions {}", pruned.deletions.len());
            println!("fast_find_s {t_find:.6e}");
            println!("fast_remove_s {t_remove:.6e}");
            if reference {
                let (t_ref_find, ref_pinches) = best_of(1, || find_pinches_reference(&path, &cfg));
                let ref_pinches = ref_pinches.map_err(|e| e.to_string())?;
                if ref_pinches != pinches {
                    return Err("the reference finder disagrees with the fast one".into());
                }
                let (t_ref_remove, ref_pruned) =
                    best_of(1, || remove_redundancy_reference(&path, &cfg));
                if ref_pruned.map_err(|e| e.to_string())? != pruned {
                    return Err("the reference removal disagrees with the fast one".into());
                }
                println!("reference_find_s {t_ref_find:.6e}");
                println!("reference_remove_s {t_ref_remove:.6e}");
            }
            Ok(())
        }
        _ => Err("usage: prune_peer --write N SEED PATH.csv CONFIG.json | \
                  --run PATH.csv CONFIG.json OUT_DIR [--reference] [--repeat R]"
            .into()),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Err(e) = run(&args) {
        eprintln!("prune_peer: {e}");
        std::process::exit(2);
    }
}
