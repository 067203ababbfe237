//! Scan-to-map matching: the pose that puts a set of range endpoints (in
//! the robot's frame) onto the site's walls.
//!
//! Gauss-Newton on the point-to-wall residuals of [`SegmentMap`], with Huber
//! weights so that a few readings of something the map lacks pull little,
//! and points farther than `outlier_m` from every wall left out. The step
//! is taken only along directions the points constrain (the eigenvectors
//! of the normal matrix above a floor): a corridor's walls say nothing
//! about where along the corridor the robot is, and the matcher leaves that
//! coordinate where the prior put it. The result carries the information
//! matrix of the constrained directions for the filter.
//!
//! [`search`] first tries a grid of poses around the prior and starts from
//! the best: a few IR readings give a cost with narrow valleys that
//! Gauss-Newton alone reaches only from close by.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::SegmentMap;

/// How points are matched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchSettings {
    /// Gauss-Newton iterations at most.
    pub max_iterations: usize,
    /// Points farther than this from every wall are left out (m).
    pub outlier_m: f64,
    /// Residuals beyond this are weighted down (Huber, m).
    pub huber_m: f64,
    /// One reading's error against the map: sensor noise and the map's own
    /// (m).
    pub point_std_m: f64,
    /// Readings of one match are not independent (map discretisation, beam
    /// width, the same wall seen many times): the information claimed is at
    /// most this many readings' worth.
    pub independent_points: f64,
    /// Fewer inliers than this give no match.
    pub min_inliers: usize,
    /// A match whose inliers' RMS residual is larger than this is refused (m).
    pub max_rms_m: f64,
    /// Directions whose information is below this share of the largest's
    /// are left alone (degenerate).
    pub degenerate_ratio: f64,
}

impl Default for MatchSettings {
    fn default() -> Self {
        Self {
            max_iterations: 12,
            outlier_m: 0.25,
            huber_m: 0.03,
            point_std_m: 0.02,
            independent_points: 20.0,
            min_inliers: 8,
            max_rms_m: 0.05,
            degenerate_ratio: 1e-3,
        }
    }
}

/// A matched pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanMatch {
    /// x, y (m), heading (rad).
    pub pose: [f64; 3],
    /// Information (inverse covariance) of the pose along the directions the
    /// points constrain; zero along the others.
    pub information: [[f64; 3]; 3],
    /// Directions constrained (0 to 3).
    pub rank: usize,
    pub inliers: usize,
    pub rms_m: f64,
}

/// Normal equations of one linearisation.
struct Normal {
    h: Matrix3<f64>,
    b: Vector3<f64>,
    inliers: usize,
    sum_sq: f64,
    cost: f64,
}

fn huber(r: f64, k: f64) -> (f64, f64) {
    let a = r.abs();
    if a <= k {
        (1.0, 0.5 * r * r)
    } else {
        (k / a, k * (a - 0.5 * k))
    }
}

fn normal(
    map: &SegmentMap,
    points: &[[f64; 2]],
    pose: &[f64; 3],
    settings: &MatchSettings,
    with_jacobian: bool,
) -> Normal {
    let (s, c) = pose[2].sin_cos();
    let mut n = Normal {
        h: Matrix3::zeros(),
        b: Vector3::zeros(),
        inliers: 0,
        sum_sq: 0.0,
        cost: 0.0,
    };
    let outlier_cost = huber(settings.outlier_m, settings.huber_m).1;
    // Accumulated as plain sums (the compiler keeps them in registers).
    let mut h = [0.0f64; 6];
    let mut b = [0.0f64; 3];
    for p in points {
        let (rx, ry) = (c * p[0] - s * p[1], s * p[0] + c * p[1]);
        let (x, y) = (pose[0] + rx, pose[1] + ry);
        let Some((r, g)) = map.residual(x, y) else {
            n.cost += outlier_cost;
            continue;
        };
        if r.abs() > settings.outlier_m {
            n.cost += outlier_cost;
            continue;
        }
        let (w, rho) = huber(r, settings.huber_m);
        n.cost += rho;
        n.inliers += 1;
        n.sum_sq += r * r;
        if with_jacobian {
            // d(point)/dθ = (-ry, rx).
            let j = [g[0], g[1], -g[0] * ry + g[1] * rx];
            h[0] += w * j[0] * j[0];
            h[1] += w * j[0] * j[1];
            h[2] += w * j[0] * j[2];
            h[3] += w * j[1] * j[1];
            h[4] += w * j[1] * j[2];
            h[5] += w * j[2] * j[2];
            b[0] += w * j[0] * r;
            b[1] += w * j[1] * r;
            b[2] += w * j[2] * r;
        }
    }
    n.h = Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5]);
    n.b = Vector3::new(b[0], b[1], b[2]);
    n
}

