//! Redundancy removal through the public API: the fast pinch finder against
//! the paper's distance-matrix method on random paths, and the shapes the
//! paper cares about (loops, self-crossings, "bump and back up" kinks).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_kinematics::Pose;
use twindrive_mission::PathSample;
use twindrive_mission::redundancy::{
    DeletionReason, KeepRegion, PinchKind, Pruned, RedundancyConfig, RedundancyError, TimeWindow,
    find_pinches, find_pinches_reference, remove_redundancy, remove_redundancy_reference,
    route_coverage,
};

// ---------------------------------------------------------------- helpers

/// A unicycle driven step by step, one sample per step, 10 ms apart.
struct Drive {
    samples: Vec<PathSample>,
}

impl Drive {
    const DT_S: f64 = 0.01;

    fn start(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        Self {
            samples: vec![sample(0.0, x_m, y_m, heading_rad, 0.0)],
        }
    }

    fn last(&self) -> PathSample {
        *self.samples.last().unwrap()
    }

    fn push(&mut self, x_m: f64, y_m: f64, heading_rad: f64, v_m_s: f64, omega_rad_s: f64) {
        let t_s = self.last().t_s + Self::DT_S;
        let mut s = sample(t_s, x_m, y_m, heading_rad, v_m_s);
        s.omega_rad_s = omega_rad_s;
        self.samples.push(s);
    }

    /// Straight ahead (or back, for a negative length) in steps of `step_m`.
    fn straight(&mut self, length_m: f64, step_m: f64) -> &mut Self {
        let steps = (length_m.abs() / step_m).round().max(1.0) as usize;
        let ds = length_m / steps as f64;
        for _ in 0..steps {
            let p = self.last().pose;
            let (s, c) = p.heading_rad.sin_cos();
            self.push(
                p.x_m + ds * c,
                p.y_m + ds * s,
                p.heading_rad,
                ds / Self::DT_S,
                0.0,
            );
        }
        self
    }

    /// Along a circle of `radius_m`, turning by `angle_rad` (> 0: left).
    fn arc(&mut self, radius_m: f64, angle_rad: f64, step_m: f64) -> &mut Self {
        let steps = (radius_m * angle_rad.abs() / step_m).round().max(1.0) as usize;
        let dh = angle_rad / steps as f64;
        let chord = 2.0 * radius_m * (dh.abs() / 2.0).sin();
        for _ in 0..steps {
            let p = self.last().pose;
            let mid = p.heading_rad + dh / 2.0;
            self.push(
                p.x_m + chord * mid.cos(),
                p.y_m + chord * mid.sin(),
                p.heading_rad + dh,
                radius_m * dh.abs() / Self::DT_S,
                dh / Self::DT_S,
            );
        }
        self
    }

    /// Turn in place (the position does not change).
    fn turn(&mut self, angle_rad: f64, steps: usize) -> &mut Self {
        for _ in 0..steps {
            let p = self.last().pose;
            let dh = angle_rad / steps as f64;
            self.push(p.x_m, p.y_m, p.heading_rad + dh, 0.0, dh / Self::DT_S);
        }
        self
    }

    fn stay(&mut self, steps: usize) -> &mut Self {
        for _ in 0..steps {
            let p = self.last().pose;
            self.push(p.x_m, p.y_m, p.heading_rad, 0.0, 0.0);
        }
        self
    }

    fn path(&self) -> Vec<PathSample> {
        self.samples.clone()
    }
}

fn sample(t_s: f64, x_m: f64, y_m: f64, heading_rad: f64, v_m_s: f64) -> PathSample {
    PathSample {
        t_s,
        pose: Pose::new(x_m, y_m, heading_rad),
        v_m_s,
        omega_rad_s: 0.0,
    }
}

/// Samples through the given points, driven forward, `dt_s` apart.
fn through(points: &[[f64; 2]], dt_s: f64) -> Vec<PathSample> {
    points
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let next = points.get(k + 1).unwrap_or(p);
            let (dx, dy) = (next[0] - p[0], next[1] - p[1]);
            sample(
                k as f64 * dt_s,
                p[0],
                p[1],
                dy.atan2(dx),
                dx.hypot(dy) / dt_s,
            )
        })
        .collect()
}

fn cfg(pinch_distance_m: f64) -> RedundancyConfig {
    RedundancyConfig::with_pinch_distance(pinch_distance_m)
}

fn deleted(pruned: &Pruned, n: usize) -> Vec<bool> {
    let mut gone = vec![true; n];
    for &k in &pruned.kept {
        gone[k] = false;
    }
    gone
}

