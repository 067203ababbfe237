//! Scan matching: the pose that puts a set of range endpoints (in the
//! sensor's or the robot's frame) onto a [`Reference`]: the site's walls
//! ([`SegmentMap`]), the previous scan ([`ScanReference`], laser odometry)
//! or a map of points ([`PointMap`]). One matcher for all three.
//!
//! Gauss-Newton on the point-to-line residuals of the reference (Censi's
//! PL-ICP metric), with Huber weights so that a few readings of something
//! the reference lacks pull little, points farther than `outlier_m` from it
//! left out and, when `trim_fraction` < 1, the worst share of the rest
//! trimmed (occlusions and what moved between two views). The step
//! is taken only along directions the points constrain (the eigenvectors
//! of the normal matrix above a floor): a corridor's walls say nothing
//! about where along the corridor the robot is, and the matcher leaves that
//! coordinate where the prior put it. The result carries the information
//! matrix of the constrained directions for the filter and, when every
//! direction is constrained, the covariance of the pose from the residuals.
//! [`register`] says why it refuses a match ([`Refusal`]).
//!
//! [`search`] first tries a grid of poses around the prior and starts from
//! the best: a few IR readings give a cost with narrow valleys that
//! Gauss-Newton alone reaches only from close by.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::{Reference, Refusal};

#[cfg(doc)]
use super::{PointMap, ScanReference, SegmentMap};

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
    /// Share of the inliers kept, the best by residual (1 keeps all; PL-ICP
    /// trims to about 0.9 for scan-to-scan, where parts of one view are
    /// hidden from the other).
    pub trim_fraction: f64,
    /// Fewer readings than this are refused before matching.
    pub min_points: usize,
    /// A match whose weakest direction carries less than this share of the
    /// strongest's information is refused as degenerate (a corridor, one
    /// wall). Judged with the heading in metres at the readings' RMS range,
    /// so the ratio has no units. 0 never refuses: the localizer keeps the
    /// constrained directions and leaves the rest to its prior.
    pub min_information_ratio: f64,
    /// Gauss-Newton stops when a step is below this (m and rad).
    pub converged_step: f64,
    /// Once the steps are below a millimetre and a milliradian, hold each
    /// point's pairing with the reference (ICP's associate-then-solve):
    /// the last steps then cost a few multiplications a point.
    pub hold_pairings: bool,
    /// Until the steps are below a millimetre and a milliradian, match
    /// every this-many-th point only (1: all).
    pub coarse_stride: usize,
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
            trim_fraction: 1.0,
            min_points: 8,
            min_information_ratio: 0.0,
            converged_step: 1e-4,
            hold_pairings: false,
            coarse_stride: 1,
        }
    }
}

