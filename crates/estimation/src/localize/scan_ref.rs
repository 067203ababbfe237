//! The previous scan as a reference, for scan-to-scan matching (laser
//! odometry): its endpoints beam by beam, each with the normal of the line
//! its neighbours lie along.
//!
//! A point is paired with the reference's reading on the same bearing from
//! the reference's origin (projective association, O(1) a point: the beam
//! it falls on, then the nearest return within a few beams) and measured
//! against that reading's tangent line: Censi's PL-ICP metric, with the
//! line from the neighbourhood rather than two readings, so that range
//! noise tilts it less.

use super::Scan;
use super::reference::{Anchor, Moments, Reference, fast_atan2};

/// Readings within this arc length along the scan of a return shape its
/// tangent line (m).
const NEIGHBOURHOOD_M: f64 = 0.4;
/// A neighbourhood spread wider than this across its line is not a line
/// (smallest over largest variance): a corner or a clump, matched point to
/// point.
const MAX_FLATNESS: f64 = 0.15;
/// Consecutive returns farther apart than this many beam spacings at their
/// range (plus 5 cm) are on different surfaces.
const GAP_SPACINGS: f64 = 3.5;
/// Beams either side of the projected bearing searched for the nearest
/// return.
const SEARCH_BEAMS: isize = 2;

/// A scan ready to be matched against.
#[derive(Debug, Clone)]
pub struct ScanReference {
    /// Endpoint per beam (sensor frame), NaN for no return, padded with
    /// [`SEARCH_BEAMS`] either side: the other end's beams on a full
    /// circle, NaN on a partial fan. Beam `i` is at `i + SEARCH_BEAMS`.
    padded: Vec<[f64; 2]>,
    /// Anchor per padded beam.
    anchors: Vec<Anchor>,
    beams: isize,
    angle_min_rad: f64,
    inverse_increment: f64,
    /// Beams in a turn (a partial fan's bearings wrap by this).
    turn_beams: isize,
    full_circle: bool,
    reach_sq: f64,
    returns: usize,
}

impl ScanReference {
    /// The reference of `scan`, pairing points at most `reach_m` from a
    /// return. Linear in the beams: each return's line comes from running
    /// sums over the returns within [`NEIGHBOURHOOD_M`] along the scan.
    pub fn new(scan: &Scan, reach_m: f64) -> Self {
        let beams = scan.ranges_m.len();
        let pad = SEARCH_BEAMS as usize;
        let full_circle = scan.full_circle();
        // Endpoints at `pad + i`, the padding filled below.
        let mut padded = vec![[f64::NAN; 2]; beams + 2 * pad];
        let mut valid = Vec::with_capacity(beams);
        for (i, p) in scan.endpoints().enumerate() {
            if let Some(p) = p {
                padded[pad + i] = p;
                valid.push(i);
            }
        }
        let point = |i: usize| padded[pad + i];
        // Arc length along the scan, restarted at every gap (with the
        // surface it belongs to), and running moments over the returns in
        // beam order.
        let spacing = scan.increment_rad.abs();
        let mut arc = Vec::with_capacity(valid.len());
        let mut prefix = Vec::with_capacity(valid.len() + 1);
        let mut sums = Moments::default();
        prefix.push(sums);
        let (mut s, mut surface) = (0.0, 0u32);
        for (k, &i) in valid.iter().enumerate() {
            let p = point(i);
            if k > 0 {
                let q = point(valid[k - 1]);
                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
                let range = (p[0] * p[0] + p[1] * p[1])
                    .max(q[0] * q[0] + q[1] * q[1])
                    .sqrt();
                let beams_apart = (i - valid[k - 1]) as f64;
                if d > GAP_SPACINGS * beams_apart * spacing * range + 0.05 {
                    surface += 1;
                    s = 0.0;
                } else {
                    s += d;
                }
            }
            arc.push((surface, s));
            sums.add(p);
            prefix.push(sums);
        }
        let no_anchor = Anchor {
            at: [f64::NAN; 2],
            normal: [0.0, 0.0],
        };
        let mut anchors = vec![no_anchor; beams + 2 * pad];
        let (mut lo, mut hi) = (0usize, 0usize);
        for k in 0..valid.len() {
            let (surface, s) = arc[k];
            while arc[lo].0 != surface || s - arc[lo].1 > NEIGHBOURHOOD_M {
                lo += 1;
            }
            hi = hi.max(k);
            while hi + 1 < valid.len()
                && arc[hi + 1].0 == surface
                && arc[hi + 1].1 - s <= NEIGHBOURHOOD_M
            {
                hi += 1;
            }
            let m = prefix[hi + 1].minus(&prefix[lo]);
            anchors[pad + valid[k]] = Anchor::from_moments(&m, point(valid[k]), MAX_FLATNESS);
        }
        // A full circle's padding is the other end's beams.
        if full_circle && beams >= pad {
            for j in 0..pad {
                padded[j] = padded[beams + j];
                anchors[j] = anchors[beams + j];
                padded[pad + beams + j] = padded[pad + j];
                anchors[pad + beams + j] = anchors[pad + j];
            }
        }
        let inverse_increment = if scan.increment_rad != 0.0 {
            1.0 / scan.increment_rad
        } else {
            0.0
        };
        Self {
            padded,
            anchors,
            beams: beams as isize,
            angle_min_rad: scan.angle_min_rad,
            inverse_increment,
            turn_beams: (std::f64::consts::TAU * inverse_increment.abs()).round() as isize,
            full_circle,
            reach_sq: reach_m * reach_m,
            returns: valid.len(),
        }
    }