/// The eigen-decomposition of `h` with degenerate directions zeroed.
fn constrained(h: &Matrix3<f64>, ratio: f64) -> (SymmetricEigen<f64, nalgebra::U3>, [bool; 3]) {
    let eig = SymmetricEigen::new(*h);
    let top = eig.eigenvalues.max();
    let keep = [0, 1, 2].map(|i| top > 0.0 && eig.eigenvalues[i] > ratio * top);
    (eig, keep)
}

/// Gauss-Newton from `prior` (x, y, heading) on `points` (robot frame).
pub fn match_points(
    map: &SegmentMap,
    points: &[[f64; 2]],
    prior: [f64; 3],
    settings: &MatchSettings,
) -> Option<ScanMatch> {
    let mut pose = prior;
    let mut last = None;
    for _ in 0..settings.max_iterations {
        let n = normal(map, points, &pose, settings, true);
        if n.inliers < settings.min_inliers {
            return None;
        }
        let (eig, keep) = constrained(&n.h, settings.degenerate_ratio);
        let mut step = Vector3::zeros();
        for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
            let u = eig.eigenvectors.column(i);
            step -= u * (u.dot(&n.b) / eig.eigenvalues[i]);
        }
        // At most 10 cm and 0.1 rad a step: the linearisation holds that far.
        let scale = (step.x.hypot(step.y) / 0.1)
            .max(step.z.abs() / 0.1)
            .max(1.0);
        step /= scale;
        pose = [pose[0] + step.x, pose[1] + step.y, pose[2] + step.z];
        // Converged to a tenth of a millimetre: this linearisation serves
        // for the information too.
        if step.x.hypot(step.y) < 1e-4 && step.z.abs() < 1e-4 {
            last = Some(n);
            break;
        }
    }
    pose[2] = twindrive_kinematics::wrap_angle(pose[2]);
    let n = last.unwrap_or_else(|| normal(map, points, &pose, settings, true));
    if n.inliers < settings.min_inliers {
        return None;
    }
    let rms_m = (n.sum_sq / n.inliers as f64).sqrt();
    if rms_m > settings.max_rms_m {
        return None;
    }
    let (eig, keep) = constrained(&n.h, settings.degenerate_ratio);
    let variance =
        settings.point_std_m.powi(2) * (n.inliers as f64 / settings.independent_points).max(1.0);
    let mut info = Matrix3::zeros();
    let mut rank = 0;
    for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
        let u = eig.eigenvectors.column(i);
        info += u * u.transpose() * (eig.eigenvalues[i] / variance);
        rank += 1;
    }
    Some(ScanMatch {
        pose,
        information: [0, 1, 2].map(|r| [0, 1, 2].map(|c| info[(r, c)])),
        rank,
        inliers: n.inliers,
        rms_m,
    })
}

/// The robust cost of `points` at `pose` (lower is better).
pub fn cost(
    map: &SegmentMap,
    points: &[[f64; 2]],
    pose: [f64; 3],
    settings: &MatchSettings,
) -> f64 {
    normal(map, points, &pose, settings, false).cost
}