impl MatchSettings {
    /// Scan-to-scan (laser odometry) and scan-to-point-map: PL-ICP's
    /// trimming, a wider outlier cut for priors a few degrees off at a few
    /// metres, refusal of degenerate views, and convergence to 10 µm.
    pub fn scan_to_scan() -> Self {
        Self {
            max_iterations: 40,
            outlier_m: 0.3,
            huber_m: 0.05,
            point_std_m: 0.02,
            independent_points: 60.0,
            min_inliers: 40,
            max_rms_m: 0.1,
            degenerate_ratio: 1e-6,
            trim_fraction: 0.9,
            min_points: 60,
            min_information_ratio: 0.02,
            converged_step: 1e-5,
            hold_pairings: true,
            coarse_stride: 2,
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
    /// Covariance of the pose (m², rad²) from the residuals' spread,
    /// inflated as the information is for readings that are not
    /// independent; `None` unless every direction is constrained.
    pub covariance: Option<[[f64; 3]; 3]>,
    pub inliers: usize,
    pub rms_m: f64,
    /// Gauss-Newton iterations taken.
    pub iterations: usize,
}

/// Normal equations of one linearisation.
struct Normal {
    h: Matrix3<f64>,
    b: Vector3<f64>,
    inliers: usize,
    sum_sq: f64,
    /// Σ w r² of the inliers (Huber weights).
    weighted_sq: f64,
    /// Σ (x² + y²) of the inliers' readings in the sensor frame.
    range_sq: f64,
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

/// The normal equations at `pose`: each point against the reference, or
/// against its `held` pairing when there is one.
#[allow(clippy::too_many_arguments)]
fn normal<R: Reference + ?Sized>(
    reference: &R,
    held: Option<&[Option<R::Feature>]>,
    points: &[[f64; 2]],
    pose: &[f64; 3],
    settings: &MatchSettings,
    with_jacobian: bool,
    keep_below: f64,
    abs: Option<&mut Vec<f64>>,
) -> Normal {
    let (s, c) = pose[2].sin_cos();
    let outlier_cost = huber(settings.outlier_m, settings.huber_m).1;
    // Accumulated as plain sums (the compiler keeps them in registers; the
    // residuals for trimming go to a slice sized beforehand, so the loop
    // makes no calls).
    let mut h = [0.0f64; 6];
    let mut b = [0.0f64; 3];
    let (mut cost, mut sum_sq, mut weighted_sq, mut range_sq) = (0.0, 0.0, 0.0, 0.0);
    let mut inliers = 0;
    let (mut abs, mut kept) = match abs {
        Some(abs) => {
            abs.clear();
            abs.resize(points.len(), 0.0);
            (Some(abs), 0)
        }
        None => (None, 0),
    };
    for (i, p) in points.iter().enumerate() {
        let (rx, ry) = (c * p[0] - s * p[1], s * p[0] + c * p[1]);
        let (x, y) = (pose[0] + rx, pose[1] + ry);
        let found = match held {
            None => reference.residual(x, y),
            Some(held) => held[i].as_ref().map(|f| reference.measure(f, x, y)),
        };
        let Some((r, g)) = found else {
            cost += outlier_cost;
            continue;
        };
        if r.abs() > settings.outlier_m {
            cost += outlier_cost;
            continue;
        }
        if let Some(abs) = abs.as_deref_mut() {
            abs[kept] = r.abs();
            kept += 1;
        }
        // Trimmed: beyond the share kept at the previous linearisation.
        if r.abs() > keep_below {
            cost += outlier_cost;
            continue;
        }
        let (w, rho) = huber(r, settings.huber_m);
        cost += rho;
        inliers += 1;
        sum_sq += r * r;
        weighted_sq += w * r * r;
        range_sq += p[0] * p[0] + p[1] * p[1];
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
    if let Some(abs) = abs {
        abs.truncate(kept);
    }
    Normal {
        h: Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5]),
        b: Vector3::new(b[0], b[1], b[2]),
        inliers,
        sum_sq,
        weighted_sq,
        range_sq,
        cost,
    }
}

/// The |residual| below which `fraction` of `abs` lie (reorders `abs`).
fn quantile(abs: &mut [f64], fraction: f64) -> f64 {
    if abs.is_empty() {
        return f64::INFINITY;
    }
    let keep = ((abs.len() as f64 * fraction).ceil() as usize).clamp(1, abs.len());
    let (_, kth, _) = abs.select_nth_unstable_by(keep - 1, f64::total_cmp);
    *kth
}

/// The eigen-decomposition of `h` with degenerate directions zeroed.
fn constrained(h: &Matrix3<f64>, ratio: f64) -> (SymmetricEigen<f64, nalgebra::U3>, [bool; 3]) {
    let eig = SymmetricEigen::new(*h);
    let top = eig.eigenvalues.max();
    let keep = [0, 1, 2].map(|i| top > 0.0 && eig.eigenvalues[i] > ratio * top);
    (eig, keep)
}

/// Gauss-Newton from `prior` (x, y, heading) on `points` (sensor frame):
/// the pose of the sensor in the reference's frame, or why there is none.
pub fn register<R: Reference + ?Sized>(
    reference: &R,
    points: &[[f64; 2]],
    prior: [f64; 3],
    settings: &MatchSettings,
) -> Result<ScanMatch, Refusal> {
    if points.len() < settings.min_points {
        return Err(Refusal::TooFewPoints {
            points: points.len(),
            needed: settings.min_points,
        });
    }
    let mut pose = prior;
    let mut last = None;
    let mut iterations = 0;
    // Trimming keeps the inliers whose |residual| is at most `keep_below`,
    // the quantile of the previous linearisation's (so one pass over the
    // points an iteration; the first keeps all).
    let trimming = settings.trim_fraction < 1.0;
    let mut keep_below = f64::INFINITY;
    let mut settled = false;
    let mut abs = Vec::new();
    // The pairings held once the pose has settled (`hold_pairings`).
    let mut held: Option<Vec<Option<R::Feature>>> = None;
    // Until the pose settles, every `stride`-th point.
    let stride = settings.coarse_stride.max(1);
    let coarse: Vec<[f64; 2]> = if stride > 1 {
        points.iter().step_by(stride).copied().collect()
    } else {
        Vec::new()
    };
    for _ in 0..settings.max_iterations {
        iterations += 1;
        let trim = trimming.then_some(&mut abs);
        let n = if held.is_none() && !settled && stride > 1 {
            let mut n = normal(
                reference, None, &coarse, &pose, settings, true, keep_below, trim,
            );
            n.inliers *= stride;
            n
        } else {
            let held = held.as_deref();
            normal(
                reference, held, points, &pose, settings, true, keep_below, trim,
            )
        };
        // The trimmed set settles once the steps are small: changing it
        // then would only make the last steps chatter.
        if trimming && !settled {
            keep_below = quantile(&mut abs, settings.trim_fraction);
        }
        if n.inliers < settings.min_inliers {
            return Err(Refusal::TooFewInliers {
                inliers: n.inliers,
                needed: settings.min_inliers,
            });
        }
        // A matcher that refuses degenerate matches at the end steps by
        // a plain solve while it can; otherwise only along the directions
        // the points constrain.
        let solved = if settings.min_information_ratio > 0.0 {
            n.h.cholesky().map(|c| -c.solve(&n.b))
        } else {
            None
        };
        let mut step = match solved {
            Some(step) => step,
            None => {
                let (eig, keep) = constrained(&n.h, settings.degenerate_ratio);
                let mut step = Vector3::zeros();
                for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
                    let u = eig.eigenvectors.column(i);
                    step -= u * (u.dot(&n.b) / eig.eigenvalues[i]);
                }
                step
            }
        };
        // At most 10 cm and 0.1 rad a step: the linearisation holds that far.
        let scale = (step.x.hypot(step.y) / 0.1)
            .max(step.z.abs() / 0.1)
            .max(1.0);
        step /= scale;
        pose = [pose[0] + step.x, pose[1] + step.y, pose[2] + step.z];
        settled |= step.x.hypot(step.y) < 1e-2 && step.z.abs() < 1e-2;
        if settled && settings.hold_pairings && held.is_none() {
            let (s, c) = pose[2].sin_cos();
            held = Some(
                points
                    .iter()
                    .map(|p| {
                        let x = pose[0] + c * p[0] - s * p[1];
                        let y = pose[1] + s * p[0] + c * p[1];
                        reference.associate(x, y)
                    })
                    .collect(),
            );
        }
        // Converged: this linearisation serves for the information too.
        if step.x.hypot(step.y) < settings.converged_step && step.z.abs() < settings.converged_step
        {
            last = Some(n);
            break;
        }
    }
    pose[2] = twindrive_kinematics::wrap_angle(pose[2]);
    let n = last.unwrap_or_else(|| {
        let held = held.as_deref();
        normal(
            reference, held, points, &pose, settings, true, keep_below, None,
        )
    });
    if n.inliers < settings.min_inliers {
        return Err(Refusal::TooFewInliers {
            inliers: n.inliers,
            needed: settings.min_inliers,
        });
    }
    let rms_m = (n.sum_sq / n.inliers as f64).sqrt();
    if rms_m > settings.max_rms_m {
        return Err(Refusal::RmsTooLarge {
            rms_m,
            max_m: settings.max_rms_m,
        });
    }
    if settings.min_information_ratio > 0.0 {
        let (ratio, direction) = weakest_direction(&n);
        if ratio < settings.min_information_ratio {
            return Err(Refusal::Degenerate {
                direction,
                ratio,
                min_ratio: settings.min_information_ratio,
            });
        }
    }
    let (eig, keep) = constrained(&n.h, settings.degenerate_ratio);
    let inflation = (n.inliers as f64 / settings.independent_points).max(1.0);
    let variance = settings.point_std_m.powi(2) * inflation;
    let mut info = Matrix3::zeros();
    let mut rank = 0;
    for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
        let u = eig.eigenvectors.column(i);
        info += u * u.transpose() * (eig.eigenvalues[i] / variance);
        rank += 1;
    }
    let covariance = if rank == 3 && n.inliers > 3 {
        let residual_variance = n.weighted_sq / (n.inliers - 3) as f64;
        n.h.try_inverse().map(|inv| {
            let cov = inv * (residual_variance * inflation);
            [0, 1, 2].map(|r| [0, 1, 2].map(|c| cov[(r, c)]))
        })
    } else {
        None
    };
    Ok(ScanMatch {
        pose,
        information: [0, 1, 2].map(|r| [0, 1, 2].map(|c| info[(r, c)])),
        rank,
        covariance,
        inliers: n.inliers,
        rms_m,
        iterations,
    })
}