/// Everything a pruning result must satisfy, whatever the path.
fn check_invariants(path: &[PathSample], cfg: &RedundancyConfig, pruned: &Pruned, what: &str) {
    let n = path.len();
    let kept = &pruned.kept;
    assert!(
        kept.windows(2).all(|w| w[0] < w[1]),
        "{what}: kept not increasing"
    );
    if n > 0 {
        assert_eq!(kept.first(), Some(&0), "{what}: first sample lost");
        if cfg.keep_end {
            assert_eq!(kept.last(), Some(&(n - 1)), "{what}: last sample lost");
        }
    }
    let gone = deleted(pruned, n);
    for (k, s) in path.iter().enumerate() {
        let protected =
            cfg.keeps(s.position(), s.t_s) || (!cfg.reversing_is_redundant && s.v_m_s < 0.0);
        assert!(
            !protected || !gone[k],
            "{what}: protected sample {k} deleted"
        );
    }
    // Deletions: sorted, disjoint, and exactly the samples not kept.
    let mut in_deletion = vec![false; n];
    let cum = cumulative(path);
    for (a, d) in pruned.deletions.iter().enumerate() {
        assert!(
            d.first_removed >= 1 && d.first_removed <= d.last_removed,
            "{what}: {d:?}"
        );
        if a > 0 {
            assert!(
                pruned.deletions[a - 1].last_removed < d.first_removed,
                "{what}: overlap"
            );
        }
        for c in &mut in_deletion[d.first_removed..=d.last_removed] {
            *c = true;
        }
        assert_eq!(d.uncovered_m, 0.0, "{what}: {d:?}");
        assert_eq!(d.t_start_s, path[d.first_removed - 1].t_s, "{what}");
        let end = if d.reason == DeletionReason::TrailingRetrace {
            assert_eq!(
                d.last_removed,
                n - 1,
                "{what}: a trailing retrace ends the path"
            );
            assert!(!cfg.keep_end, "{what}: trailing retrace with keep_end");
            n - 1
        } else {
            d.last_removed + 1
        };
        assert_eq!(d.t_end_s, path[end].t_s, "{what}");
        let length = cum[end] - cum[d.first_removed - 1];
        assert!(
            (d.length_m - length).abs() <= 1e-9 * (1.0 + length),
            "{what}: {d:?}"
        );
    }
    assert_eq!(
        in_deletion, gone,
        "{what}: deletions do not match the kept samples"
    );
    // Coverage: every deleted sample within the radius of the kept path
    // (segments between samples kept side by side, and kept samples).
    let r = cfg.effective_coverage_radius_m();
    assert_eq!(pruned.coverage_radius_m, r, "{what}");
    let pieces: Vec<([f64; 2], [f64; 2])> = kept
        .iter()
        .map(|&k| {
            let p = path[k].position();
            match kept.binary_search(&(k + 1)) {
                Ok(_) => (p, path[k + 1].position()),
                Err(_) => (p, p),
            }
        })
        .collect();
    for k in (0..n).filter(|&k| gone[k]) {
        let s = path[k].position();
        let nearest = pieces
            .iter()
            .map(|&(p, q)| point_segment_distance(s, p, q))
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest <= r * (1.0 + 1e-9),
            "{what}: deleted sample {k} at {s:?} is {nearest} m from the kept path (radius {r})"
        );
    }
    for c in &pruned.refused {
        assert!(c.would_drop_m > 0.0 && c.i < c.j, "{what}: {c:?}");
    }
}

