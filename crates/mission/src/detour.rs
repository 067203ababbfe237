//! Continuations that finish the interrupted plan: after a hand-back the
//! twin knows obstacles the plan did not (blocks learnt from the robot's
//! contacts and readings). The continuation drives from where the robot
//! stands back onto the rest of the plan, and around every stretch of it
//! that now passes too close to a learnt block, so the mission's route is
//! still covered but nothing the twin knows is touched.
//!
//! Each detour is a shortest path on a grid over the twin's world (A*,
//! 8-connected) through cells whose centres keep the robot's footprint clear
//! of every wall, with a cost that grows as the clearance falls below the
//! wanted one; the path is then shortened by line of sight (a straight leg
//! replaces a run of cells when every point along it keeps at least the
//! clearance its ends have) and driven as turns in place and straight legs:
//! a circular robot turning in place sweeps nothing new. The geometry is
//! timed by the caller (the pipeline's time-optimal re-timing under the
//! wheel limits).

use twindrive_kinematics::{Pose, wrap_angle};
use twindrive_sim::World;

use crate::error::PipelineError;
use crate::grid_search::{ClearanceGrid, Clearances};
use crate::path::PathSample;

/// How detours are planned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetourSettings {
    /// Wanted clearance between the footprint and any wall or block (m).
    pub clearance_m: f64,
    /// Clearance a detour keeps wherever it can (m): a hard floor, not a
    /// cost, except near where it starts and ends (a robot against what it
    /// touched has to leave it). Where no way keeps it (a narrow passage),
    /// the search takes the way that costs least below the wanted
    /// clearance, and the caller judges it.
    pub min_clearance_m: f64,
    /// Grid cell size (m).
    pub resolution_m: f64,
    /// Spacing of the emitted samples along straight legs (m) and turns (rad).
    pub step_m: f64,
    pub step_rad: f64,
}

impl Default for DetourSettings {
    fn default() -> Self {
        Self {
            clearance_m: 0.10,
            min_clearance_m: 0.0,
            resolution_m: 0.04,
            step_m: 0.01,
            step_rad: 0.05,
        }
    }
}

/// How far a robot against an obstacle backs away before it turns (m).
const BACK_OFF_M: f64 = 0.08;

/// Axis-aligned block `(min, max)` (m).
pub type Block = ([f64; 2], [f64; 2]);

/// Distance from `p` to `block` (0 inside).
pub fn distance_to_block(p: [f64; 2], (min, max): &Block) -> f64 {
    let dx = (min[0] - p[0]).max(p[0] - max[0]).max(0.0);
    let dy = (min[1] - p[1]).max(p[1] - max[1]).max(0.0);
    dx.hypot(dy)
}

/// The geometry of a continuation: from `start` (where the robot stands) to
/// the first sample of `remaining` (the interrupted plan from the hand-back
/// on) that keeps `footprint_radius_m + clearance_m` from every block in
/// `learnt`, then along `remaining`, with every later stretch that comes
/// closer to a learnt block replaced by a detour. `world` is the twin's
/// world with the learnt blocks in it. Times are left to the caller.
pub fn continuation_path(
    world: &World,
    footprint_radius_m: f64,
    start: Pose,
    remaining: &[PathSample],
    learnt: &[Block],
    settings: &DetourSettings,
) -> Result<Vec<PathSample>, PipelineError> {
    let wanted = footprint_radius_m + settings.clearance_m;
    let free: Vec<bool> = remaining
        .iter()
        .map(|s| {
            learnt
                .iter()
                .all(|b| distance_to_block(s.position(), b) >= wanted)
        })
        .collect();
    let first = free.iter().position(|&f| f).ok_or_else(|| {
        PipelineError::Infeasible(
            "the rest of the plan passes the learnt obstacles all the way to its end".into(),
        )
    })?;
    let grid = Grid::new(world, footprint_radius_m, settings, start, remaining)?;
    let mut out = Vec::new();
    let start = grid.back_off(start, settings, &mut out);
    grid.drive(start, remaining[first].pose, settings, &mut out)?;
    let mut k = first;
    while k < remaining.len() {
        if free[k] {
            out.push(remaining[k]);
            k += 1;
            continue;
        }
        // A stretch too close to a learnt block: go around it to the next
        // free sample (the plan's end if the stretch runs to it).
        let from = remaining[k - 1].pose;
        let next = (k..remaining.len()).find(|&j| free[j]);
        let to = next.map_or(remaining[remaining.len() - 1].pose, |j| remaining[j].pose);
        grid.drive(from, to, settings, &mut out)?;
        k = next.unwrap_or(remaining.len());
    }
    Ok(out)
}