    /// Returns in the reference.
    pub fn len(&self) -> usize {
        self.returns
    }

    pub fn is_empty(&self) -> bool {
        self.returns == 0
    }
}

impl Reference for ScanReference {
    type Feature = Anchor;

    #[inline]
    fn measure(&self, feature: &Anchor, x: f64, y: f64) -> (f64, [f64; 2]) {
        feature.residual([x, y])
    }

    #[inline]
    fn associate(&self, x: f64, y: f64) -> Option<Anchor> {
        let beams = self.beams;
        let at = (fast_atan2(y, x) - self.angle_min_rad) * self.inverse_increment;
        if !at.is_finite() || beams == 0 {
            return None;
        }
        // Rounded by a cast (f64::round is a library call on baseline x86-64).
        let mut at = if at >= 0.0 {
            (at + 0.5) as isize
        } else {
            (at - 0.5) as isize
        };
        // Bring the bearing within a turn of the fan's start (the padding
        // covers a full circle's seam).
        if at < -SEARCH_BEAMS || at >= beams + SEARCH_BEAMS {
            at = at.rem_euclid(self.turn_beams.max(1));
            if self.full_circle && at >= beams {
                at -= beams;
            }
            if !(-SEARCH_BEAMS..beams + SEARCH_BEAMS).contains(&at) {
                return None;
            }
        }
        let (lo, hi) = (
            (at).max(0) as usize,
            ((at + 2 * SEARCH_BEAMS).min(beams + 2 * SEARCH_BEAMS - 1)) as usize,
        );
        let mut best = (f64::INFINITY, usize::MAX);
        for (j, p) in self.padded[lo..=hi].iter().enumerate() {
            // NaN (no return) never compares below.
            let d2 = (x - p[0]) * (x - p[0]) + (y - p[1]) * (y - p[1]);
            if d2 < best.0 {
                best = (d2, lo + j);
            }
        }
        if best.0 > self.reach_sq {
            return None;
        }
        Some(self.anchors[best.1])
    }
}

#[cfg(test)]
mod tests {
    use rand::RngExt;

    use super::super::testkit::{Lidar, compose, free_pose, rng, room, scan};
    use super::super::{MatchSettings, Refusal, SegmentMap, register};
    use super::*;

