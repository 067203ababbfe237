//! A plan's corridor as the page draws it: a band around the plan's path,
//! as wide each side as the corridor's half width there, clipped to what
//! the path sees on the plan's map. The band is made of spokes: rays
//! across the path, cast from points of the path, each ending at the half
//! width or at the first wall (a map's occupied cells travel as their
//! outlines), the nearer of the two. So the band covers only ground the
//! robot's body reaches from its path without crossing a wall: never an
//! occupied cell, never the room beyond a wall, though the corridor's half
//! width would reach there. At a bend the spokes fan round its outside (a
//! round join); at the path's two ends they fan round a half disc (round
//! caps). Where the half width changes (a stretch ends), the band steps.
//!
//! The spokes come in order round the band (left side forward, round the
//! end, right side back, round the start); the page fills the quadrilateral
//! between each spoke and the next (the last and the first too), each on
//! its own, so the band is their union however the path bends or crosses
//! itself. Spokes are cast every [`STEP_M`] along the path and at most
//! [`MAX_CHORD_M`] apart at their ends in a fan: the band's edge is exact
//! to that spacing.

use std::f64::consts::PI;

use twindrive_sim::{Vector, World};

/// Rays are cast from points at least this far apart along the path (m),
/// and wherever the half width changes.
pub const STEP_M: f64 = 0.02;

/// The spokes of a fan end at most this far apart at the half width (m),
/// and at most 15° apart.
pub const MAX_CHORD_M: f64 = 0.04;
const FAN_STEP_RAD: f64 = PI / 12.0;

/// Positions closer than this are one place (m): a turn on the spot.
const SAME_M: f64 = 1e-9;

/// A ray of the band: from a point of the path to where it ends.
pub type Spoke = ([f64; 2], [f64; 2]);