/// The world's clearances over its box, and the exact clearance between
/// cell centres.
struct Grid<'w> {
    world: &'w World,
    cells: ClearanceGrid,
    footprint_m: f64,
    keep: Clearances,
}

impl<'w> Grid<'w> {
    fn new(
        world: &'w World,
        footprint_m: f64,
        settings: &DetourSettings,
        start: Pose,
        remaining: &[PathSample],
    ) -> Result<Self, PipelineError> {
        let cell_m = settings.resolution_m;
        if !(cell_m.is_finite() && cell_m > 0.0) {
            return Err(PipelineError::Value(
                twindrive_plan::PlanError::BadSetting {
                    field: "detour resolution_m",
                    value: cell_m,
                },
            ));
        }
        // The world's box, grown to hold the robot and the plan.
        let (mut lo, mut hi) = ([start.x_m, start.y_m], [start.x_m, start.y_m]);
        for s in remaining {
            lo = [lo[0].min(s.pose.x_m), lo[1].min(s.pose.y_m)];
            hi = [hi[0].max(s.pose.x_m), hi[1].max(s.pose.y_m)];
        }
        if let Some(b) = world.bounds() {
            lo = [lo[0].min(b.mins.x), lo[1].min(b.mins.y)];
            hi = [hi[0].max(b.maxs.x), hi[1].max(b.maxs.y)];
        }
        let margin = footprint_m + 2.0 * cell_m;
        let origin = [lo[0] - margin, lo[1] - margin];
        let size = [
            ((hi[0] - lo[0] + 2.0 * margin) / cell_m).ceil() as usize + 1,
            ((hi[1] - lo[1] + 2.0 * margin) / cell_m).ceil() as usize + 1,
        ];
        if size[0].saturating_mul(size[1]) > 16_000_000 {
            return Err(PipelineError::Infeasible(format!(
                "a detour grid of {} x {} cells at {cell_m} m is too large",
                size[0], size[1]
            )));
        }
        let keep = Clearances {
            want_m: settings.clearance_m,
            floor_m: settings.min_clearance_m,
            ends_m: footprint_m + settings.clearance_m + cell_m,
        };
        let mut grid = Self {
            world,
            cells: ClearanceGrid::new(origin, cell_m, size, vec![0.0; size[0] * size[1]]),
            footprint_m,
            keep,
        };
        let clearance: Vec<f64> = (0..size[0] * size[1])
            .map(|c| grid.clearance_at(grid.cells.centre(c)))
            .collect();
        grid.cells.clearances_mut().copy_from_slice(&clearance);
        Ok(grid)
    }

    /// Clearance of the footprint centred at `p`, capped a little above the
    /// wanted one (further is as good).
    fn clearance_at(&self, p: [f64; 2]) -> f64 {
        let cap = self.footprint_m + self.keep.want_m + self.cells.cell_m();
        self.world.clearance_m(p[0], p[1], cap) - self.footprint_m
    }

    /// Waypoints from `from` to `to` ([`ClearanceGrid::waypoints`], with
    /// the world's exact clearances).
    fn waypoints(&self, from: [f64; 2], to: [f64; 2]) -> Option<Vec<[f64; 2]>> {
        self.cells
            .waypoints(from, to, &self.keep, &|p| self.clearance_at(p))
    }

    /// A robot that stopped against something (closer than the wanted
    /// clearance, as after a bump) first backs straight away from it by up
    /// to `BACK_OFF_M`, as far as the clearance keeps growing: turning in
    /// place against a face keeps the bumper pressed. Appends the reverse
    /// leg (if any) and returns where it ends.
    fn back_off(&self, from: Pose, settings: &DetourSettings, out: &mut Vec<PathSample>) -> Pose {
        let wanted = self.keep.want_m;
        let mut clearance = self.clearance_at([from.x_m, from.y_m]);
        if clearance >= wanted {
            return from;
        }
        let (s, c) = from.heading_rad.sin_cos();
        let steps = (BACK_OFF_M / settings.step_m).ceil() as usize;
        let mut at = from;
        let mut leg = Vec::new();
        for k in 1..=steps {
            let d = BACK_OFF_M * k as f64 / steps as f64;
            let p = Pose::new(from.x_m - d * c, from.y_m - d * s, from.heading_rad);
            let next = self.clearance_at([p.x_m, p.y_m]);
            if next <= clearance {
                break;
            }
            (at, clearance) = (p, next);
            leg.push(p);
        }
        if !leg.is_empty() {
            push(out, from);
            for p in leg {
                push(out, p);
            }
        }
        at
    }