/// Distance from `s` to the segment `p q`, written independently of the
/// library's predicate.
fn point_segment_distance(s: [f64; 2], p: [f64; 2], q: [f64; 2]) -> f64 {
    let d = [q[0] - p[0], q[1] - p[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 {
        (((s[0] - p[0]) * d[0] + (s[1] - p[1]) * d[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (s[0] - p[0] - t * d[0]).hypot(s[1] - p[1] - t * d[1])
}

/// Percent of the path's length within the radius of what was kept.
fn coverage_percent(path: &[PathSample], pruned: &Pruned) -> f64 {
    route_coverage(path, &pruned.apply(path), pruned.coverage_radius_m)
        .unwrap()
        .covered_percent
}

fn cumulative(path: &[PathSample]) -> Vec<f64> {
    let mut total = 0.0;
    let mut cum = vec![0.0; path.len()];
    for k in 1..path.len() {
        total += path[k - 1].pose.distance_to(&path[k].pose);
        cum[k] = total;
    }
    cum
}

// ------------------------------------------------------- random paths

/// Wandering with loops, kinks, stops and turns in place.
fn random_drive(rng: &mut ChaCha8Rng, samples: usize) -> Vec<PathSample> {
    let step = rng.random_range(0.005..0.03);
    let mut d = Drive::start(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        0.0,
    );
    while d.samples.len() < samples {
        match rng.random_range(0..10) {
            0..=2 => d.straight(rng.random_range(0.05..0.6), step),
            3..=4 => d.arc(rng.random_range(0.05..0.5), rng.random_range(-PI..PI), step),
            5 => d.arc(
                rng.random_range(0.05..0.3),
                TAU * rng.random_range(0.8..2.2),
                step,
            ),
            6 => d.straight(-rng.random_range(0.02..0.3), step),
            7 => d.turn(rng.random_range(-PI..PI), rng.random_range(1..20)),
            8 => d.stay(rng.random_range(1..30)),
            _ => d.arc(
                rng.random_range(0.1..0.4),
                -TAU * rng.random_range(0.5..1.5),
                step,
            ),
        };
    }
    d.path()
}

/// A figure-eight of random size, several laps, with noise.
fn figure_eights(rng: &mut ChaCha8Rng, samples: usize) -> Vec<PathSample> {
    let scale = rng.random_range(0.5..3.0);
    let laps = rng.random_range(0.7..2.5);
    let s0 = rng.random_range(0.0..TAU);
    let noise = rng.random_range(0.0..0.01) * scale;
    let points: Vec<[f64; 2]> = (0..samples)
        .map(|k| {
            let s = s0 + TAU * laps * k as f64 / samples as f64;
            [
                scale * s.sin() + rng.random_range(-noise..=noise),
                scale * s.sin() * s.cos() + rng.random_range(-noise..=noise),
            ]
        })
        .collect();
    through(&points, 0.02)
}

/// A spiral in and a straight way out across all its turns.
fn spiral(rng: &mut ChaCha8Rng, samples: usize) -> Vec<PathSample> {
    let turns = rng.random_range(1.5..5.0);
    let r0 = rng.random_range(0.5..2.0);
    let inward = samples * 3 / 4;
    let mut points: Vec<[f64; 2]> = (0..inward)
        .map(|k| {
            let f = k as f64 / inward as f64;
            let a = TAU * turns * f;
            let r = r0 * (1.0 - 0.9 * f);
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    let [x, y] = *points.last().unwrap();
    let out = samples - inward;
    let heading = rng.random_range(0.0..TAU);
    for k in 1..=out {
        let f = 1.2 * r0 * k as f64 / out as f64;
        points.push([x + f * heading.cos(), y + f * heading.sin()]);
    }
    through(&points, 0.01)
}

/// Steps on a lattice of quarter metres (exact in binary): distances equal
/// to the pinch distance, collinear overlaps, ends on segments, stops.
fn lattice_walk(rng: &mut ChaCha8Rng, samples: usize) -> Vec<PathSample> {
    let mut p = [0.0, 0.0];
    let points: Vec<[f64; 2]> = (0..samples)
        .map(|_| {
            let here = p;
            let step = rng.random_range(1..4) as f64 * 0.25;
            p[0] += step * rng.random_range(-1..=1) as f64;
            p[1] += step * rng.random_range(-1..=1) as f64;
            here
        })
        .collect();
    through(&points, 0.1)
}

/// Sparse random points: long segments, many crossings.
fn scribble(rng: &mut ChaCha8Rng, samples: usize) -> Vec<PathSample> {
    let size = rng.random_range(1.0..20.0);
    let points: Vec<[f64; 2]> = (0..samples / 3)
        .map(|_| [rng.random_range(0.0..size), rng.random_range(0.0..size)])
        .collect();
    through(&points, 0.5)
}

/// A random drive far from the origin (a survey frame, say).
fn far_away(rng: &mut ChaCha8Rng, samples: usize) -> Vec<PathSample> {
    let (dx, dy) = (rng.random_range(-5e6..5e6), rng.random_range(-5e6..5e6));
    let mut path = random_drive(rng, samples);
    for s in &mut path {
        s.pose.x_m += dx;
        s.pose.y_m += dy;
    }
    path
}

/// A random definition of redundancy that fits the path's size.
fn random_config(rng: &mut ChaCha8Rng, path: &[PathSample], lattice: bool) -> RedundancyConfig {
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for s in path {
        let p = s.position();
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.1);
    let pinch = if lattice {
        [0.25, 0.5, 0.75, 1.0][rng.random_range(0..4)]
    } else {
        size * rng.random_range(0.005..0.08)
    };
    let mut cfg = cfg(pinch);
    cfg.min_loop_length_m = match rng.random_range(0..4) {
        0 => None,
        1 => Some(0.0),
        2 => Some(pinch * rng.random_range(1.0..10.0)),
        _ => Some(size * rng.random_range(0.0..2.0)),
    };
    if rng.random_range(0..3) == 0 {
        cfg.min_loop_duration_s = path.last().unwrap().t_s * rng.random_range(0.0..0.3);
    }
    cfg.reversing_is_redundant = rng.random_range(0..3) > 0;
    cfg.coverage_radius_m = match rng.random_range(0..3) {
        0 => None,
        _ => Some(pinch * rng.random_range(0.3..4.0)),
    };
    cfg.keep_end = rng.random_range(0..3) == 0;
    for _ in 0..rng.random_range(0..3) {
        let c = [
            rng.random_range(lo[0]..=hi[0]),
            rng.random_range(lo[1]..=hi[1]),
        ];
        let r = size * rng.random_range(0.02..0.2);
        cfg.keep_regions.push(if rng.random_range(0..2) == 0 {
            KeepRegion::Circle {
                x_m: c[0],
                y_m: c[1],
                radius_m: r,
            }
        } else {
            KeepRegion::Rectangle {
                min_x_m: c[0] - r,
                min_y_m: c[1] - r / 2.0,
                max_x_m: c[0] + r / 2.0,
                max_y_m: c[1] + r,
            }
        });
    }
    let t_end = path.last().unwrap().t_s;
    for _ in 0..rng.random_range(0..3) {
        let start_s = rng.random_range(0.0..t_end);
        let end_s = start_s + t_end * rng.random_range(0.001..0.1);
        cfg.keep_windows.push(TimeWindow { start_s, end_s });
    }
    cfg
}

type Generator = fn(&mut ChaCha8Rng, usize) -> Vec<PathSample>;

const GENERATORS: [(&str, Generator); 6] = [
    ("random_drive", random_drive),
    ("figure_eights", figure_eights),
    ("spiral", spiral),
    ("lattice_walk", lattice_walk),
    ("scribble", scribble),
    ("far_away", far_away),
];

#[test]
fn fast_and_reference_pinch_finders_agree_on_random_paths() {
    let mut crossings = 0;
    let mut nears = 0;
    for (name, generate) in GENERATORS {
        for seed in 0..60u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let samples = rng.random_range(150..700);
            let path = generate(&mut rng, samples);
            let cfg = random_config(&mut rng, &path, name == "lattice_walk");
            let what = format!("{name}, seed {seed}, {} samples, {cfg:?}", path.len());
            let fast = find_pinches(&path, &cfg).unwrap();
            let reference = find_pinches_reference(&path, &cfg).unwrap();
            assert_eq!(fast, reference, "{what}");
            nears += fast.iter().filter(|p| p.kind == PinchKind::Near).count();
            crossings += fast
                .iter()
                .filter(|p| p.kind == PinchKind::Crossing)
                .count();

            let pruned = remove_redundancy(&path, &cfg).unwrap();
            let pruned_reference = remove_redundancy_reference(&path, &cfg).unwrap();
            assert_eq!(pruned, pruned_reference, "{what}");
            check_invariants(&path, &cfg, &pruned, &what);
        }
    }
    // The comparison means something only if both kinds occur often.
    assert!(
        nears > 5_000 && crossings > 1_000,
        "{nears} near, {crossings} crossing"
    );
}

// ------------------------------------------------------------ shapes

/// x = sin s, y = sin s cos s: through the origin at s = 0 and s = π,
/// crossing at right angles; the right lobe (x > 0) lies between.
fn lemniscate(s: f64) -> [f64; 2] {
    [s.sin(), s.sin() * s.cos()]
}

/// From the far left, through the centre, round the right lobe, back
/// through the centre, and on round the left lobe to `s1`.
fn figure_eight(n: usize, s1: f64) -> Vec<PathSample> {
    let s0 = -FRAC_PI_2;
    let s = |k: usize| s0 + (s1 - s0) * k as f64 / (n - 1) as f64;
    through(&(0..n).map(|k| lemniscate(s(k))).collect::<Vec<_>>(), 0.01)
}

#[test]
fn a_figure_eight_driven_once_keeps_both_lobes() {
    // The centre pinches the right lobe off, but the lobe is ground no
    // other pass covers: the cut is refused, with what it would drop.
    let path = figure_eight(2_000, 1.25 * PI);
    let cfg = cfg(0.05);
    assert!(!find_pinches(&path, &cfg).unwrap().is_empty());
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "figure-eight");
    assert!(pruned.deletions.is_empty(), "{:?}", pruned.deletions);
    assert_eq!(pruned.kept.len(), path.len());
    assert_eq!(pruned.refused.len(), 1, "{:?}", pruned.refused);
    // The lobe is about half the curve's 6.1 m length.
    assert!((2.7..3.3).contains(&pruned.refused[0].would_drop_m));
    assert!(coverage_percent(&path, &pruned) > 99.999);
}

#[test]
fn a_figure_eight_driven_twice_keeps_its_first_pass() {
    // One and a half times round: the second pass retraces the first, so
    // the plan ends where the first pass closed.
    let n = 3_000;
    let path = figure_eight(n, -FRAC_PI_2 + 3.0 * PI);
    let cfg = cfg(0.05);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "figure-eight twice");
    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    let tail = pruned.deletions[0];
    assert_eq!(tail.reason, DeletionReason::TrailingRetrace);
    // The first pass is 2π of the curve's 3π: two thirds of the samples;
    // its last 5 cm (16 samples) come within the coverage radius of its start.
    let first_pass_end = 2 * n / 3;
    assert!(
        (first_pass_end - 20..first_pass_end + 5).contains(&tail.first_removed),
        "{tail:?}"
    );
    assert!(coverage_percent(&path, &pruned) >= 99.9);

    let mut keep_end = cfg.clone();
    keep_end.keep_end = true;
    let pruned = remove_redundancy(&path, &keep_end).unwrap();
    check_invariants(&path, &keep_end, &pruned, "figure-eight twice, keep end");
    assert_eq!(pruned.kept.last(), Some(&(n - 1)));
    assert_eq!(coverage_percent(&path, &pruned), 100.0);
}

#[test]
fn a_sparse_figure_eight_is_cut_at_its_self_crossing() {
    // Samples 0.15 m apart and a 5 cm pinch distance: no two samples are
    // near, only the segments through the centre cross. With a coverage
    // radius as large as the figure, the lobe is redundant.
    let n = 40;
    let (s0, s1) = (-FRAC_PI_2 + 0.03, 1.25 * PI);
    let s = |k: usize| s0 + (s1 - s0) * k as f64 / (n - 1) as f64;
    let path = through(&(0..n).map(|k| lemniscate(s(k))).collect::<Vec<_>>(), 0.1);
    let mut cfg = cfg(0.05);
    cfg.coverage_radius_m = Some(1.5);
    cfg.keep_end = true;
    let pinches = find_pinches(&path, &cfg).unwrap();
    assert!(
        pinches.iter().all(|p| p.kind == PinchKind::Crossing),
        "{pinches:?}"
    );
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "sparse figure-eight");

    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    assert_eq!(pruned.deletions[0].reason, DeletionReason::Crossing);
    let gone = deleted(&pruned, n);
    for (k, p) in path.iter().enumerate() {
        assert_eq!(
            gone[k],
            p.pose.x_m > 0.0 && k > 0 && k < n - 1,
            "sample {k}"
        );
    }

    // At a coverage radius of 5 cm the lobe is ground of its own.
    cfg.coverage_radius_m = None;
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "sparse figure-eight, 5 cm");
    assert!(pruned.deletions.is_empty());
}

/// Along +x to the origin, `laps` times round a circle of 0.5 m to the
/// left, then on along +x. Returns the path and the lap boundaries.
fn circle_laps(laps: usize) -> (Vec<PathSample>, Vec<usize>) {
    let mut d = Drive::start(-2.0, 0.0, 0.0);
    d.straight(2.0, 0.01);
    let mut bounds = vec![d.samples.len() - 1];
    for _ in 0..laps {
        d.arc(0.5, TAU, 0.01);
        bounds.push(d.samples.len() - 1);
    }
    d.straight(2.0, 0.01);
    (d.path(), bounds)
}

#[test]
fn a_circle_driven_twice_loses_its_second_lap() {
    let (path, laps) = circle_laps(2);
    let cfg = cfg(0.05);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "circle twice");

    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    let cut = pruned.deletions[0];
    assert_eq!(cut.reason, DeletionReason::Loop);
    // The cut starts where lap 1 closes: where it comes within the 5 cm
    // coverage radius of the way in, which the circle touches (0.22 m
    // before it closes) and ends where lap 2 does.
    assert!(
        (laps[1] - 30..=laps[1] - 15).contains(&cut.first_removed),
        "{cut:?}, laps {laps:?}"
    );
    // Its partner is where lap 2 passes the same place.
    assert!(cut.last_removed >= laps[2] - 30 && cut.last_removed <= laps[2] - 15);
    assert!((cut.length_m - PI).abs() < 0.05, "{}", cut.length_m);
    // Lap 1 is whole but for what the way in covers.
    assert!((laps[0]..laps[1] - 30).all(|k| pruned.kept.binary_search(&k).is_ok()));
    assert_eq!(coverage_percent(&path, &pruned), 100.0);
}

#[test]
fn a_loop_circled_three_times_loses_two_circles() {
    let (path, laps) = circle_laps(3);
    let cfg = cfg(0.05);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "three circles");
    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    let cut = pruned.deletions[0];
    assert!((laps[1] - 30..=laps[1] - 15).contains(&cut.first_removed));
    assert!(cut.last_removed >= laps[3] - 30 && cut.last_removed <= laps[3] - 15);
    assert!((cut.length_m - TAU).abs() < 0.05, "{}", cut.length_m);
    assert_eq!(coverage_percent(&path, &pruned), 100.0);
    // The way out, after the circles, is kept.
    assert_eq!(pruned.kept.last(), Some(&(path.len() - 1)));
}

#[test]
fn loops_over_new_ground_stay() {
    // Straight, half a big circle, a small loop, the other half, straight:
    // the small loop pinches, but nothing is driven twice.
    let mut d = Drive::start(-1.0, 0.0, 0.0);
    d.straight(1.0, 0.01).arc(1.0, PI, 0.01);
    let small = d.samples.len();
    d.arc(0.2, TAU, 0.01);
    let small_end = d.samples.len() - 1;
    d.arc(1.0, PI, 0.01).straight(1.0, 0.01);
    let path = d.path();
    let cfg = cfg(0.05);
    let pinches = find_pinches(&path, &cfg).unwrap();
    assert!(
        pinches
            .iter()
            .any(|p| p.i >= small - 10 && p.j <= small_end + 10),
        "the small loop pinches on its own: {pinches:?}"
    );
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "loops over new ground");
    assert!(pruned.deletions.is_empty(), "{:?}", pruned.deletions);
    assert!(!pruned.refused.is_empty());
}