/// The band along `path` (positions in order), `half_width_m` (one per
/// position; the shorter of the two sets the length) each side, clipped to
/// what the path sees in `world`: its spokes in order round it. Every
/// spoke starts at a point `p` of the path, is no longer than `p`'s half
/// width and crosses no wall.
pub fn band(path: &[[f64; 2]], half_width_m: &[f64], world: &World) -> Vec<Spoke> {
    let n = path.len().min(half_width_m.len());
    if n == 0 {
        return Vec::new();
    }
    // The points rays are cast from, with their half widths: every STEP_M,
    // and on both sides of a change of width (the last point of one
    // stretch and the first of the next).
    let mut kept: Vec<(usize, [f64; 2], f64)> = vec![(0, path[0], half_width_m[0])];
    for i in 1..n {
        let (p, w) = (path[i], half_width_m[i]);
        let &(last_i, q, wq) = kept.last().expect("one at least");
        if w != wq {
            if last_i != i - 1 {
                kept.push((i - 1, path[i - 1], half_width_m[i - 1]));
            }
            kept.push((i, p, w));
        } else if distance(p, q) >= STEP_M || i == n - 1 {
            kept.push((i, p, w));
        }
    }
    let cast = |p: [f64; 2], angle: f64, w: f64| -> Spoke {
        let (s, c) = angle.sin_cos();
        let r = world.cast_ray(Vector::new(p[0], p[1]), Vector::new(c, s), w.max(0.0));
        (p, [p[0] + c * r, p[1] + s * r])
    };
    // How many spokes a fan of `angle` (rad) at half width `w` takes.
    let fan = |angle: f64, w: f64| -> usize {
        let step = FAN_STEP_RAD.min(MAX_CHORD_M / w.max(MAX_CHORD_M));
        (angle.abs() / step).ceil() as usize
    };
    // The path's heading into and out of each point, from the nearest
    // points elsewhere (a turn on the spot has none of its own).
    let heading = |from: [f64; 2], to: [f64; 2]| (to[1] - from[1]).atan2(to[0] - from[0]);
    let m = kept.len();
    let mut incoming: Vec<Option<f64>> = vec![None; m];
    let mut last_elsewhere: Option<[f64; 2]> = None;
    for k in 0..m {
        let p = kept[k].1;
        if let Some(q) = last_elsewhere {
            incoming[k] = Some(heading(q, p));
        }
        if k + 1 < m && distance(kept[k + 1].1, p) > SAME_M {
            last_elsewhere = Some(p);
        }
    }
    let mut outgoing: Vec<Option<f64>> = vec![None; m];
    let mut next_elsewhere: Option<[f64; 2]> = None;
    for k in (0..m).rev() {
        let p = kept[k].1;
        if let Some(q) = next_elsewhere {
            outgoing[k] = Some(heading(p, q));
        }
        if k > 0 && distance(kept[k - 1].1, p) > SAME_M {
            next_elsewhere = Some(p);
        }
    }
    if incoming.iter().chain(&outgoing).all(Option::is_none) {
        // The path never leaves one place: a disc.
        let (_, p, w) = kept[0];
        let rays = fan(2.0 * PI, w);
        return (0..rays)
            .map(|j| cast(p, 2.0 * PI * j as f64 / rays as f64, w))
            .collect();
    }
    let mut left = Vec::with_capacity(m);
    let mut right = Vec::with_capacity(m);
    let mut ends = (0.0, 0.0);
    for k in 0..m {
        let (_, p, w) = kept[k];
        let (a_in, a_out) = match (incoming[k], outgoing[k]) {
            (Some(a), Some(b)) => (a, b),
            (Some(a), None) | (None, Some(a)) => (a, a),
            (None, None) => unreachable!("a path that leaves its place has headings"),
        };
        if k == 0 {
            ends.0 = a_in;
        }
        if k == m - 1 {
            ends.1 = a_out;
        }
        let turn = wrap(a_out - a_in);
        let rays = fan(turn, w);
        if rays == 0 {
            left.push(cast(p, a_in + PI / 2.0, w));
            right.push(cast(p, a_in - PI / 2.0, w));
        } else {
            for j in 0..=rays {
                let a = a_in + turn * j as f64 / rays as f64;
                left.push(cast(p, a + PI / 2.0, w));
                right.push(cast(p, a - PI / 2.0, w));
            }
        }
    }
    // Round the end (from the left through ahead to the right), back
    // along the right, round the start (from the right through behind to
    // the left).
    let (_, end, w_end) = kept[m - 1];
    let (_, start, w_start) = kept[0];
    let (cap_end, cap_start) = (fan(PI, w_end), fan(PI, w_start));
    let mut ring = left;
    ring.extend((1..cap_end).map(|j| {
        cast(
            end,
            ends.1 + PI / 2.0 - PI * j as f64 / cap_end as f64,
            w_end,
        )
    }));
    ring.extend(right.into_iter().rev());
    ring.extend((1..cap_start).map(|j| {
        cast(
            start,
            ends.0 - PI / 2.0 - PI * j as f64 / cap_start as f64,
            w_start,
        )
    }));
    ring
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// An angle in (-π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI { w - 2.0 * PI } else { w }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use twindrive_sim::rectangle_segments;

    /// Whether segments ab and cd cross (touching at an end does not
    /// count).
    fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
        let side = |o: [f64; 2], p: [f64; 2], q: [f64; 2]| {
            (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])
        };
        let (d1, d2) = (side(c, d, a), side(c, d, b));
        let (d3, d4) = (side(a, b, c), side(a, b, d));
        d1 * d2 < 0.0 && d3 * d4 < 0.0
    }

    /// Whether `spoke` starts at a point of `path`, is no longer than
    /// that point's half width, and crosses no wall of `walls` (it may end
    /// on one).
    fn honest(path: &[[f64; 2]], widths: &[f64], walls: &[[f64; 4]], (p, q): Spoke) -> bool {
        path.iter().zip(widths).any(|(&c, &w)| {
            let d = distance(p, q);
            if c != p || d > w + 1e-9 {
                return false;
            }
            let t = if d > 1e-4 { (d - 1e-4) / d } else { 0.0 };
            let q = [p[0] + (q[0] - p[0]) * t, p[1] + (q[1] - p[1]) * t];
            walls
                .iter()
                .all(|w| !cross(p, q, [w[0], w[1]], [w[2], w[3]]))
        })
    }

    /// Rooms of random size split by a wall with a door at a random place,
    /// random boxes, a random path through the door with a turn on the
    /// spot, and random corridor widths in stretches: every spoke is a ray
    /// from the path within its half width that crosses no wall, so nothing
    /// of the band lies beyond a wall or inside a box; neighbouring spokes
    /// end close together; and the band is not a thin line.
    #[test]
    fn the_band_never_reaches_past_a_wall() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(54);
        for trial in 0..40 {
            let (w, h) = (rng.random_range(4.0..9.0), rng.random_range(3.0..6.0));
            let split = rng.random_range(0.35..0.65) * w;
            let door = rng.random_range(1.0..h - 1.0);
            // Through the door, a wander on each side, at 1 cm, with a turn
            // on the spot at the door.
            let waypoints = [
                [
                    rng.random_range(0.5..split - 0.5),
                    rng.random_range(0.5..h - 0.5),
                ],
                [split - 0.3, door],
                [split, door],
                [split, door],
                [split + 0.3, door],
                [
                    rng.random_range(split + 0.5..w - 0.5),
                    rng.random_range(0.5..h - 0.5),
                ],
            ];
            let mut path = Vec::new();
            for leg in waypoints.windows(2) {
                let steps = (distance(leg[0], leg[1]) / 0.01).ceil().max(1.0) as usize;
                for s in 0..steps {
                    let t = s as f64 / steps as f64;
                    path.push([
                        leg[0][0] + (leg[1][0] - leg[0][0]) * t,
                        leg[0][1] + (leg[1][1] - leg[0][1]) * t,
                    ]);
                }
            }
            path.push(waypoints[5]);
            let mut walls: Vec<[f64; 4]> = vec![
                [0.0, 0.0, w, 0.0],
                [w, 0.0, w, h],
                [w, h, 0.0, h],
                [0.0, h, 0.0, 0.0],
                [split, 0.0, split, door - 0.4],
                [split, door + 0.4, split, h],
            ];
            // Boxes anywhere the path keeps 0.2 m from.
            let mut solids = Vec::new();
            for _ in 0..rng.random_range(1..6) {
                let (x, y) = (
                    rng.random_range(0.3..w - 0.8),
                    rng.random_range(0.3..h - 0.8),
                );
                let (bw, bh) = (rng.random_range(0.1..0.5), rng.random_range(0.1..0.5));
                let near = |p: &[f64; 2]| {
                    p[0] > x - 0.2 && p[0] < x + bw + 0.2 && p[1] > y - 0.2 && p[1] < y + bh + 0.2
                };
                if (x - 0.05..x + bw + 0.05).contains(&split) || path.iter().any(near) {
                    continue;
                }
                walls.extend([
                    [x, y, x + bw, y],
                    [x + bw, y, x + bw, y + bh],
                    [x + bw, y + bh, x, y + bh],
                    [x, y + bh, x, y],
                ]);
                solids.push([x, y, x + bw, y + bh]);
            }
            let world = World::from_walls(&walls, &solids);
            let mut widths = Vec::with_capacity(path.len());
            while widths.len() < path.len() {
                let wd = (rng.random_range(0.15..1.5_f64) * 20.0).floor() / 20.0;
                let run = rng.random_range(20..200);
                widths.extend(std::iter::repeat_n(wd, run));
            }
            widths.truncate(path.len());
            let spokes = band(&path, &widths, &world);
            assert!(spokes.len() > 20, "trial {trial}: {} spokes", spokes.len());
            let widest = spokes
                .iter()
                .map(|&(p, q)| distance(p, q))
                .fold(0.0, f64::max);
            assert!(
                widest > 0.14,
                "trial {trial}: the band reaches {widest} m from the path"
            );
            for (k, &spoke) in spokes.iter().enumerate() {
                assert!(
                    honest(&path, &widths, &walls, spoke),
                    "trial {trial}: {spoke:?} is no ray from the path within its half width"
                );
                let (next, q) = (spokes[(k + 1) % spokes.len()], spoke.1);
                // Unless a wall cut one of them short.
                let full = |(p, q): Spoke, w: f64| (distance(p, q) - w).abs() < 1e-9;
                let w_of = |p: [f64; 2]| widths[path.iter().position(|&c| c == p).unwrap()];
                if full(spoke, w_of(spoke.0))
                    && full(next, w_of(next.0))
                    && w_of(spoke.0) == w_of(next.0)
                {
                    assert!(
                        distance(q, next.1) < MAX_CHORD_M + STEP_M + 1e-6,
                        "trial {trial}: spokes {k} and {} end {} m apart",
                        k + 1,
                        distance(q, next.1)
                    );
                }
                for b in &solids {
                    let inside = q[0] > b[0] + 1e-6
                        && q[0] < b[2] - 1e-6
                        && q[1] > b[1] + 1e-6
                        && q[1] < b[3] - 1e-6;
                    assert!(!inside, "trial {trial}: {q:?} inside the box {b:?}");
                }
            }
        }
    }

    /// In the open, a straight path's band is the full half width each
    /// side with round ends; a wall near one side holds that side to it.
    #[test]
    fn in_the_open_the_band_is_the_full_width_and_a_wall_clips_one_side() {
        let far = World::new(
            rectangle_segments([-10.0, -10.0], [10.0, 10.0]),
            vec![],
            None,
        );
        let path: Vec<[f64; 2]> = (0..=100).map(|i| [i as f64 * 0.01, 0.0]).collect();
        let widths = vec![0.5; path.len()];
        let ends = |spokes: Vec<Spoke>| spokes.into_iter().map(|s| s.1).collect::<Vec<_>>();
        let ring = ends(band(&path, &widths, &far));
        let top = ring.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
        let bottom = ring.iter().map(|p| p[1]).fold(f64::MAX, f64::min);
        let ahead = ring.iter().map(|p| p[0]).fold(f64::MIN, f64::max);
        let behind = ring.iter().map(|p| p[0]).fold(f64::MAX, f64::min);
        assert!((top - 0.5).abs() < 1e-9 && (bottom + 0.5).abs() < 1e-9);
        assert!((ahead - 1.5).abs() < 1e-9 && (behind + 0.5).abs() < 1e-9);
        let mut segs = rectangle_segments([-10.0, -10.0], [10.0, 10.0]);
        segs.extend(twindrive_sim::polyline_segments(
            &[[-1.0, 0.2], [3.0, 0.2]],
            false,
        ));
        let walled = World::new(segs, vec![], None);
        let ring = ends(band(&path, &widths, &walled));
        let top = ring.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
        let bottom = ring.iter().map(|p| p[1]).fold(f64::MAX, f64::min);
        assert!((top - 0.2).abs() < 1e-9, "{top}");
        assert!((bottom + 0.5).abs() < 1e-9, "{bottom}");
    }
}
