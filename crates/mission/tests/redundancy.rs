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
        assert_eq!(kept.last(), Some(&(n - 1)), "{what}: last sample lost");
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
    let mut covered = vec![false; n];
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
        for c in &mut covered[d.first_removed..=d.last_removed] {
            *c = true;
        }
        assert_eq!(d.t_start_s, path[d.first_removed - 1].t_s, "{what}");
        assert_eq!(d.t_end_s, path[d.last_removed + 1].t_s, "{what}");
        let length = cum[d.last_removed + 1] - cum[d.first_removed - 1];
        assert!(
            (d.length_m - length).abs() <= 1e-9 * (1.0 + length),
            "{what}: {d:?}"
        );
    }
    assert_eq!(
        covered, gone,
        "{what}: deletions do not match the kept samples"
    );
    // Nothing cuttable is left.
    let out = pruned.apply(path);
    assert_eq!(
        find_pinches(&out, cfg).unwrap(),
        vec![],
        "{what}: pinches left"
    );
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

#[test]
fn a_figure_eight_loses_the_lobe_between_its_two_passes() {
    // From the far left, through the centre, round the right lobe, back
    // through the centre, and half way round the left lobe.
    let n = 2_000;
    let (s0, s1) = (-FRAC_PI_2, 1.25 * PI);
    let s = |k: usize| s0 + (s1 - s0) * k as f64 / (n - 1) as f64;
    let path = through(&(0..n).map(|k| lemniscate(s(k))).collect::<Vec<_>>(), 0.01);
    let cfg = cfg(0.05);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "figure-eight");

    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    assert_eq!(pruned.deletions[0].reason, DeletionReason::Loop);
    let gone = deleted(&pruned, n);
    for (k, p) in path.iter().enumerate() {
        let x = p.pose.x_m;
        assert!(x <= 0.1 || gone[k], "right lobe sample {k} kept");
        assert!(x >= -0.1 || !gone[k], "left lobe sample {k} deleted");
    }
    // The lobe is about half the curve's 6.1 m length.
    assert!((2.8..3.3).contains(&pruned.deletions[0].length_m));
}

#[test]
fn a_sparse_figure_eight_is_cut_at_its_self_crossing() {
    // Samples 0.15 m apart and a 5 cm pinch distance: no two samples are
    // near, only the segments through the centre cross.
    let n = 40;
    let (s0, s1) = (-FRAC_PI_2 + 0.03, 1.25 * PI);
    let s = |k: usize| s0 + (s1 - s0) * k as f64 / (n - 1) as f64;
    let path = through(&(0..n).map(|k| lemniscate(s(k))).collect::<Vec<_>>(), 0.1);
    let cfg = cfg(0.05);
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

/// The circles touch the x axis, so the samples where they come within a
/// pinch distance of it pinch the way in or out and may stay; all others go.
fn assert_lifted_samples_deleted(path: &[PathSample], pruned: &Pruned, pinch_distance_m: f64) {
    let gone = deleted(pruned, path.len());
    for (k, s) in path.iter().enumerate() {
        assert!(
            s.pose.y_m < pinch_distance_m || gone[k],
            "sample {k} at {:?} kept",
            s.position()
        );
    }
}

#[test]
fn a_circle_driven_twice_loses_the_second_lap_when_the_first_is_kept() {
    let (path, laps) = circle_laps(2);
    let mut cfg = cfg(0.05);
    cfg.keep_windows.push(TimeWindow {
        start_s: path[laps[0]].t_s,
        end_s: path[laps[1]].t_s,
    });
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "circle twice");

    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    let cut = pruned.deletions[0];
    assert_eq!(cut.reason, DeletionReason::Loop);
    assert_eq!(
        cut.first_removed,
        laps[1] + 1,
        "the cut starts where lap 1 ends"
    );
    assert!(cut.last_removed >= laps[2] - 1 && cut.last_removed <= laps[2] + 5);
    assert!((cut.length_m - PI).abs() < 0.06, "{}", cut.length_m);
}

#[test]
fn nested_loops_go_in_one_cut() {
    // Twice round the circle: every sample of lap 1 pinches one of lap 2;
    // the outermost pinch takes both laps.
    let (path, laps) = circle_laps(2);
    let cfg = cfg(0.05);
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "two laps");
    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    assert!(pruned.deletions[0].first_removed <= laps[0] + 1);
    assert_lifted_samples_deleted(&path, &pruned, cfg.pinch_distance_m);

    // A small loop inside a big one.
    let mut d = Drive::start(-1.0, 0.0, 0.0);
    d.straight(1.0, 0.01).arc(1.0, PI, 0.01);
    let small = d.samples.len();
    d.arc(0.2, TAU, 0.01);
    let small_end = d.samples.len() - 1;
    d.arc(1.0, PI, 0.01).straight(1.0, 0.01);
    let path = d.path();
    let pinches = find_pinches(&path, &cfg).unwrap();
    assert!(
        pinches
            .iter()
            .any(|p| p.i >= small - 10 && p.j <= small_end + 10),
        "the small loop pinches on its own: {pinches:?}"
    );
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "nested loops");
    assert_eq!(pruned.deletions.len(), 1, "{:?}", pruned.deletions);
    let cut = pruned.deletions[0];
    assert!(
        cut.first_removed < small && cut.last_removed > small_end,
        "{cut:?}"
    );
}