#[test]
fn a_spiral_that_never_retraces_is_not_cut() {
    // Turns 8 cm apart: closer than the 10 cm pinch distance, so every
    // sample pinches the next turn, but farther than a 5 cm coverage
    // radius, so no turn covers another.
    let mut points = Vec::new();
    let mut a: f64 = 0.0;
    loop {
        let r = 0.2 + 0.08 * a / TAU;
        if r > 1.0 {
            break;
        }
        points.push([r * a.cos(), r * a.sin()]);
        a += 0.01 / r;
    }
    let path = through(&points, 0.01);
    let mut cfg = cfg(0.1);
    cfg.coverage_radius_m = Some(0.05);
    assert!(find_pinches(&path, &cfg).unwrap().len() > path.len() / 2);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "spiral");
    assert!(pruned.deletions.is_empty(), "{:?}", pruned.deletions);
    assert_eq!(pruned.kept.len(), path.len());
    assert!(!pruned.refused.is_empty());
}

/// A rounded-rectangle route driven twice with a wall follower's wobble
/// (the second lap a few centimetres off the first), stopping after
/// `second_lap` of the second lap.
fn two_laps(second_lap: f64) -> Vec<PathSample> {
    let lap_steps = 1_200;
    let total = lap_steps + (second_lap * lap_steps as f64) as usize;
    let route = |u: f64| -> [f64; 2] {
        // A 4 m x 2 m rectangle with rounded corners, by arc length.
        let (w, h, r) = (4.0, 2.0, 0.4);
        let straight = [w - 2.0 * r, h - 2.0 * r, w - 2.0 * r, h - 2.0 * r];
        let quarter = FRAC_PI_2 * r;
        let perimeter: f64 = straight.iter().sum::<f64>() + 4.0 * quarter;
        let mut s = u.rem_euclid(1.0) * perimeter;
        let corners = [[w - r, r], [w - r, h - r], [r, h - r], [r, r]];
        let mut heading = 0.0;
        let mut p = [r, 0.0];
        for side in 0..4 {
            let (c, sn) = (f64::cos(heading), f64::sin(heading));
            if s <= straight[side] {
                return [p[0] + s * c, p[1] + s * sn];
            }
            s -= straight[side];
            let centre = corners[side];
            if s <= quarter {
                let a = heading - FRAC_PI_2 + s / r;
                return [centre[0] + r * a.cos(), centre[1] + r * a.sin()];
            }
            s -= quarter;
            heading += FRAC_PI_2;
            let a = heading - FRAC_PI_2;
            p = [centre[0] + r * a.cos(), centre[1] + r * a.sin()];
        }
        p
    };
    let points: Vec<[f64; 2]> = (0..total)
        .map(|k| {
            let u = k as f64 / lap_steps as f64;
            let [x, y] = route(u);
            // Wobble, and a lap-dependent offset of up to 4 cm.
            let wobble = 0.01 * (7.0 * TAU * u).sin() + 0.04 * (u / 2.0).min(1.0);
            [x + wobble * 0.3, y - wobble]
        })
        .collect();
    through(&points, 0.05)
}

