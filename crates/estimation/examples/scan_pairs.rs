//! The twindrive side of `bench/scan_match_vs_open3d.sh`: scan-to-scan
//! matching (laser odometry) on pairs of 360-beam scans.
//!
//! `--write FILE [--pairs N] [--seed S]`: N pairs from random rooms (4-12 m
//! a side, 3-8 boxes and a few loose walls), each scan cast by the
//! simulator's world with 1-3 cm of range noise, 1 % dropouts and an 8-12 m
//! range (a reading at the maximum is no return); the second view moved by
//! up to 0.3 m and 20 degrees, the prior off the true motion by up to 5 cm
//! and 3 degrees. Little-endian binary, per pair: truth and prior (x, y, θ
//! as f64), then two scans, each `angle_min, increment, range_min,
//! range_max` (f64), `beams` (u32) and the ranges (f32).
//! `--run FILE [--repeat R]`: matches every pair R times on one thread
//! (building the reference from the first scan is part of the time) and
//! prints `pairs`, `us_per_pair`, `rmse_xy_m`, `rmse_theta_rad`, `refused`.
//! A refused pair keeps its prior (what laser odometry falls back to), so
//! refusals count in the errors.

use std::io::{Read, Write};
use std::path::Path;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use twindrive_estimation::localize::{MatchSettings, Scan, ScanReference, register};
use twindrive_sim::{Vector, World};

const BEAMS: usize = 360;

struct Pair {
    truth: [f64; 3],
    prior: [f64; 3],
    reference: Scan,
    current: Scan,
}

fn compose(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    let (s, c) = a[2].sin_cos();
    [
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        a[2] + b[2],
    ]
}

fn site(rng: &mut ChaCha8Rng) -> (Vec<[f64; 4]>, [f64; 2]) {
    let (w, h) = (rng.random_range(4.0..12.0), rng.random_range(4.0..12.0));
    let mut walls = vec![
        [0.0, 0.0, w, 0.0],
        [w, 0.0, w, h],
        [w, h, 0.0, h],
        [0.0, h, 0.0, 0.0],
    ];
    for _ in 0..rng.random_range(3..9) {
        let (x, y) = (
            rng.random_range(0.3..w - 0.8),
            rng.random_range(0.3..h - 0.8),
        );
        let (bw, bh) = (rng.random_range(0.2..0.8), rng.random_range(0.2..0.8));
        walls.extend([
            [x, y, x + bw, y],
            [x + bw, y, x + bw, y + bh],
            [x + bw, y + bh, x, y + bh],
            [x, y + bh, x, y],
        ]);
    }
    for _ in 0..rng.random_range(0..3) {
        let (x, y) = (
            rng.random_range(0.5..w - 0.5),
            rng.random_range(0.5..h - 0.5),
        );
        let a = rng.random_range(0.0..std::f64::consts::PI);
        let l = rng.random_range(0.5..2.0);
        walls.push([x, y, x + l * a.cos(), y + l * a.sin()]);
    }
    (walls, [w, h])
}

fn cast(world: &World, pose: [f64; 3], noise_m: f64, max_m: f64, rng: &mut ChaCha8Rng) -> Scan {
    let noise = Normal::new(0.0, noise_m).expect("a valid spread");
    let increment_rad = std::f64::consts::TAU / BEAMS as f64;
    let angle_min_rad = -std::f64::consts::PI;
    let ranges_m = (0..BEAMS)
        .map(|i| {
            let a = pose[2] + angle_min_rad + i as f64 * increment_rad;
            let r = world.cast_ray(
                Vector::new(pose[0], pose[1]),
                Vector::new(a.cos(), a.sin()),
                max_m,
            );
            let noisy = r + noise.sample(rng);
            let dropout = rng.random::<f64>() < 0.01;
            if r >= max_m || dropout || noisy >= max_m {
                max_m as f32
            } else {
                noisy as f32
            }
        })
        .collect();
    Scan {
        t_s: 0.0,
        angle_min_rad,
        increment_rad,
        range_min_m: 0.05,
        range_max_m: max_m,
        ranges_m,
    }
}

fn generate(pairs: usize, seed: u64) -> Vec<Pair> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(pairs);
    while out.len() < pairs {
        let (walls, [w, h]) = site(&mut rng);
        let world = World::from_walls(&walls, &[]);
        let from = [
            rng.random_range(0.3..w - 0.3),
            rng.random_range(0.3..h - 0.3),
            rng.random_range(-3.1..3.1),
        ];
        let truth = [
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.1..0.1),
            rng.random_range(-0.35..0.35),
        ];
        let to = compose(from, truth);
        if world.clearance_m(from[0], from[1], 1.0) < 0.3
            || world.clearance_m(to[0], to[1], 1.0) < 0.3
            || !(0.0..w).contains(&to[0])
            || !(0.0..h).contains(&to[1])
        {
            continue;
        }
        let prior = [
            truth[0] + rng.random_range(-0.05..0.05),
            truth[1] + rng.random_range(-0.05..0.05),
            truth[2] + rng.random_range(-3f64.to_radians()..3f64.to_radians()),
        ];
        let noise_m = rng.random_range(0.01..0.03);
        let max_m = rng.random_range(8.0..12.0);
        let reference = cast(&world, from, noise_m, max_m, &mut rng);
        let current = cast(&world, to, noise_m, max_m, &mut rng);
        out.push(Pair {
            truth,
            prior,
            reference,
            current,
        });
    }
    out
}

