//! Multi-beam range scans by angular sweep: each wall segment is projected
//! onto the beam fan and only the beams it can block are intersected, so a
//! 360-beam scan costs about (segments + beams) ray-segment tests instead of
//! segments x beams. Single rays go through parry2d ([`World::cast_ray`]);
//! tests check every beam against it.

use std::f64::consts::TAU;

use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;

use crate::World;

/// Fan geometry of a scan: beam `i` points at `heading + angle_min + i * increment`.
#[derive(Debug, Clone, Copy)]
pub struct Fan {
    pub angle_min_rad: f64,
    pub increment_rad: f64,
    pub beams: usize,
}

/// Precomputed beam directions in the sensor frame.
#[derive(Debug, Clone)]
pub struct ScanKernel {
    fan: Fan,
    local_dirs: Vec<Vector>,
    world_dirs: Vec<Vector>,
}

impl ScanKernel {
    pub fn new(fan: Fan) -> Self {
        let local_dirs = (0..fan.beams)
            .map(|i| {
                let a = fan.angle_min_rad + fan.increment_rad * i as f64;
                Vector::new(a.cos(), a.sin())
            })
            .collect();
        Self {
            fan,
            local_dirs,
            world_dirs: vec![Vector::ZERO; fan.beams],
        }
    }

    /// Writes the distance to the first wall along every beam into `out`
    /// (`max_range_m` where nothing is hit).
    pub fn scan(
        &mut self,
        world: &World,
        origin: Vector,
        heading_rad: f64,
        max_range_m: f64,
        out: &mut [f64],
    ) {
        let n = self.fan.beams;
        debug_assert_eq!(out.len(), n);
        out.fill(max_range_m);
        let (s, c) = heading_rad.sin_cos();
        for (w, l) in self.world_dirs.iter_mut().zip(&self.local_dirs) {
            *w = Vector::new(c * l.x - s * l.y, s * l.x + c * l.y);
        }
        let base = (heading_rad + self.fan.angle_min_rad).rem_euclid(TAU);
        let inc = self.fan.increment_rad;
        let query = Aabb::new(
            origin - Vector::splat(max_range_m),
            origin + Vector::splat(max_range_m),
        );
        let segments = world.segments();
        let dirs = &self.world_dirs;
        world.for_each_candidate(&query, |k| {
            let seg = &segments[k];
            let a = seg.a - origin;
            let b = seg.b - origin;
            let e = b - a;
            let area = a.perp_dot(b);
            if area == 0.0 {
                // On a line through the sensor. A sensor on the wall itself
                // reads 0 on every beam; otherwise only the beam along the
                // line meets it, at the nearer endpoint (as parry2d reports).
                if e.length_squared() == 0.0 {
                    return;
                }
                if a.dot(b) <= 0.0 {
                    out.fill(0.0);
                    return;
                }
                let near = if a.length_squared() <= b.length_squared() {
                    a
                } else {
                    b
                };
                let dist = near.length();
                {
                    let d = near;
                    let mut rel = fast_atan2(d.y, d.x) - base;
                    while rel < 0.0 {
                        rel += TAU;
                    }
                    let margin = FAST_ATAN2_MAX_ERROR + 1e-9;
                    for shift in [0.0, -TAU] {
                        let (lo, hi) = (rel + shift - margin, rel + shift + margin);
                        let (j0, j1) = if n == 1 || inc == 0.0 {
                            if lo <= 0.0 && hi >= 0.0 {
                                (0, 0)
                            } else {
                                continue;
                            }
                        } else {
                            if hi < 0.0 {
                                continue;
                            }
                            (
                                ceil_non_negative(lo / inc),
                                ((hi / inc) as usize).min(n - 1),
                            )
                        };
                        for j in j0..=j1 {
                            let dir = dirs[j];
                            if dir.perp_dot(d).abs() <= 1e-12 * d.length()
                                && dir.dot(d) > 0.0
                                && dist < out[j]
                            {
                                out[j] = dist;
                            }
                        }
                    }
                }
                return;
            }
            // Skip segments entirely beyond range.
            let t = (-a.dot(e) / e.length_squared()).clamp(0.0, 1.0);
            if (a + e * t).length_squared() > max_range_m * max_range_m {
                return;
            }
            // Counter-clockwise angular interval from the first to the second endpoint.
            let (first, second) = if area > 0.0 { (a, b) } else { (b, a) };
            // Approximate angles are enough to choose candidate beams: the
            // window is widened by the approximation's error bound and the
            // exact test in `hit` decides.
            // fast_atan2 is in [-π, π] and base in [0, 2π): two folds at most.
            let mut start = fast_atan2(first.y, first.x) - base;
            while start < 0.0 {
                start += TAU;
            }
            let span = fast_atan2(first.perp_dot(second), first.dot(second));
            let margin = FAST_ATAN2_MAX_ERROR + 1e-9;
            let mut visit = |lo: f64, hi: f64| {
                if n == 1 || inc == 0.0 {
                    if lo - margin <= 0.0 && hi + margin >= 0.0 {
                        hit(&mut out[0], dirs[0], a, e);
                    }
                    return;
                }
                let hi = (hi + margin) / inc;
                if hi < 0.0 {
                    return;
                }
                let j0 = ceil_non_negative((lo - margin) / inc);
                let j1 = (hi as usize).min(n - 1); // truncation is floor for hi >= 0
                for j in j0..=j1 {
                    hit(&mut out[j], dirs[j], a, e);
                }
            };
            visit(start, start + span);
            // The part of the interval that wraps past a full turn.
            visit(start - TAU, start + span - TAU);
        });
    }
}