#[test]
fn a_two_lap_mission_keeps_its_first_lap_wherever_it_stops() {
    let cfg = cfg(0.15);
    for (name, second_lap) in [
        ("early", 0.1),
        ("middle", 0.5),
        ("nearly complete", 0.95),
        ("a little past", 1.08),
    ] {
        let path = two_laps(second_lap);
        let pruned = remove_redundancy(&path, &cfg).unwrap();
        let what = format!("two laps, stopped {name}");
        check_invariants(&path, &cfg, &pruned, &what);
        let covered = coverage_percent(&path, &pruned);
        assert!(covered >= 99.0, "{what}: {covered} %");
        // The first lap is kept (its last coverage radius may be cut).
        assert!(
            (0..1_150).all(|k| pruned.kept.binary_search(&k).is_ok()),
            "{what}: {:?}",
            pruned.deletions
        );
        let kept_length = twindrive_mission::path_length_m(&pruned.apply(&path));
        let length = twindrive_mission::path_length_m(&path);
        if second_lap < 1.0 {
            assert!(
                kept_length < length / (1.0 + second_lap) + 0.2,
                "{what}: kept {kept_length} of {length} m"
            );
        }
    }
}

/// Forward 2 m along +x, back `back_m`, a quarter turn left in place, 1 m up.
fn bump_and_back_up(back_m: f64) -> Vec<PathSample> {
    let mut d = Drive::start(0.0, 0.0, 0.0);
    d.straight(2.0, 0.01)
        .straight(-back_m, 0.01)
        .turn(FRAC_PI_2, 10)
        .straight(1.0, 0.01);
    d.path()
}