    /// Appends the drive from `from` to `to`: a turn in place towards each
    /// waypoint and a straight leg to it, then a turn to `to`'s heading.
    fn drive(
        &self,
        from: Pose,
        to: Pose,
        settings: &DetourSettings,
        out: &mut Vec<PathSample>,
    ) -> Result<(), PipelineError> {
        let points = self
            .waypoints([from.x_m, from.y_m], [to.x_m, to.y_m])
            .ok_or_else(|| {
                PipelineError::Infeasible(format!(
                    "no way on the twin from ({:.2}, {:.2}) to ({:.2}, {:.2}) with the footprint clear",
                    from.x_m, from.y_m, to.x_m, to.y_m
                ))
            })?;
        let mut pose = from;
        push(out, pose);
        for w in points.windows(2) {
            let (dx, dy) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
            let length = dx.hypot(dy);
            if length < 1e-6 {
                continue;
            }
            pose = turn(out, pose, dy.atan2(dx), settings.step_rad);
            let steps = (length / settings.step_m).ceil() as usize;
            for k in 1..=steps {
                let s = k as f64 / steps as f64;
                pose = Pose::new(w[0][0] + s * dx, w[0][1] + s * dy, pose.heading_rad);
                push(out, pose);
            }
        }
        turn(out, pose, to.heading_rad, settings.step_rad);
        Ok(())
    }
}

fn push(out: &mut Vec<PathSample>, pose: Pose) {
    let t_s = out.last().map_or(0.0, |s| s.t_s);
    out.push(PathSample {
        t_s,
        pose,
        v_m_s: 0.0,
        omega_rad_s: 0.0,
    });
}