/// The weakest direction of the normal matrix with the heading in metres
/// at the readings' RMS range: its share of the strongest's information
/// and the direction (x, y in m; heading in rad).
fn weakest_direction(n: &Normal) -> (f64, [f64; 3]) {
    let range_m = (n.range_sq / n.inliers.max(1) as f64).sqrt().max(1e-3);
    let d = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 1.0 / range_m));
    let eig = SymmetricEigen::new(d * n.h * d);
    let (mut lo, mut hi) = (0, 0);
    for i in 1..3 {
        if eig.eigenvalues[i] < eig.eigenvalues[lo] {
            lo = i;
        }
        if eig.eigenvalues[i] > eig.eigenvalues[hi] {
            hi = i;
        }
    }
    let top = eig.eigenvalues[hi];
    let ratio = if top > 0.0 {
        (eig.eigenvalues[lo] / top).max(0.0)
    } else {
        0.0
    };
    let u = eig.eigenvectors.column(lo);
    let mut direction = [u[0], u[1], u[2] / range_m];
    let norm = direction.iter().map(|v| v * v).sum::<f64>().sqrt();
    let sign = if direction[0].abs() >= direction[1].abs() {
        direction[0].signum()
    } else {
        direction[1].signum()
    };
    for v in &mut direction {
        *v *= sign / norm.max(f64::MIN_POSITIVE);
    }
    (ratio, direction)
}

/// [`register`] for callers that need only the match (the localizer).
pub fn match_points<R: Reference + ?Sized>(
    reference: &R,
    points: &[[f64; 2]],
    prior: [f64; 3],
    settings: &MatchSettings,
) -> Option<ScanMatch> {
    register(reference, points, prior, settings).ok()
}

/// The robust cost of `points` at `pose` (lower is better).
pub fn cost<R: Reference + ?Sized>(
    map: &R,
    points: &[[f64; 2]],
    pose: [f64; 3],
    settings: &MatchSettings,
) -> f64 {
    normal(
        map,
        None,
        points,
        &pose,
        settings,
        false,
        f64::INFINITY,
        None,
    )
    .cost
}

/// A grid of `steps` poses a side (odd) within `half_width` (x, y, heading)
/// of `prior`, then Gauss-Newton from the cheapest.
pub fn search<R: Reference + ?Sized>(
    map: &R,
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
    use crate::localize::SegmentMap;
    use crate::localize::testkit::room;

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