#[test]
fn a_bump_and_back_up_kink_is_removed_when_reversing_is_redundant() {
    // Backing up 0.3 m: the kink's far end is 0.3 m from the path that
    // remains, so at a coverage radius of 0.35 m it goes.
    let path = bump_and_back_up(0.3);
    let mut cfg = cfg(0.1);
    cfg.coverage_radius_m = Some(0.35);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "bump and back up");

    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    assert_eq!(pruned.deletions[0].reason, DeletionReason::Reversal);
    let gone = deleted(&pruned, path.len());
    for (k, s) in path.iter().enumerate() {
        if s.v_m_s < 0.0 {
            assert!(gone[k], "reversing sample {k} kept");
        } else if s.v_m_s > 0.0 && s.pose.y_m == 0.0 {
            let x = s.pose.x_m;
            assert!(
                x >= 1.695 || !gone[k],
                "forward sample {k} at x = {x} deleted"
            );
            assert!(x <= 1.705 || gone[k], "retraced sample {k} at x = {x} kept");
        } else {
            assert!(!gone[k], "sample {k} after the kink deleted");
        }
    }
    // About 0.3 m there and 0.3 m back.
    assert!((pruned.deletions[0].length_m - 0.6).abs() < 0.03);

    // A back-up shorter than the pinch distance goes at the default radius.
    let path = bump_and_back_up(0.08);
    let cfg = RedundancyConfig::with_pinch_distance(0.1);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "short back-up");
    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    assert!(
        path.iter()
            .enumerate()
            .all(|(k, s)| s.v_m_s >= 0.0 || pruned.kept.binary_search(&k).is_err())
    );
}

#[test]
fn a_kink_that_would_drop_ground_is_kept_and_reported() {
    // 0.3 m back at a 0.1 m radius: cutting would drop the last 0.2 m
    // before the bump.
    let path = bump_and_back_up(0.3);
    let cfg = cfg(0.1);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "long back-up");
    assert!(pruned.deletions.is_empty(), "{:?}", pruned.deletions);
    assert_eq!(pruned.refused.len(), 1, "{:?}", pruned.refused);
    let refused = pruned.refused[0];
    // The farthest cut from the sample before the back-up: the kink, or a
    // loop that also takes the turn in place.
    assert!(matches!(
        refused.reason,
        DeletionReason::Reversal | DeletionReason::Loop
    ));
    assert!(
        (refused.would_drop_m - 0.4).abs() < 0.03,
        "0.2 m there and back: {refused:?}"
    );
}

#[test]
fn a_turn_in_place_that_wobbles_around_zero_speed_is_not_a_kink() {
    // Forward 1 m, a quarter turn in place whose smoothed speed wobbles
    // around zero (the planner's output of a real turn), forward 1 m.
    let mut path = Vec::new();
    let mut t = 0.0;
    for k in 0..50 {
        path.push(sample(t, 0.02 * k as f64, 0.0, 0.0, 0.2));
        t += 0.1;
    }
    for k in 0..30 {
        let wobble = if k % 2 == 0 { -2e-4 } else { 2e-4 };
        let heading = std::f64::consts::FRAC_PI_2 * k as f64 / 29.0;
        path.push(sample(
            t,
            1.0 + wobble * 0.1,
            1e-5 * k as f64,
            heading,
            wobble,
        ));
        t += 0.1;
    }
    for k in 1..50 {
        path.push(sample(
            t,
            1.0,
            0.02 * k as f64,
            std::f64::consts::FRAC_PI_2,
            0.2,
        ));
        t += 0.1;
    }
    let pruned = remove_redundancy(&path, &cfg(0.1)).unwrap();
    assert!(pruned.deletions.is_empty(), "{:?}", pruned.deletions);
    assert_eq!(pruned.kept.len(), path.len());
}