/// Turns in place from `pose` to `heading_rad` along the shorter way.
fn turn(out: &mut Vec<PathSample>, pose: Pose, heading_rad: f64, step_rad: f64) -> Pose {
    let delta = wrap_angle(heading_rad - pose.heading_rad);
    let steps = (delta.abs() / step_rad).ceil() as usize;
    let mut at = pose;
    for k in 1..=steps {
        at = Pose::new(
            pose.x_m,
            pose.y_m,
            pose.heading_rad + delta * k as f64 / steps as f64,
        );
        push(out, at);
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn straight(from: [f64; 2], to: [f64; 2], n: usize) -> Vec<PathSample> {
        let heading = (to[1] - from[1]).atan2(to[0] - from[0]);
        (0..=n)
            .map(|k| {
                let s = k as f64 / n as f64;
                PathSample {
                    t_s: s * 10.0,
                    pose: Pose::new(
                        from[0] + s * (to[0] - from[0]),
                        from[1] + s * (to[1] - from[1]),
                        heading,
                    ),
                    v_m_s: 0.0,
                    omega_rad_s: 0.0,
                }
            })
            .collect()
    }

    fn room_with(blocks: &[Block]) -> World {
        let room = twindrive_sim::polyline_segments(
            &[[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]],
            true,
        );
        World::new(room, Vec::new(), None).with_blocks(blocks)
    }

    /// Random blocks across a straight route: every detour keeps the
    /// footprint clear of the world by the wanted clearance (where the robot
    /// does not start against a block), ends on the route past the blocks and
    /// keeps the route's samples that were clear.
    /// A room with `block` on a straight route along y = 2 m, and the
    /// robot (footprint `r`) stopped against the block's west face: the
    /// world, the route, where it stands and the continuation from there.
    fn around(
        block: Block,
        r: f64,
        settings: &DetourSettings,
    ) -> (World, Vec<PathSample>, Pose, Vec<PathSample>) {
        let world = room_with(&[block]);
        let route = straight([0.6, 2.0], [5.4, 2.0], 480);
        let start = Pose::new(block.0[0] - r - 0.002, 2.0, 0.0);
        let k = route.iter().position(|s| s.pose.x_m > start.x_m).unwrap();
        let path = continuation_path(&world, r, start, &route[k..], &[block], settings).unwrap();
        (world, route, start, path)
    }

    #[test]
    fn detours_go_around_random_blocks_and_rejoin_the_route() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let r = 0.15;
        let settings = DetourSettings::default();
        for _ in 0..20 {
            let cx = rng.random_range(2.0..4.0);
            let half = [rng.random_range(0.05..0.3), rng.random_range(0.05..0.4)];
            let cy = 2.0 + rng.random_range(-0.2..0.2);
            let block = ([cx - half[0], cy - half[1]], [cx + half[0], cy + half[1]]);
            let (world, route, start, path) = around(block, r, &settings);
            assert_eq!(path[0].pose, start);
            let last = path.last().unwrap().pose;
            assert!((last.x_m - 5.4).abs() < 1e-9 && (last.y_m - 2.0).abs() < 1e-9);
            for s in &path {
                let c = world.clearance_m(s.pose.x_m, s.pose.y_m, 1.0) - r;
                let from_start = s.pose.distance_to(&start);
                // Leaving the contact it never comes closer than it stood,
                // and away from it it keeps the wanted clearance (the grid's
                // cell size is the planner's resolution).
                assert!(c > 0.0, "touches at {:?}", s.pose);
                if from_start > 0.3 {
                    assert!(
                        c >= settings.clearance_m - settings.resolution_m,
                        "{c} m clearance at {:?} around {block:?}",
                        s.pose
                    );
                }
            }
            // The route's clear samples past the block are kept as they were.
            let tail: Vec<_> = route
                .iter()
                .filter(|s| s.pose.x_m > block.1[0] + r + settings.clearance_m + 0.05)
                .collect();
            for s in tail {
                assert!(path.iter().any(|p| p.pose == s.pose));
            }
        }
    }

    /// A floor on the clearance holds everywhere away from the ends where
    /// a way keeps it (a block across the route with room either side);
    /// where none does (a gap narrower than the floor), the detour still
    /// goes through with the footprint clear.
    #[test]
    fn a_clearance_floor_is_kept_where_any_way_keeps_it() {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let r = 0.15;
        for _ in 0..10 {
            let floor = rng.random_range(0.12..0.3);
            let settings = DetourSettings {
                clearance_m: floor,
                min_clearance_m: floor,
                ..DetourSettings::default()
            };
            let cx = rng.random_range(2.5..3.5);
            let half = [rng.random_range(0.05..0.2), rng.random_range(0.1..0.4)];
            let block = ([cx - half[0], 2.0 - half[1]], [cx + half[0], 2.0 + half[1]]);
            let (world, _, start, path) = around(block, r, &settings);
            let end = path.last().unwrap().pose;
            for s in &path {
                let c = world.clearance_m(s.pose.x_m, s.pose.y_m, 1.0) - r;
                let near_end = s.pose.distance_to(&start).min(s.pose.distance_to(&end))
                    < r + floor + 2.0 * settings.resolution_m;
                assert!(c > 0.0, "touches at {:?}", s.pose);
                if !near_end {
                    assert!(c >= floor - 1e-9, "{c} m < {floor} m at {:?}", s.pose);
                }
            }
        }
        // A gap of 0.4 m between two blocks (a robot 0.3 m across): no way
        // keeps 0.2 m either side, the one through the gap is taken.
        let settings = DetourSettings {
            clearance_m: 0.2,
            min_clearance_m: 0.2,
            ..DetourSettings::default()
        };
        let blocks = [([2.8, 0.0], [3.0, 1.8]), ([2.8, 2.2], [3.0, 4.0])];
        let world = room_with(&blocks);
        let route = straight([0.6, 1.0], [5.4, 1.0], 480);
        let path = continuation_path(
            &world,
            0.15,
            Pose::new(0.6, 1.0, 0.0),
            &route[1..],
            &blocks,
            &settings,
        )
        .unwrap();
        assert!(
            path.iter()
                .all(|s| world.clearance_m(s.pose.x_m, s.pose.y_m, 1.0) > 0.15)
        );
        assert!(path.iter().any(|s| (s.pose.x_m - 2.9).abs() < 0.05));
    }

    #[test]
    fn a_route_walled_off_by_a_block_has_no_detour() {
        let block = ([2.0, 0.0], [2.2, 4.0]);
        let world = room_with(&[block]);
        let route = straight([0.6, 2.0], [5.4, 2.0], 480);
        let err = continuation_path(
            &world,
            0.15,
            Pose::new(1.848, 2.0, 0.0),
            &route[50..],
            &[block],
            &DetourSettings::default(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("no way on the twin"), "{err}");
    }
}
