//! Mapping held-out-style sites: a ring of corridor around a random
//! central block in a random room, with random boxes, driven one and a
//! quarter laps by odometry whose scale and turn are off by 0.4-0.8 %
//! (what a fair calibration leaves), a lidar at a random mount with 1-3 cm
//! of noise and dropouts. The map must put 95 % of its occupied cells
//! within 5 cm of a true wall and draw 90 % of the wall the lidar saw,
//! where the odometry alone draws the walls twice after the loop.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal as Gauss};
use twindrive_sim::{Vector, World};

use super::*;
use crate::localize::Scan;
use crate::localize::testkit::{compose, rng};
use crate::se2::between;

struct Site {
    walls: Vec<[f64; 4]>,
    /// The corridor's centre line: a rectangle inside the ring.
    loop_min: [f64; 2],
    loop_max: [f64; 2],
}

fn rect(min: [f64; 2], max: [f64; 2]) -> [[f64; 4]; 4] {
    [
        [min[0], min[1], max[0], min[1]],
        [max[0], min[1], max[0], max[1]],
        [max[0], max[1], min[0], max[1]],
        [min[0], max[1], min[0], min[1]],
    ]
}

fn site(rng: &mut ChaCha8Rng) -> Site {
    let (w, h) = (rng.random_range(7.0..11.0), rng.random_range(6.0..9.0));
    let corridor = rng.random_range(1.4..2.0);
    let mut walls: Vec<[f64; 4]> = rect([0.0, 0.0], [w, h]).to_vec();
    walls.extend(rect([corridor, corridor], [w - corridor, h - corridor]));
    // Boxes against the outer walls, clear of the centre line.
    for _ in 0..rng.random_range(2..6) {
        let s = rng.random_range(0.15..0.35);
        let (x, y) = match rng.random_range(0..4) {
            0 => (rng.random_range(0.5..w - 1.0), 0.05),
            1 => (rng.random_range(0.5..w - 1.0), h - 0.05 - s),
            2 => (0.05, rng.random_range(0.5..h - 1.0)),
            _ => (w - 0.05 - s, rng.random_range(0.5..h - 1.0)),
        };
        walls.extend(rect([x, y], [x + s, y + s]));
    }
    let half = corridor / 2.0;
    Site {
        walls,
        loop_min: [half, half],
        loop_max: [w - half, h - half],
    }
}

/// Poses every 0.1 s at 0.3 m/s around the corridor's centre line,
/// counter-clockwise with rounded corners, for `laps` laps.
fn drive(site: &Site, laps: f64) -> Vec<[f64; 3]> {
    let (a, b) = (site.loop_min, site.loop_max);
    let r = 0.4;
    // Straight legs and quarter turns, as (length, curvature).
    let turn = (std::f64::consts::FRAC_PI_2 * r, 1.0 / r);
    let (along_x, along_y) = ((b[0] - a[0] - 2.0 * r, 0.0), (b[1] - a[1] - 2.0 * r, 0.0));
    let legs = [along_x, turn, along_y, turn, along_x, turn, along_y, turn];
    let lap: f64 = legs.iter().map(|l| l.0).sum();
    let ds = 0.03;
    let steps = (laps * lap / ds) as usize;
    let mut pose = [a[0] + r, a[1], 0.0];
    let mut out = vec![pose];
    let mut s_in_leg = 0.0;
    let mut leg = 0;
    for _ in 0..steps {
        let (len, k) = legs[leg];
        let dth = k * ds;
        pose = compose(pose, [ds * (0.5 * dth).cos(), ds * (0.5 * dth).sin(), dth]);
        out.push(pose);
        s_in_leg += ds;
        if s_in_leg >= len {
            s_in_leg -= len;
            leg = (leg + 1) % legs.len();
        }
    }
    out
}