fn write(path: &Path, pairs: &[Pair]) -> std::io::Result<()> {
    let mut out = Vec::new();
    out.extend((pairs.len() as u32).to_le_bytes());
    for p in pairs {
        for v in p.truth.iter().chain(&p.prior) {
            out.extend(v.to_le_bytes());
        }
        for s in [&p.reference, &p.current] {
            for v in [
                s.angle_min_rad,
                s.increment_rad,
                s.range_min_m,
                s.range_max_m,
            ] {
                out.extend(v.to_le_bytes());
            }
            out.extend((s.ranges_m.len() as u32).to_le_bytes());
            for r in &s.ranges_m {
                out.extend(r.to_le_bytes());
            }
        }
    }
    let tmp = path.with_extension("tmp");
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(&out)?;
    f.sync_all()?;
    std::fs::rename(tmp, path)
}

struct Reader {
    bytes: Vec<u8>,
    at: usize,
}

impl Reader {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let end = self.at + N;
        let b = self.bytes.get(self.at..end).ok_or_else(|| {
            format!(
                "the pair file ends at byte {}, inside a record",
                self.bytes.len()
            )
        })?;
        self.at = end;
        Ok(b.try_into().expect("N bytes"))
    }
    fn f64(&mut self) -> Result<f64, String> {
        self.take::<8>().map(f64::from_le_bytes)
    }
    fn u32(&mut self) -> Result<u32, String> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    fn scan(&mut self) -> Result<Scan, String> {
        let [angle_min_rad, increment_rad, range_min_m, range_max_m] =
            [self.f64()?, self.f64()?, self.f64()?, self.f64()?];
        let beams = self.u32()? as usize;
        let ranges_m = (0..beams)
            .map(|_| self.take::<4>().map(f32::from_le_bytes))
            .collect::<Result<_, _>>()?;
        Ok(Scan {
            t_s: 0.0,
            angle_min_rad,
            increment_rad,
            range_min_m,
            range_max_m,
            ranges_m,
        })
    }
}

fn read(path: &Path) -> Result<Vec<Pair>, String> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let mut r = Reader { bytes, at: 0 };
    let n = r.u32()?;
    (0..n)
        .map(|_| {
            let truth = [r.f64()?, r.f64()?, r.f64()?];
            let prior = [r.f64()?, r.f64()?, r.f64()?];
            Ok(Pair {
                truth,
                prior,
                reference: r.scan()?,
                current: r.scan()?,
            })
        })
        .collect::<Result<_, String>>()
        .map_err(|e| format!("{}: {e}", path.display()))
}

fn run(pairs: &[Pair], repeat: usize) {
    let settings = MatchSettings::scan_to_scan();
    let points: Vec<Vec<[f64; 2]>> = pairs.iter().map(|p| p.current.points()).collect();
    let mut poses = vec![[0.0; 3]; pairs.len()];
    let mut refused = 0;
    let start = Instant::now();
    for round in 0..repeat.max(1) {
        for (k, (p, pts)) in pairs.iter().zip(&points).enumerate() {
            let reference = ScanReference::new(&p.reference, settings.outlier_m + 0.2);
            let m = register(&reference, pts, p.prior, &settings);
            if round == 0 {
                match m {
                    Ok(m) => poses[k] = m.pose,
                    Err(_) => {
                        poses[k] = p.prior;
                        refused += 1;
                    }
                }
            } else {
                std::hint::black_box(m.ok());
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let (mut sxy, mut sth) = (0.0, 0.0);
    for (p, pose) in pairs.iter().zip(&poses) {
        sxy += (pose[0] - p.truth[0]).powi(2) + (pose[1] - p.truth[1]).powi(2);
        sth += twindrive_kinematics::wrap_angle(pose[2] - p.truth[2]).powi(2);
    }
    let n = pairs.len().max(1) as f64;
    println!("pairs {}", pairs.len());
    println!(
        "us_per_pair {:.2}",
        seconds * 1e6 / (n * repeat.max(1) as f64)
    );
    println!("rmse_xy_m {:.6}", (sxy / n).sqrt());
    println!("rmse_theta_rad {:.6}", (sth / n).sqrt());
    println!("refused {refused}");
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let usage = || -> ! {
        eprintln!(
            "usage: scan_pairs --write FILE [--pairs N] [--seed S] | --run FILE [--repeat R]"
        );
        std::process::exit(2)
    };
    let number = |flag: &str, default: u64| match value(flag) {
        None => default,
        Some(v) => v.parse().unwrap_or_else(|_| {
            eprintln!("{flag}: expected a whole number, got {v:?}");
            std::process::exit(2)
        }),
    };
    if let Some(file) = value("--write") {
        let pairs = generate(number("--pairs", 2000) as usize, number("--seed", 1));
        if let Err(e) = write(Path::new(&file), &pairs) {
            eprintln!("{file}: {e}");
            std::process::exit(1);
        }
    } else if let Some(file) = value("--run") {
        match read(Path::new(&file)) {
            Ok(pairs) => run(&pairs, number("--repeat", 1) as usize),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
    } else {
        usage();
    }
}