/// A grid of `steps` poses a side (odd) within `half_width` (x, y, heading)
/// of `prior`, then Gauss-Newton from the cheapest.
pub fn search(
    map: &SegmentMap,
    points: &[[f64; 2]],
    prior: [f64; 3],
    half_width: [f64; 3],
    steps: usize,
    settings: &MatchSettings,
) -> Option<ScanMatch> {
    let steps = steps.max(1) | 1;
    let half = (steps / 2) as f64;
    let offset = |k: usize, w: f64| {
        if steps == 1 {
            0.0
        } else {
            (k as f64 - half) / half * w
        }
    };
    let mut best = (cost(map, points, prior, settings), prior);
    for i in 0..steps {
        for j in 0..steps {
            for k in 0..steps {
                let pose = [
                    prior[0] + offset(i, half_width[0]),
                    prior[1] + offset(j, half_width[1]),
                    prior[2] + offset(k, half_width[2]),
                ];
                let c = cost(map, points, pose, settings);
                if c < best.0 {
                    best = (c, pose);
                }
            }
        }
    }
    match_points(map, points, best.1, settings)
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal as Gauss};

    use super::*;

    /// Endpoints of a full scan from `pose` (an 8 m range) among the walls,
    /// cast by the simulator's world, in the robot frame, with noise.
    fn scan(
        walls: &[[f64; 4]],
        pose: [f64; 3],
        beams: usize,
        rng: &mut ChaCha8Rng,
    ) -> Vec<[f64; 2]> {
        use twindrive_sim::{Vector, World};
        let world = World::from_walls(walls, &[]);
        let noise = Gauss::new(0.0, 0.01).unwrap();
        (0..beams)
            .filter_map(|i| {
                let a = i as f64 * std::f64::consts::TAU / beams as f64;
                let dir = Vector::new((pose[2] + a).cos(), (pose[2] + a).sin());
                let r = world.cast_ray(Vector::new(pose[0], pose[1]), dir, 8.0);
                (r < 8.0).then(|| {
                    let r = r + noise.sample(rng);
                    [r * a.cos(), r * a.sin()]
                })
            })
            .collect()
    }

    fn room(rng: &mut ChaCha8Rng) -> Vec<[f64; 4]> {
        let (w, h) = (rng.random_range(4.0..9.0), rng.random_range(4.0..9.0));
        let mut walls = vec![
            [0.0, 0.0, w, 0.0],
            [w, 0.0, w, h],
            [w, h, 0.0, h],
            [0.0, h, 0.0, 0.0],
        ];
        // A few boxes.
        for _ in 0..3 {
            let (x, y) = (
                rng.random_range(0.5..w - 1.0),
                rng.random_range(0.5..h - 1.0),
            );
            let s = rng.random_range(0.2..0.5);
            walls.extend([
                [x, y, x + s, y],
                [x + s, y, x + s, y + s],
                [x + s, y + s, x, y + s],
                [x, y + s, x, y],
            ]);
        }
        walls
    }

    #[test]
    fn a_scan_finds_the_true_pose_from_an_offset_prior_on_random_rooms() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let settings = MatchSettings::default();
        let mut worst = [0.0f64; 2];
        for _ in 0..40 {
            let walls = room(&mut rng);
            let map = SegmentMap::new(&walls, 0.05, 0.5);
            let truth = [
                rng.random_range(0.4..3.5),
                rng.random_range(0.4..3.5),
                rng.random_range(-3.1..3.1),
            ];
            if map.distance_m(truth[0], truth[1]).is_some_and(|d| d < 0.2) {
                continue;
            }
            let points = scan(&walls, truth, 360, &mut rng);
            let prior = [
                truth[0] + rng.random_range(-0.1..0.1),
                truth[1] + rng.random_range(-0.1..0.1),
                truth[2] + rng.random_range(-0.08..0.08),
            ];
            let m = match_points(&map, &points, prior, &settings).expect("a match");
            assert_eq!(m.rank, 3, "a room constrains every direction");
            let e = (m.pose[0] - truth[0]).hypot(m.pose[1] - truth[1]);
            let eh = twindrive_kinematics::wrap_angle(m.pose[2] - truth[2]).abs();
            worst = [worst[0].max(e), worst[1].max(eh)];
        }
        assert!(worst[0] < 0.01 && worst[1] < 0.005, "worst error {worst:?}");
    }

    #[test]
    fn a_corridor_leaves_the_along_coordinate_to_the_prior() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let walls = [[-50.0, 0.0, 50.0, 0.0], [-50.0, 2.0, 50.0, 2.0]];
        let map = SegmentMap::new(&walls, 0.05, 0.5);
        let truth = [0.0, 0.8, 0.1];
        let points = scan(&walls, truth, 360, &mut rng);
        let points: Vec<[f64; 2]> = points
            .into_iter()
            .filter(|p| p[0].hypot(p[1]) < 4.0)
            .collect();
        let prior = [0.3, 0.9, 0.05];
        let m = match_points(&map, &points, prior, &MatchSettings::default()).expect("a match");
        assert_eq!(m.rank, 2, "along the corridor is unconstrained");
        assert!((m.pose[0] - 0.3).abs() < 1e-6, "x stays at the prior");
        assert!((m.pose[1] - 0.8).abs() < 0.01 && (m.pose[2] - 0.1).abs() < 0.01);
        // No information along x.
        assert!(m.information[0][0].abs() < 1e-6 * m.information[1][1]);
    }

    #[test]
    fn a_few_beams_along_a_corner_are_found_by_search() {
        // Twenty IR readings of one wall and its corner, from a robot that
        // moved along it: the grid search starts Gauss-Newton in the valley.
        let walls = [[0.0, 0.0, 3.0, 0.0], [3.0, 0.0, 3.0, 3.0]];
        let map = SegmentMap::new(&walls, 0.05, 0.5);
        let truth = [2.2, 0.4, 0.0];
        let mut points = Vec::new();
        for k in 0..20 {
            let x = 2.2 - 0.5 + k as f64 * 0.025;
            points.push([x - truth[0], 0.0 - truth[1]]);
            points.push([3.0 - truth[0], 0.2 + k as f64 * 0.03 - truth[1]]);
        }
        let prior = [2.28, 0.46, 0.04];
        let settings = MatchSettings::default();
        let m = search(&map, &points, prior, [0.1, 0.1, 0.06], 7, &settings).expect("a match");
        assert!(
            (m.pose[0] - truth[0]).abs() < 0.005 && (m.pose[1] - truth[1]).abs() < 0.005,
            "{:?}",
            m.pose
        );
        assert!(m.pose[2].abs() < 0.005);
    }

    #[test]
    fn points_off_the_map_give_no_match() {
        let map = SegmentMap::new(&[[0.0, 0.0, 1.0, 0.0]], 0.05, 0.3);
        let points = vec![[5.0, 5.0]; 40];
        assert!(match_points(&map, &points, [0.0; 3], &MatchSettings::default()).is_none());
    }
}