/// Odometry of a true track: each step's length and turn scaled by the
/// calibration's errors, with a little noise; starts at the true pose.
fn odometry(truth: &[[f64; 3]], scale: f64, turn: f64, rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
    let noise = Gauss::new(0.0, 1e-4).unwrap();
    let mut pose = truth[0];
    let mut out = vec![pose];
    for w in truth.windows(2) {
        let (s, c) = w[0][2].sin_cos();
        let (dx, dy) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
        let local = [c * dx + s * dy, -s * dx + c * dy];
        let dth = twindrive_kinematics::wrap_angle(w[1][2] - w[0][2]);
        let step = [
            local[0] * (1.0 + scale) + noise.sample(rng),
            local[1] * (1.0 + scale),
            dth * (1.0 + turn) + noise.sample(rng),
        ];
        pose = compose(pose, step);
        out.push(pose);
    }
    out
}

/// A 360-beam scan from the sensor pose, and where its returns truly met
/// the walls.
fn scan(
    world: &World,
    sensor: [f64; 3],
    noise_std_m: f64,
    rng: &mut ChaCha8Rng,
) -> (Scan, Vec<[f64; 2]>) {
    let beams = 360;
    let max_range_m = 8.0;
    let noise = Gauss::new(0.0, noise_std_m).unwrap();
    let increment_rad = std::f64::consts::TAU / beams as f64;
    let angle_min_rad = -std::f64::consts::PI;
    let mut seen = Vec::new();
    let ranges_m = (0..beams)
        .map(|i| {
            let a = sensor[2] + angle_min_rad + i as f64 * increment_rad;
            let dir = Vector::new(a.cos(), a.sin());
            let r = world.cast_ray(Vector::new(sensor[0], sensor[1]), dir, max_range_m);
            let noisy = r + noise.sample(rng);
            if r >= max_range_m || rng.random::<f64>() < 0.02 || noisy >= max_range_m {
                return f32::INFINITY;
            }
            seen.push([sensor[0] + r * a.cos(), sensor[1] + r * a.sin()]);
            noisy as f32
        })
        .collect();
    (
        Scan {
            t_s: 0.0,
            angle_min_rad,
            increment_rad,
            range_min_m: 0.05,
            range_max_m: max_range_m,
            ranges_m,
        },
        seen,
    )
}

struct Case {
    site: Site,
    truth: Vec<[f64; 3]>,
    scans: Vec<(Scan, [f64; 3])>,
    seen: Vec<[f64; 2]>,
    mount: [f64; 3],
}

fn case(seed: u64, laps: f64) -> Case {
    let mut rng = rng(seed);
    let site = site(&mut rng);
    case_on(site, &mut rng, laps)
}

/// A drive `laps` around `site`'s loop, with odometry, lidar and noise
/// drawn from `rng`.
fn case_on(site: Site, rng: &mut ChaCha8Rng, laps: f64) -> Case {
    let world = World::from_walls(&site.walls, &[]);
    let mount = [
        rng.random_range(-0.05..0.05),
        rng.random_range(-0.05..0.05),
        rng.random_range(-3.1..3.1),
    ];
    let sign = |rng: &mut ChaCha8Rng| if rng.random::<bool>() { 1.0 } else { -1.0 };
    let scale = sign(rng) * rng.random_range(0.004..0.008);
    let turn = sign(rng) * rng.random_range(0.004..0.008);
    let noise_std_m = rng.random_range(0.01..0.03);
    let truth = drive(&site, laps);
    let odo = odometry(&truth, scale, turn, rng);
    let mut seen = Vec::new();
    let mut scans = Vec::new();
    // A scan every step: 0.1 s at 0.3 m/s.
    for (t, o) in truth.iter().zip(&odo) {
        let (s, hits) = scan(&world, compose(*t, mount), noise_std_m, rng);
        seen.extend(hits);
        scans.push((s, *o));
    }
    Case {
        site,
        truth,
        scans,
        seen,
        mount,
    }
}

/// `scans` with their odometry moved so that the drive claims to start at
/// `start` (its shape kept).
fn claiming(scans: &[(Scan, [f64; 3])], start: [f64; 3]) -> Vec<(Scan, [f64; 3])> {
    let at = scans[0].1;
    scans
        .iter()
        .map(|(s, o)| (s.clone(), compose(start, between(at, *o))))
        .collect()
}