#[test]
fn a_bump_and_back_up_kink_stays_when_reversing_is_not_redundant() {
    let path = bump_and_back_up(0.08);
    let mut cfg = cfg(0.1);
    cfg.reversing_is_redundant = false;
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "bump and back up kept");
    assert_eq!(pruned.kept, (0..path.len()).collect::<Vec<_>>());
    assert!(pruned.deletions.is_empty());
}

#[test]
fn a_retrace_inside_a_keep_region_or_window_survives() {
    let (path, laps) = circle_laps(2);
    let n = path.len();
    let cfg_plain = cfg(0.05);
    let plain = remove_redundancy(&path, &cfg_plain).unwrap();
    assert_eq!(plain.deletions.len(), 1, "without a keep region lap 2 goes");

    // Around the top of the circle (centre (0, 0.5), top (0, 1)): the
    // second lap's pass there must stay, so no cut can take the lap.
    let mut cfg = cfg_plain.clone();
    cfg.keep_regions.push(KeepRegion::Circle {
        x_m: 0.0,
        y_m: 1.0,
        radius_m: 0.1,
    });
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "keep region");
    let top_of_lap_2 = laps[1] + (laps[2] - laps[1]) / 2;
    assert!(pruned.kept.binary_search(&top_of_lap_2).is_ok());
    assert_eq!(pruned.kept.len(), n, "{:?}", pruned.deletions);

    let mut cfg = cfg_plain;
    cfg.keep_windows.push(TimeWindow {
        start_s: path[top_of_lap_2].t_s,
        end_s: path[top_of_lap_2 + 3].t_s,
    });
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "keep window");
    assert!(pruned.kept.binary_search(&top_of_lap_2).is_ok());
}

#[test]
fn a_path_back_at_its_start_keeps_its_round() {
    // A 4 m square, ending exactly where it began. The closing pinch would
    // delete the whole round; at most the last coverage radius, which the
    // start covers, goes.
    let mut d = Drive::start(0.0, 0.0, 0.0);
    for _ in 0..4 {
        d.straight(4.0, 0.02).turn(FRAC_PI_2, 5);
    }
    let mut path = d.path();
    path.last_mut().unwrap().pose.x_m = 0.0;
    path.last_mut().unwrap().pose.y_m = 0.0;
    let n = path.len();

    let cfg = cfg(0.1);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "closed square");
    assert_eq!(coverage_percent(&path, &pruned), 100.0);
    // Measured from the last kept sample, one 2 cm step farther out.
    let removed: f64 = pruned.deletions.iter().map(|d| d.length_m).sum();
    assert!(removed <= 0.12 + 1e-9, "{:?}", pruned.deletions);
    assert!(
        pruned
            .deletions
            .iter()
            .all(|d| d.reason == DeletionReason::TrailingRetrace)
    );
    assert!(
        pruned
            .refused
            .iter()
            .any(|r| r.i == 0 && r.would_drop_m > 15.0)
    );

    let mut keep_end = cfg.clone();
    keep_end.keep_end = true;
    let pruned = remove_redundancy(&path, &keep_end).unwrap();
    check_invariants(&path, &keep_end, &pruned, "closed square, keep end");
    assert_eq!(pruned.kept, (0..n).collect::<Vec<_>>());
}

#[test]
fn a_path_without_loops_passes_through_unchanged() {
    let mut d = Drive::start(0.0, 0.0, 0.3);
    d.straight(3.0, 0.01)
        .stay(50)
        .arc(2.0, 1.0, 0.01)
        .turn(-0.5, 20)
        .arc(1.0, -2.0, 0.01)
        .straight(5.0, 0.05);
    let path = d.path();
    let cfg = cfg(0.1);
    assert!(find_pinches(&path, &cfg).unwrap().is_empty());
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    assert_eq!(pruned.kept, (0..path.len()).collect::<Vec<_>>());
    assert!(pruned.deletions.is_empty() && pruned.refused.is_empty());

    for short in [vec![], path[..1].to_vec(), path[..2].to_vec()] {
        let pruned = remove_redundancy(&short, &cfg).unwrap();
        assert_eq!(pruned.kept, (0..short.len()).collect::<Vec<_>>());
    }
}

#[test]
fn coverage_of_a_sparse_path_is_measured_along_its_segments() {
    // Samples metres apart with a 1 m radius: the rule holds at every
    // sample, but a deleted leg passes 3 m from what remains between its
    // ends. The measured coverage says so.
    let points = [
        [0.0, 0.0],
        [0.0, -5.0],
        [6.0, -5.0],
        [6.0, 0.0],
        [6.0, 0.5],
        [0.0, 0.5],
        [0.0, 0.2],
        [6.0, 0.05],
        [6.0, -1.0],
    ];
    let path = through(&points, 1.0);
    let mut cfg = cfg(0.1);
    cfg.coverage_radius_m = Some(1.0);
    cfg.keep_end = true;
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "sparse");
    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    let c = route_coverage(&path, &pruned.apply(&path), 1.0).unwrap();
    assert!(c.uncovered_m > 1.0, "{c:?}");
    assert!(c.covered_percent < 95.0, "{c:?}");
    assert!(!c.uncovered_stretches.is_empty());
}