/// Forward 2 m along +x, back 0.3 m, a quarter turn left in place, 1 m up.
fn bump_and_back_up() -> Vec<PathSample> {
    let mut d = Drive::start(0.0, 0.0, 0.0);
    d.straight(2.0, 0.01)
        .straight(-0.3, 0.01)
        .turn(FRAC_PI_2, 10)
        .straight(1.0, 0.01);
    d.path()
}

#[test]
fn a_bump_and_back_up_kink_is_removed_when_reversing_is_redundant() {
    let path = bump_and_back_up();
    let cfg = cfg(0.1);
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
    let path = bump_and_back_up();
    let mut cfg = cfg(0.1);
    cfg.reversing_is_redundant = false;
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "bump and back up kept");
    assert_eq!(pruned.kept, (0..path.len()).collect::<Vec<_>>());
    assert!(pruned.deletions.is_empty());
}

/// Along +x to the origin, once round a circle of 0.5 m, on along +x.
fn one_loop() -> (Vec<PathSample>, std::ops::Range<usize>) {
    let (path, laps) = circle_laps(1);
    (path, laps[0] + 1..laps[1])
}

#[test]
fn a_loop_inside_a_keep_region_survives() {
    let (path, lap) = one_loop();
    let cfg_plain = cfg(0.05);
    let plain = remove_redundancy(&path, &cfg_plain).unwrap();
    assert_eq!(
        plain.deletions.len(),
        1,
        "without a keep region the loop goes"
    );
    assert!(plain.deletions[0].first_removed <= lap.start);
    assert_lifted_samples_deleted(&path, &plain, cfg_plain.pinch_distance_m);

    let mut cfg = cfg_plain.clone();
    // Around the top of the circle (centre (0, 0.5), top (0, 1)).
    cfg.keep_regions.push(KeepRegion::Circle {
        x_m: 0.0,
        y_m: 1.0,
        radius_m: 0.1,
    });
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "keep region");
    assert_eq!(pruned.kept, (0..path.len()).collect::<Vec<_>>());
    assert!(pruned.deletions.is_empty());

    let mut cfg = cfg_plain;
    let top = lap.start + lap.len() / 2;
    cfg.keep_windows.push(TimeWindow {
        start_s: path[top].t_s,
        end_s: path[top + 3].t_s,
    });
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "keep window");
    assert!(pruned.deletions.is_empty());
}

#[test]
fn a_path_back_at_its_start_keeps_its_end_and_its_kept_regions() {
    // A 4 m square, ending exactly where it began.
    let mut d = Drive::start(0.0, 0.0, 0.0);
    for _ in 0..4 {
        d.straight(4.0, 0.02).turn(FRAC_PI_2, 5);
    }
    let mut path = d.path();
    path.last_mut().unwrap().pose.x_m = 0.0;
    path.last_mut().unwrap().pose.y_m = 0.0;
    let n = path.len();

    let cfg_plain = cfg(0.1);
    let pruned = remove_redundancy(&path, &cfg_plain).unwrap();
    check_invariants(&path, &cfg_plain, &pruned, "closed square");
    assert_eq!(pruned.kept, vec![0, n - 1], "start and end survive");

    let mut cfg = cfg_plain;
    cfg.keep_regions.push(KeepRegion::Rectangle {
        min_x_m: 3.5,
        min_y_m: 3.5,
        max_x_m: 4.5,
        max_y_m: 4.5,
    });
    let pruned = remove_redundancy(&path, &cfg).unwrap();
    check_invariants(&path, &cfg, &pruned, "closed square with a kept corner");
    let corner: Vec<usize> = (0..n)
        .filter(|&k| cfg.keep_regions[0].contains(path[k].position()))
        .collect();
    assert!(corner.len() > 40);
    assert!(corner.iter().all(|k| pruned.kept.contains(k)));
    assert_eq!(pruned.kept.last(), Some(&(n - 1)));
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
    assert!(pruned.deletions.is_empty() && pruned.pinches.is_empty());

    for short in [vec![], path[..1].to_vec(), path[..2].to_vec()] {
        let pruned = remove_redundancy(&short, &cfg).unwrap();
        assert_eq!(pruned.kept, (0..short.len()).collect::<Vec<_>>());
    }
}

#[test]
fn bad_settings_and_samples_are_named() {
    let (path, _) = one_loop();
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
}