fn draw(case: &Case, poses: &[[f64; 3]]) -> LogOddsGrid {
    let settings = MappingSettings::default();
    let surfaces = Surfaces::new(&case.scans, poses, case.mount, settings);
    let mut grid = LogOddsGrid::new(settings.resolution_m, settings.log_odds);
    for ((s, _), p) in case.scans.iter().zip(poses) {
        surfaces.draw(&mut grid, *p, s);
    }
    grid
}

#[test]
fn a_loop_is_drawn_once_within_5_cm_of_the_walls() {
    for seed in 4_100..4_103 {
        let case = case(seed, 1.25);
        let mapped = map_drive(
            &case.scans,
            case.mount,
            MappingSettings::default(),
            None,
            |_, _| {},
        );
        let s = score(&mapped.grid, &case.site.walls, &case.seen, 0.05);
        let worst_pose = mapped
            .poses
            .iter()
            .zip(&case.truth)
            .map(|(p, t)| (p[0] - t[0]).hypot(p[1] - t[1]))
            .fold(0.0, f64::max);
        eprintln!(
            "seed {seed}: {} cells, {:.1} % on a wall (worst {:.3} m), {:.1} % of {:.1} m seen drawn, \
             {}/{} scans matched, worst pose {:.1} mm",
            s.occupied_cells,
            100.0 * s.on_a_wall,
            s.worst_m,
            100.0 * s.seen_drawn,
            s.seen_wall_m,
            mapped.matched,
            case.scans.len(),
            1e3 * worst_pose
        );
        assert!(s.on_a_wall >= 0.95, "seed {seed}: {s:?}");
        assert!(s.seen_drawn >= 0.90, "seed {seed}: {s:?}");
        assert!(worst_pose < 0.05, "seed {seed}: a pose {worst_pose} m off");
        assert!(
            mapped.matched + 1 >= case.scans.len() * 9 / 10,
            "seed {seed}"
        );
        // The odometry alone, drawn the same way, has drifted by the end
        // of the lap: its walls are drawn twice.
        let odo: Vec<[f64; 3]> = case.scans.iter().map(|(_, o)| *o).collect();
        let dead = score(&draw(&case, &odo), &case.site.walls, &case.seen, 0.05);
        assert!(
            dead.on_a_wall < 0.9,
            "seed {seed}: the odometry alone would have done: {dead:?}"
        );
    }
}

#[test]
fn no_beam_no_knowledge_and_a_prior_map_keeps_its_frame() {
    let case = case(4_200, 1.0);
    let half = case.scans.len() / 2;
    let first = map_drive(
        &case.scans[..half],
        case.mount,
        MappingSettings::default(),
        None,
        |_, _| {},
    );
    // The second half, from a start the odometry misplaces by a further
    // 11 cm and 3 degrees, is located in the first half's map.
    let second = claiming(
        &case.scans[half..],
        compose(case.scans[half].1, [0.1, -0.05, 0.05]),
    );
    let both = map_drive(
        &second,
        case.mount,
        MappingSettings::default(),
        Some(&first.grid),
        |_, _| {},
    );
    let err = (both.poses[10][0] - case.truth[half + 10][0])
        .hypot(both.poses[10][1] - case.truth[half + 10][1]);
    assert!(
        err < 0.03,
        "the second half is located in the first's frame: {err} m"
    );
    let s = score(&both.grid, &case.site.walls, &case.seen, 0.05);
    assert!(s.on_a_wall >= 0.95 && s.seen_drawn >= 0.9, "{s:?}");
    // Inside the central block no beam reached: unknown, not free.
    let mid = [
        0.5 * (case.site.loop_min[0] + case.site.loop_max[0]),
        0.5 * (case.site.loop_min[1] + case.site.loop_max[1]),
    ];
    assert_eq!(both.grid.state_at(mid), CellState::Unknown);
    // The corridor where the robot drove is free.
    assert_eq!(
        both.grid.state_at([case.truth[5][0], case.truth[5][1]]),
        CellState::Free
    );
}