#[test]
fn route_coverage_measures_the_ground_a_plan_leaves_out() {
    // A 3 m line; the "plan" drives only its first metre and its last.
    let route = through(
        &(0..=300)
            .map(|k| [0.01 * k as f64, 0.0])
            .collect::<Vec<_>>(),
        0.1,
    );
    let plan: Vec<PathSample> = route
        .iter()
        .filter(|s| s.pose.x_m <= 1.0 || s.pose.x_m >= 2.0)
        .copied()
        .collect();
    // The plan's jump from x = 1 to x = 2 is part of its polyline: drop it
    // by measuring against the first metre and the last separately.
    let first = &plan[..101];
    let c = route_coverage(&route, first, 0.1).unwrap();
    assert!((c.route_length_m - 3.0).abs() < 1e-9);
    assert!((c.uncovered_m - 1.9).abs() < 0.011, "{c:?}");
    assert!((c.covered_percent - 100.0 * 1.1 / 3.0).abs() < 0.4, "{c:?}");
    assert_eq!(c.uncovered_stretches.len(), 1);
    // x = 1.1 is 0.1 m from the plan, give or take a rounding.
    assert!((110..=111).contains(&c.uncovered_stretches[0].first));
    assert_eq!(c.uncovered_stretches[0].last, 300);
    assert!((c.plan_length_m - 1.0).abs() < 1e-9);
    let whole = route_coverage(&route, &plan, 0.1).unwrap();
    assert_eq!(whole.covered_percent, 100.0);
    assert!(route_coverage(&route, &plan, 0.0).is_err());
    assert_eq!(
        route_coverage(&route, &[], 0.1).unwrap().covered_percent,
        0.0
    );
}

#[test]
fn bad_settings_and_samples_are_named() {
    let (path, _) = circle_laps(1);
    let err = remove_redundancy(&path, &cfg(0.0)).unwrap_err();
    assert_eq!(err.to_string(), "pinch_distance_m must be > 0, got 0");
    let err = find_pinches(&path, &cfg(-1.0)).unwrap_err();
    assert_eq!(err.to_string(), "pinch_distance_m must be > 0, got -1");
    assert!(remove_redundancy(&path, &cfg(f64::NAN)).is_err());

    let mut bad = cfg(0.1);
    bad.min_loop_length_m = Some(-0.5);
    assert_eq!(
        remove_redundancy(&path, &bad).unwrap_err().to_string(),
        "min_loop_length_m must be >= 0, got -0.5"
    );
    let mut bad = cfg(0.1);
    bad.keep_regions.push(KeepRegion::Rectangle {
        min_x_m: 1.0,
        min_y_m: 0.0,
        max_x_m: 1.0,
        max_y_m: 2.0,
    });
    assert!(
        remove_redundancy(&path, &bad)
            .unwrap_err()
            .to_string()
            .starts_with("keep_regions[0] ")
    );

    let mut broken = path.clone();
    broken[17].pose.y_m = f64::NAN;
    assert_eq!(
        remove_redundancy(&broken, &cfg(0.1))
            .unwrap_err()
            .to_string(),
        "path sample 17: pose.y_m is NaN, not a finite number"
    );
    assert!(matches!(
        remove_redundancy(&broken, &cfg(0.1)),
        Err(RedundancyError::NotFinite {
            index: 17,
            field: "pose.y_m",
            ..
        })
    ));
    let mut broken = path.clone();
    broken[40].t_s = broken[39].t_s;
    assert!(matches!(
        remove_redundancy(&broken, &cfg(0.1)),
        Err(RedundancyError::TimeNotIncreasing { index: 40, .. })
    ));
}

#[test]
fn a_toml_file_with_only_the_pinch_distance_is_complete() {
    let cfg: RedundancyConfig = toml::from_str("pinch_distance_m = 0.1").unwrap();
    assert_eq!(cfg, RedundancyConfig::with_pinch_distance(0.1));
    let cfg: RedundancyConfig = toml::from_str(
        r#"
        pinch_distance_m = 0.1
        min_loop_length_m = 0.5
        min_loop_duration_s = 2.0
        reversing_is_redundant = false

        [[keep_regions]]
        kind = "circle"
        x_m = 1.0
        y_m = 2.0
        radius_m = 0.5

        [[keep_regions]]
        kind = "rectangle"
        min_x_m = 0.0
        min_y_m = 0.0
        max_x_m = 1.0
        max_y_m = 1.0

        [[keep_windows]]
        start_s = 10.0
        end_s = 20.0
        "#,
    )
    .unwrap();
    assert_eq!(cfg.keep_regions.len(), 2);
    assert_eq!(cfg.min_loop_length_m, Some(0.5));
    assert!(!cfg.reversing_is_redundant);
    assert!(toml::from_str::<RedundancyConfig>("pinch_distance_m = 0.1\nloop = 1").is_err());
    let cfg: RedundancyConfig =
        toml::from_str("pinch_distance_m = 0.1\ncoverage_radius_m = 0.2\nkeep_end = true").unwrap();
    assert_eq!(cfg.effective_coverage_radius_m(), 0.2);
    assert!(cfg.keep_end);
}