/// ceil(x) for x >= 0, 0 for x < 0, without a libm call.
#[inline(always)]
fn ceil_non_negative(x: f64) -> usize {
    if x <= 0.0 {
        return 0;
    }
    let t = x as usize;
    if (t as f64) < x { t + 1 } else { t }
}

/// Upper bound (with headroom) of [`fast_atan2`]'s error in radians; the
/// polynomial's own maximum error is about 1e-5.
const FAST_ATAN2_MAX_ERROR: f64 = 1e-4;

/// atan2 by a degree-9 minimax polynomial on [-1, 1] plus octant folding.
#[inline(always)]
fn fast_atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    if ax == 0.0 && ay == 0.0 {
        return 0.0;
    }
    let swap = ay > ax;
    let z = if swap { ax / ay } else { ay / ax };
    let z2 = z * z;
    let mut a = z
        * (0.999_866_0
            + z2 * (-0.330_299_5 + z2 * (0.180_141_0 + z2 * (-0.085_133_0 + z2 * 0.020_835_1))));
    if swap {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 { -a } else { a }
}

/// Shortens `*best` if the ray from the origin along `dir` crosses the
/// segment `a + u e`, u in [0, 1].
#[inline(always)]
fn hit(best: &mut f64, dir: Vector, a: Vector, e: Vector) {
    let denom = dir.perp_dot(e);
    if denom == 0.0 {
        return;
    }
    let inv = 1.0 / denom;
    let t = a.perp_dot(e) * inv;
    let u = a.perp_dot(dir) * inv;
    if t >= 0.0 && t < *best && (-1e-12..=1.0 + 1e-12).contains(&u) {
        *best = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::{polyline_segments, rectangle_segments};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::PI;

    fn cluttered_world(rng: &mut ChaCha8Rng, pieces: usize) -> World {
        let mut segs = rectangle_segments([0.0, 0.0], [10.0, 10.0]);
        for _ in 0..pieces {
            let p = [rng.random_range(0.0..10.0), rng.random_range(0.0..10.0)];
            let q = [
                p[0] + rng.random_range(-2.0..2.0),
                p[1] + rng.random_range(-2.0..2.0),
            ];
            segs.extend(polyline_segments(&[p, q], false));
        }
        World::new(segs, vec![], None)
    }

    fn check_against_parry(world: &World, fan: Fan, seed: u64, rng: &mut ChaCha8Rng) {
        let mut kernel = ScanKernel::new(fan);
        let mut out = vec![0.0; fan.beams];
        for case in 0..200 {
            let origin = Vector::new(rng.random_range(0.5..9.5), rng.random_range(0.5..9.5));
            let heading = rng.random_range(-PI..PI);
            let max_range = rng.random_range(1.0..12.0);
            kernel.scan(world, origin, heading, max_range, &mut out);
            for (i, got) in out.iter().enumerate() {
                let a = heading + fan.angle_min_rad + fan.increment_rad * i as f64;
                let want = world.cast_ray(origin, Vector::new(a.cos(), a.sin()), max_range);
                assert!(
                    (got - want).abs() < 1e-9,
                    "seed {seed} case {case} beam {i}: sweep {got} vs parry {want}"
                );
            }
        }
    }

    #[test]
    fn fast_atan2_error_is_bounded() {
        let mut worst: f64 = 0.0;
        for k in 0..100_000 {
            let a = -PI + TAU * k as f64 / 100_000.0;
            for r in [1e-6, 0.3, 7.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                let err = (fast_atan2(y, x) - y.atan2(x)).abs();
                // Same angle modulo a turn (±π both valid at the cut).
                worst = worst.max(err.min((err - TAU).abs()));
            }
        }
        assert!(worst < FAST_ATAN2_MAX_ERROR / 5.0, "worst error {worst}");
        assert_eq!(fast_atan2(0.0, 0.0), 0.0);
    }

    #[test]
    fn walls_seen_edge_on_match_parry() {
        // Segments on lines through the sensor, in front of, behind and through it.
        let segs = polyline_segments(&[[2.0, 0.0], [3.0, 0.0]], false)
            .into_iter()
            .chain(polyline_segments(&[[0.0, -1.5], [0.0, -4.0]], false))
            .chain(polyline_segments(&[[-1.0, -1.0], [-2.0, -2.0]], false))
            .collect();
        let world = World::new(segs, vec![], None);
        let fan = Fan {
            angle_min_rad: -PI,
            increment_rad: TAU / 360.0,
            beams: 360,
        };
        let mut kernel = ScanKernel::new(fan);
        let mut out = vec![0.0; 360];
        kernel.scan(&world, Vector::ZERO, 0.0, 10.0, &mut out);
        for (i, got) in out.iter().enumerate() {
            let a = fan.angle_min_rad + fan.increment_rad * i as f64;
            let want = world.cast_ray(Vector::ZERO, Vector::new(a.cos(), a.sin()), 10.0);
            assert!(
                (got - want).abs() < 1e-9,
                "beam {i} ({:.1}°): sweep {got} vs parry {want}",
                a.to_degrees()
            );
        }
        assert_eq!(out[180], 2.0, "straight ahead along the first wall");
        assert_eq!(out[90], 1.5, "straight down along the second wall");
        assert!(
            (out[45] - 2f64.sqrt()).abs() < 1e-12,
            "down-left along the third wall"
        );
        // A sensor sitting on a wall reads 0 everywhere.
        let on_wall = World::new(
            polyline_segments(&[[-1.0, -1.0], [1.0, 1.0]], false),
            vec![],
            None,
        );
        kernel.scan(&on_wall, Vector::ZERO, 0.3, 10.0, &mut out);
        assert!(out.iter().all(|&r| r == 0.0));
        assert_eq!(
            on_wall.cast_ray(Vector::ZERO, Vector::new(0.0, 1.0), 10.0),
            0.0
        );
    }

    #[test]
    fn sweep_matches_parry_ray_casts() {
        for seed in 0..6 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let world = cluttered_world(&mut rng, if seed < 3 { 10 } else { 80 });
            let full = Fan {
                angle_min_rad: -PI,
                increment_rad: TAU / 360.0,
                beams: 360,
            };
            check_against_parry(&world, full, seed, &mut rng);
            let narrow = Fan {
                angle_min_rad: -1.2,
                increment_rad: 2.4 / 90.0,
                beams: 91,
            };
            check_against_parry(&world, narrow, seed, &mut rng);
            let single = Fan {
                angle_min_rad: 0.4,
                increment_rad: 0.0,
                beams: 1,
            };
            check_against_parry(&world, single, seed, &mut rng);
        }
    }
}