/// A drive whose log says it started metres and up to half a turn from
/// where it did is placed on the map drawn before, by a search over the
/// whole map, and agrees with it; a drive on another site matches nowhere
/// on it, or, placed where its first metres fit, disagrees.
#[test]
fn a_drive_that_starts_elsewhere_is_placed_on_the_prior_and_another_sites_is_not() {
    for seed in 4_300..4_304 {
        let case = case(seed, 1.0);
        let half = case.scans.len() / 2;
        let first = map_drive(
            &case.scans[..half],
            case.mount,
            MappingSettings::default(),
            None,
            |_, _| {},
        );
        let mut r = rng(seed + 50);
        let off = [
            r.random_range(1.0..4.0) * if r.random::<bool>() { 1.0 } else { -1.0 },
            r.random_range(1.0..4.0) * if r.random::<bool>() { 1.0 } else { -1.0 },
            r.random_range(-3.1..3.1),
        ];
        let claimed = compose(case.scans[half].1, off);
        let second = claiming(&case.scans[half..], claimed);
        let both = map_drive(
            &second,
            case.mount,
            MappingSettings::default(),
            Some(&first.grid),
            |_, _| {},
        );
        let placed = both.placement.expect("placed");
        let mut errs: Vec<f64> = both
            .poses
            .iter()
            .zip(&case.truth[half..])
            .map(|(p, t)| (p[0] - t[0]).hypot(p[1] - t[1]))
            .collect();
        errs.sort_by(f64::total_cmp);
        let p99 = errs[errs.len() * 99 / 100];
        let worst = errs[errs.len() - 1];
        eprintln!(
            "seed {seed}: claimed {:.2} m and {:.2} rad off; placed with score {:.2} (moved: {}), \
             agreement {:.3}, {}/{} scans matched, poses within {:.1} mm (99 %), worst {:.1} mm",
            off[0].hypot(off[1]),
            off[2],
            placed.score,
            placed.moved,
            both.prior_agreement.unwrap(),
            both.matched,
            second.len(),
            1e3 * p99,
            1e3 * worst
        );
        assert!(placed.moved, "seed {seed}");
        // (One seed has one scan the SLAM itself matched 18 cm astray.)
        assert!(p99 < 0.05, "seed {seed}: poses {p99} m off");
        assert!(both.matched * 10 >= second.len() * 9, "seed {seed}");
        let s = score(&both.grid, &case.site.walls, &case.seen, 0.05);
        assert!(s.on_a_wall >= 0.95, "seed {seed}: {s:?}");

        // Another site's drive, claimed at the same start: a hall with
        // pillars.
        let mut r = rng(seed + 1_000);
        let (w, h) = (r.random_range(10.0..14.0), r.random_range(8.0..11.0));
        let mut walls: Vec<[f64; 4]> = rect([0.0, 0.0], [w, h]).to_vec();
        for k in 0..4 {
            let (x, y) = (
                w * (0.3 + 0.4 * f64::from(k % 2)),
                h * (0.3 + 0.4 * f64::from(k / 2)),
            );
            walls.extend(rect([x - 0.2, y - 0.2], [x + 0.2, y + 0.2]));
        }
        let hall = Site {
            walls,
            loop_min: [1.2, 1.2],
            loop_max: [w - 1.2, h - 1.2],
        };
        let other = case_on(hall, &mut r, 0.5);
        let stranger = claiming(&other.scans, claimed);
        let lost = map_drive(
            &stranger,
            other.mount,
            MappingSettings::default(),
            Some(&first.grid),
            |_, _| {},
        );
        eprintln!(
            "seed {seed}: another site's drive: placement {:?}, agreement {:.3}, {}/{} scans matched",
            lost.placement.map(|p| p.score),
            lost.prior_agreement.unwrap(),
            lost.matched,
            stranger.len()
        );
        assert!(
            lost.placement.is_none() || lost.prior_agreement.unwrap() < 0.6,
            "seed {seed}: another site's drive agrees with this map"
        );
        assert!(both.prior_agreement.unwrap() > 0.9, "seed {seed}");
    }
}