    /// Scan-to-scan on random rooms: 180 and 360 beams, 1-3 cm of noise,
    /// dropouts and max-range readings, motions up to 0.3 m and 20 degrees,
    /// priors 5 cm and 3 degrees off. Against the ideal: the same points
    /// matched to the exact walls (no noise in the reference).
    #[test]
    fn laser_odometry_on_random_rooms_is_near_the_exact_walls_accuracy_with_an_honest_covariance() {
        let mut rng = rng(2024);
        let settings = MatchSettings::scan_to_scan();
        let (mut sum_sq, mut ideal_sq, mut worst, mut nees, mut n) =
            ([0.0f64; 2], [0.0f64; 2], [0.0f64; 2], 0.0, 0);
        for trial in 0..80 {
            let walls = room(&mut rng);
            let lidar = Lidar {
                beams: if trial % 2 == 0 { 360 } else { 180 },
                noise_std_m: rng.random_range(0.01..0.03),
                dropout: 0.02,
                max_range_m: rng.random_range(5.0..10.0),
            };
            let from = free_pose(&walls, 0.5, &mut rng);
            let motion = [
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.35..0.35),
            ];
            let to = compose(from, motion);
            let exact = SegmentMap::new(&walls, 0.05, 0.5);
            if exact.distance_m(to[0], to[1]).is_some_and(|d| d < 0.3) {
                continue;
            }
            let reference = ScanReference::new(&scan(&walls, from, lidar, &mut rng), 0.5);
            let points = scan(&walls, to, lidar, &mut rng).points();
            let prior = [
                motion[0] + rng.random_range(-0.05..0.05),
                motion[1] + rng.random_range(-0.05..0.05),
                motion[2] + rng.random_range(-0.05..0.05),
            ];
            let m = register(&reference, &points, prior, &settings)
                .unwrap_or_else(|e| panic!("trial {trial}: {e}"));
            let e = [
                m.pose[0] - motion[0],
                m.pose[1] - motion[1],
                twindrive_kinematics::wrap_angle(m.pose[2] - motion[2]),
            ];
            let ideal = register(&exact, &points, compose(from, prior), &settings)
                .unwrap_or_else(|e| panic!("trial {trial}, exact walls: {e}"));
            let ideal_xy = (ideal.pose[0] - to[0]).hypot(ideal.pose[1] - to[1]);
            let ideal_h = twindrive_kinematics::wrap_angle(ideal.pose[2] - to[2]);
            let exy = e[0].hypot(e[1]);
            worst = [worst[0].max(exy), worst[1].max(e[2].abs())];
            sum_sq = [sum_sq[0] + exy * exy, sum_sq[1] + e[2] * e[2]];
            ideal_sq = [
                ideal_sq[0] + ideal_xy.powi(2),
                ideal_sq[1] + ideal_h.powi(2),
            ];
            let cov = nalgebra::Matrix3::from(m.covariance.expect("full rank")).transpose();
            let ev = nalgebra::Vector3::from(e);
            nees += (ev.transpose() * cov.try_inverse().unwrap() * ev)[0];
            n += 1;
        }
        assert!(n >= 50, "{n} trials");
        let rms = sum_sq.map(|s| (s / n as f64).sqrt());
        let ideal = ideal_sq.map(|s| (s / n as f64).sqrt());
        let mean_nees = nees / n as f64;
        eprintln!(
            "scan-to-scan, {n} pairs: RMS {:.1} mm, {:.3} deg (exact walls {:.1} mm, {:.3} deg); \
             worst {:.1} mm, {:.3} deg; mean NEES {mean_nees:.2}",
            rms[0] * 1e3,
            rms[1].to_degrees(),
            ideal[0] * 1e3,
            ideal[1].to_degrees(),
            worst[0] * 1e3,
            worst[1].to_degrees()
        );
        assert!(rms[0] < 0.01, "RMS translation error {} m", rms[0]);
        assert!(
            rms[1] < 0.3f64.to_radians(),
            "RMS heading error {} rad",
            rms[1]
        );
        // Two noisy views against one: within twice the ideal's error.
        assert!(rms[0] < 2.0 * ideal[0] + 1e-3 && rms[1] < 2.0 * ideal[1] + 1e-4);
        assert!(
            worst[0] < 0.05 && worst[1] < 1f64.to_radians(),
            "worst {worst:?}"
        );
        // The covariance is honest: a 3-dof NEES near 3 on average, neither
        // overconfident nor uselessly loose.
        assert!((1.0..6.0).contains(&mean_nees), "mean NEES {mean_nees}");
    }

    #[test]
    fn the_scan_reference_agrees_with_the_exact_walls() {
        // The same points matched against the scan they came from and
        // against the walls themselves land on the same pose.
        let mut rng = rng(7);
        for _ in 0..10 {
            let walls = room(&mut rng);
            let lidar = Lidar {
                beams: 360,
                noise_std_m: 0.01,
                dropout: 0.0,
                max_range_m: 12.0,
            };
            let from = free_pose(&walls, 0.5, &mut rng);
            let motion = [0.1, 0.05, 0.1];
            let to = compose(from, motion);
            let reference = ScanReference::new(&scan(&walls, from, lidar, &mut rng), 0.5);
            let points = scan(&walls, to, lidar, &mut rng).points();
            let by_scan = register(
                &reference,
                &points,
                [0.12, 0.03, 0.08],
                &MatchSettings::scan_to_scan(),
            )
            .expect("a match against the scan");
            let map = SegmentMap::new(&walls, 0.05, 0.5);
            let by_walls = register(
                &map,
                &points,
                compose(from, [0.12, 0.03, 0.08]),
                &MatchSettings::scan_to_scan(),
            )
            .expect("a match against the walls");
            let walls_motion = {
                // The walls give the world pose; bring it into `from`'s frame.
                let (s, c) = from[2].sin_cos();
                let (dx, dy) = (by_walls.pose[0] - from[0], by_walls.pose[1] - from[1]);
                [
                    c * dx + s * dy,
                    -s * dx + c * dy,
                    twindrive_kinematics::wrap_angle(by_walls.pose[2] - from[2]),
                ]
            };
            let d = (by_scan.pose[0] - walls_motion[0]).hypot(by_scan.pose[1] - walls_motion[1]);
            assert!(d < 0.006, "{d} m apart");
            assert!((by_scan.pose[2] - walls_motion[2]).abs() < 0.003);
        }
    }

    #[test]
    fn a_corridor_is_refused_as_degenerate_and_an_empty_view_as_too_few_points() {
        let mut rng = rng(3);
        let walls = [[-50.0, 0.0, 50.0, 0.0], [-50.0, 2.0, 50.0, 2.0]];
        let lidar = Lidar {
            beams: 360,
            noise_std_m: 0.02,
            dropout: 0.0,
            max_range_m: 6.0,
        };
        let from = [0.0, 1.0, 0.0];
        let reference = ScanReference::new(&scan(&walls, from, lidar, &mut rng), 0.5);
        let points = scan(&walls, compose(from, [0.2, 0.0, 0.0]), lidar, &mut rng).points();
        match register(
            &reference,
            &points,
            [0.2, 0.0, 0.0],
            &MatchSettings::scan_to_scan(),
        ) {
            Err(Refusal::Degenerate { direction, .. }) => {
                assert!(
                    direction[0].abs() > 0.95,
                    "along the corridor: {direction:?}"
                );
            }
            other => panic!("a corridor must be refused as degenerate: {other:?}"),
        }
        let open = [[100.0, 100.0, 101.0, 100.0]];
        let empty = scan(&open, [0.0; 3], lidar, &mut rng);
        assert!(empty.points().is_empty());
        let e = register(
            &reference,
            &empty.points(),
            [0.0; 3],
            &MatchSettings::scan_to_scan(),
        )
        .unwrap_err();
        assert_eq!(e.kind(), "too few points");
        assert!(e.to_string().contains("0 valid readings"), "{e}");
    }

    #[test]
    fn a_partial_fan_pairs_only_what_it_saw() {
        // A 270-degree scanner: points behind it have no reference reading.
        let mut rng = rng(9);
        let walls = room(&mut rng);
        let from = free_pose(&walls, 0.5, &mut rng);
        let lidar = Lidar {
            beams: 360,
            noise_std_m: 0.0,
            dropout: 0.0,
            max_range_m: 20.0,
        };
        let mut full = scan(&walls, from, lidar, &mut rng);
        // Keep -135..135 degrees.
        let first = 45;
        full.ranges_m = full.ranges_m[first..360 - first].to_vec();
        full.angle_min_rad += first as f64 * full.increment_rad;
        let reference = ScanReference::new(&full, 0.3);
        assert!(
            reference.residual(-1.0, 0.0).is_none(),
            "behind the scanner"
        );
        let p = full.endpoint(100).unwrap();
        let (r, _) = reference.residual(p[0], p[1]).unwrap();
        assert!(r.abs() < 0.01, "{r}");
    }
}
