//! The robot's local planner: a way around what the twin did not know,
//! inside the corridor the operator approved, out of the keep-out zones,
//! back onto the plan. No I/O, no clock: scans and poses come in, a path
//! goes out.
//!
//! The robot plans on its own occupancy grid over a square window around
//! where the detour starts: the plan's map (its walls, rasterized once)
//! and what its lidar sees ([`LogOddsGrid`]: each beam clears the cells it
//! crosses and marks the one it ends in, so a box that moves away is
//! forgotten). An exact Euclidean distance transform (Felzenszwalb and
//! Huttenlocher, 2012) gives each cell its distance to the nearest
//! obstacle; a cell may hold the robot's centre when that distance keeps
//! the footprint clear by three standard deviations of the robot's
//! position, and the cell lies in the corridor (within the stretch's half
//! width less the footprint of the plan's path near the detour, a margin
//! inside so tracking noise does not leave it) and out of every keep-out
//! zone. The way is [`ClearanceGrid::waypoints`]: A* at a cost that grows
//! as the clearance falls below the wanted one, shortened by line of sight.
//!
//! Where it rejoins: the plan's samples ahead are each judged by the same
//! clearances; past the last one that passes closer to an obstacle than
//! the wanted clearance (the obstacle's stretch), the first sample
//! `rejoin_beyond_m` further on that is clear.

use std::sync::Arc;
use twindrive_estimation::mapping::{Beam as GridBeam, CellState, LogOdds, LogOddsGrid};
use twindrive_kinematics::Pose;

use twindrive_mission::distance_transform;
use twindrive_mission::freedom::{distance_to_boundary, inside};
use twindrive_mission::grid_search::{ClearanceGrid, Clearances};
use twindrive_mission::plan::MissionPlan;

/// How the robot plans around an obstacle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalPlannerSettings {
    /// Cell size of its grid (m).
    pub cell_m: f64,
    /// Side of the square window it plans over (m), centred where the
    /// detour starts.
    pub window_m: f64,
    /// Clearance it prefers beyond the footprint and three standard
    /// deviations of its position (m): passing closer costs more.
    pub want_clearance_m: f64,
    /// Rejoin the plan this far past the obstacle's stretch (m).
    pub rejoin_beyond_m: f64,
    /// How far along the plan it looks for the obstacle's stretch and a
    /// place to rejoin (m).
    pub look_ahead_m: f64,
    /// Planned inside the corridor by this much (m), so tracking noise
    /// does not take the robot out of it.
    pub corridor_margin_m: f64,
}

impl Default for LocalPlannerSettings {
    fn default() -> Self {
        Self {
            cell_m: 0.05,
            window_m: 8.0,
            want_clearance_m: 0.15,
            rejoin_beyond_m: 0.3,
            look_ahead_m: 3.0,
            corridor_margin_m: 0.05,
        }
    }
}

/// A way around: waypoints from the robot to the plan's sample `rejoin`.
#[derive(Debug, Clone, PartialEq)]
pub struct Detour {
    pub waypoints: Vec<[f64; 2]>,
    /// The plan sample it rejoins at.
    pub rejoin: usize,
    pub length_m: f64,
}

/// Why there is no way around.
#[derive(Debug, Clone, PartialEq)]
pub enum NoWay {
    /// No clear sample to rejoin at within the look-ahead (the obstacle
    /// fills the plan's path that far, or the window ends).
    NoRejoin,
    /// Nothing the robot's grid holds blocks the plan ahead: what stopped
    /// it is not in what the lidar sees, and it cannot plan around it.
    NotSeen,
    /// No way inside the corridor and out of the zones to the rejoin
    /// sample with the footprint clear.
    Enclosed { rejoin: usize },
}

/// The robot's local planner over one window.
pub struct LocalPlanner {
    settings: LocalPlannerSettings,
    footprint_m: f64,
    /// The plane's cell index of the window's corner cell, and its size.
    first: [i64; 2],
    size: [usize; 2],
    /// Cells the plan's map has a wall in.
    walls: Vec<bool>,
    /// Cells the robot's centre may plan through (corridor less its
    /// margin, out of the zones), and may stand in (the whole corridor).
    plannable: Vec<bool>,
    inside: Vec<bool>,
    /// What the lidar saw.
    seen: LogOddsGrid,
    /// Distance of each cell to the nearest obstacle (m), and scratch.
    distance: Vec<f64>,
    scratch: distance_transform::Scratch,
    search: ClearanceGrid,
    /// Arc length of each plan sample.
    along_m: Arc<[f64]>,
}

impl LocalPlanner {
    /// A planner for `plan` (`along_m`: its arc length at each sample, as
    /// [`twindrive_mission::freedom::sample_arc_lengths`] gives it) around `centre` (where the robot is when
    /// it first sees the obstacle), for the stretch of plan from sample `k`
    /// (its progress) on; `seen` carries on what earlier detours saw.
    pub fn new(
        plan: &MissionPlan,
        along_m: Arc<[f64]>,
        k: usize,
        centre: [f64; 2],
        settings: LocalPlannerSettings,
        seen: Option<LogOddsGrid>,
    ) -> Self {
        let r = settings.cell_m;
        let half = (0.5 * settings.window_m / r).ceil() as i64;
        let c = [
            (centre[0] / r).floor() as i64,
            (centre[1] / r).floor() as i64,
        ];
        let first = [c[0] - half, c[1] - half];
        let n = (2 * half + 1) as usize;
        let size = [n, n];
        assert_eq!(along_m.len(), plan.samples.len(), "an arc length a sample");
        let footprint_m = plan.header.robot.footprint_radius_m;
        let mut me = Self {
            settings,
            footprint_m,
            first,
            size,
            walls: vec![false; n * n],
            plannable: vec![false; n * n],
            inside: vec![false; n * n],
            seen: seen.unwrap_or_else(|| LogOddsGrid::new(r, LogOdds::default())),
            distance: vec![0.0; n * n],
            scratch: distance_transform::Scratch::default(),
            search: ClearanceGrid::new(
                [(first[0] as f64 + 0.5) * r, (first[1] as f64 + 0.5) * r],
                r,
                size,
                vec![-1.0; n * n],
            ),
            along_m,
        };
        me.draw_walls(&plan.header.site_map.segments);
        me.draw_corridor(plan, k);
        me
    }

    /// The robot's footprint radius (m).
    pub fn footprint_m(&self) -> f64 {
        self.footprint_m
    }

    /// What the lidar has seen, to carry on to the next detour.
    pub fn into_seen(self) -> LogOddsGrid {
        self.seen
    }

    fn cell_index(&self, p: [f64; 2]) -> Option<usize> {
        let r = self.settings.cell_m;
        let (i, j) = (
            (p[0] / r).floor() as i64 - self.first[0],
            (p[1] / r).floor() as i64 - self.first[1],
        );
        (i >= 0 && j >= 0 && (i as usize) < self.size[0] && (j as usize) < self.size[1])
            .then(|| i as usize + j as usize * self.size[0])
    }

    fn centre(&self, cell: usize) -> [f64; 2] {
        self.search.centre(cell)
    }

    /// Marks every cell a wall of the plan's map passes through.
    fn draw_walls(&mut self, segments: &[[f64; 4]]) {
        let r = self.settings.cell_m;
        let lo = [self.first[0] as f64 * r, self.first[1] as f64 * r];
        let hi = [
            lo[0] + self.size[0] as f64 * r,
            lo[1] + self.size[1] as f64 * r,
        ];
        for w in segments {
            if w[0].max(w[2]) < lo[0]
                || w[0].min(w[2]) > hi[0]
                || w[1].max(w[3]) < lo[1]
                || w[1].min(w[3]) > hi[1]
            {
                continue;
            }
            let length = (w[2] - w[0]).hypot(w[3] - w[1]);
            let steps = (length / (0.5 * r)).ceil().max(1.0) as usize;
            for s in 0..=steps {
                let f = s as f64 / steps as f64;
                if let Some(c) =
                    self.cell_index([w[0] + f * (w[2] - w[0]), w[1] + f * (w[3] - w[1])])
                {
                    self.walls[c] = true;
                }
            }
        }
    }

    /// Marks the cells the robot's centre may be in: within the half width
    /// (less the footprint) of the corridor's stretch at the nearest of the
    /// plan's samples from a metre behind sample `k` to the look-ahead and
    /// a metre past it (so a wide stretch does not spill into a narrow one
    /// beside it), give or take `corridor_margin_m` and half a cell's
    /// diagonal for tracking, and with the footprint out of every keep-out
    /// zone. The cells it may plan through keep `corridor_margin_m` inside
    /// the half width, and the footprint that margin and half a cell's
    /// diagonal off every zone.
    fn draw_corridor(&mut self, plan: &MissionPlan, k: usize) {
        let f = &plan.header.freedom;
        let r = self.settings.cell_m;
        let margin = self.settings.corridor_margin_m;
        let s0 = self.along_m.get(k).copied().unwrap_or(0.0);
        let (from, to) = (s0 - 1.0, s0 + self.settings.look_ahead_m + 1.0);
        // The samples a cell apart, with how far the centre may stray.
        let mut kept: Vec<([f64; 2], f64)> = Vec::new();
        let mut last_s = f64::NEG_INFINITY;
        for (i, s) in plan.samples.iter().enumerate() {
            let along = self.along_m[i];
            if along < from || along > to || along - last_s < r {
                continue;
            }
            let Some(hw) = f.half_width_at(along) else {
                continue;
            };
            last_s = along;
            kept.push(([s.x_m, s.y_m], hw - self.footprint_m));
        }
        let widest = kept.iter().map(|k| k.1).fold(0.0f64, f64::max);
        let n = self.inside.len();
        // Per cell, the squared distance to its nearest kept sample and
        // that sample's reach.
        let mut nearest_d2 = vec![f64::INFINITY; n];
        let mut nearest_reach = vec![-1.0f64; n];
        let span = (widest / r).ceil() as i64 + 2;
        let (w, h) = (self.size[0] as i64, self.size[1] as i64);
        let origin = [
            (self.first[0] as f64 + 0.5) * r,
            (self.first[1] as f64 + 0.5) * r,
        ];
        for &(p, reach) in &kept {
            let ci = (p[0] / r).floor() as i64 - self.first[0];
            let cj = (p[1] / r).floor() as i64 - self.first[1];
            for j in (cj - span).max(0)..=(cj + span).min(h - 1) {
                let dy = origin[1] + j as f64 * r - p[1];
                let dy2 = dy * dy;
                let row = (j * w) as usize;
                for i in (ci - span).max(0)..=(ci + span).min(w - 1) {
                    let dx = origin[0] + i as f64 * r - p[0];
                    let d2 = dx * dx + dy2;
                    let cell = row + i as usize;
                    if d2 < nearest_d2[cell] {
                        nearest_d2[cell] = d2;
                        nearest_reach[cell] = reach;
                    }
                }
            }
        }
        let half_diagonal = 0.5 * std::f64::consts::SQRT_2 * r;
        let zone_reach = self.footprint_m + margin + half_diagonal;
        let nearest = nearest_d2
            .iter()
            .zip(&nearest_reach)
            .map(|(d2, reach)| (d2.sqrt(), *reach));
        for (cell, (d, reach)) in nearest.enumerate() {
            // It may stand up to the margin (and the cell's quantisation)
            // outside what it plans in: tracking is not exact, and a
            // directed stretch (no reach at all) is still its path.
            if d > reach + margin + half_diagonal {
                continue;
            }
            let c = self.centre(cell);
            let mut stand = true;
            let mut pass = d <= reach - margin;
            for z in &f.keep_out {
                let into = inside(&z.polygon, c);
                let edge = distance_to_boundary(&z.polygon, c);
                stand &= !(into || edge < self.footprint_m);
                pass &= !(into || edge < zone_reach);
            }
            self.inside[cell] = stand;
            self.plannable[cell] = stand && pass;
        }
    }

    /// Whether the robot's centre at `p` is inside its corridor and out of
    /// the zones (as far as this window reaches).
    pub fn in_corridor(&self, p: [f64; 2]) -> bool {
        self.cell_index(p).is_some_and(|c| self.inside[c])
    }

    /// One scan of the lidar at `origin` (map frame): `ends[i]` where beam
    /// `i` ended (map frame; `None` for no return, which clears up to
    /// `max_ends[i]` without marking).
    pub fn integrate(&mut self, origin: [f64; 2], beams: &[([f64; 2], bool)]) {
        let beams: Vec<GridBeam> = beams
            .iter()
            .map(|&(end, hit)| GridBeam {
                end: if hit { end } else { [f64::NAN, f64::NAN] },
                free_to: end,
            })
            .collect();
        self.seen.integrate_beams(origin, &beams);
    }

    /// Whether the lidar has marked the cell at `p` occupied (something
    /// the map lacks, or a wall it has).
    pub fn seen_occupied(&self, p: [f64; 2]) -> bool {
        self.seen.state_at(p) == CellState::Occupied
    }

    /// The distance of every window cell to the nearest obstacle (walls of
    /// the map, and what the lidar marked occupied), and the footprint
    /// clearances the search uses: less the footprint and `keep_m` (three
    /// standard deviations of the position), negative where the robot's
    /// centre may not plan.
    fn update_clearances(&mut self, keep_m: f64) {
        let n = self.walls.len();
        let big = 1e12;
        for cell in 0..n {
            let occupied = self.walls[cell] || self.seen_occupied(self.centre(cell));
            self.distance[cell] = if occupied { 0.0 } else { big };
        }
        distance_transform::edt(&mut self.distance, self.size, &mut self.scratch);
        let r = self.settings.cell_m;
        let clearances = self.search.clearances_mut();
        for ((c, d2), plannable) in clearances
            .iter_mut()
            .zip(&self.distance)
            .zip(&self.plannable)
        {
            // Cells to metres; an obstacle cell's own half width counts.
            let d = d2.sqrt() * r - 0.5 * r;
            *c = if *plannable {
                d - self.footprint_m - keep_m
            } else {
                -1.0
            };
        }
    }

    /// The footprint's clearance at `p` (m) as the last
    /// [`plan`](Self::plan) saw it; negative outside the window.
    pub fn clearance_at(&self, p: [f64; 2]) -> f64 {
        match self.cell_index(p) {
            Some(c) => {
                self.distance[c].sqrt() * self.settings.cell_m
                    - 0.5 * self.settings.cell_m
                    - self.footprint_m
            }
            None => -1.0,
        }
    }

    /// A way from `from` back onto `plan` past what blocks it from sample
    /// `k` on, keeping `keep_m` (three standard deviations of the robot's
    /// position) beyond the footprint. When nothing blocks the plan any
    /// more (what it went around moved away), the way leads to `rejoined`
    /// (the sample an earlier plan of this detour rejoined at), if given.
    pub fn plan(
        &mut self,
        plan: &MissionPlan,
        k: usize,
        from: Pose,
        keep_m: f64,
        rejoined: Option<usize>,
    ) -> Result<Detour, NoWay> {
        self.update_clearances(keep_m);
        let want = self.settings.want_clearance_m;
        let samples = &plan.samples;
        let s0 = self.along_m[k.min(samples.len() - 1)];
        let within = |i: usize| self.along_m[i] <= s0 + self.settings.look_ahead_m;
        let clear = |i: usize| {
            let p = [samples[i].x_m, samples[i].y_m];
            self.search.contains(p) && self.search.clearance(self.search.cell_of(p)) >= want
        };
        // The obstacle's stretch: the last sample ahead passing closer
        // than wanted.
        let last_blocked = (k..samples.len())
            .take_while(|&i| within(i))
            .filter(|&i| !clear(i))
            .last();
        let rejoin = match (last_blocked, rejoined) {
            (Some(last_blocked), _) => {
                let beyond = self.along_m[last_blocked] + self.settings.rejoin_beyond_m;
                (last_blocked..samples.len())
                    .take_while(|&i| self.search.contains([samples[i].x_m, samples[i].y_m]))
                    .find(|&i| self.along_m[i] >= beyond && clear(i))
                    .ok_or(NoWay::NoRejoin)?
            }
            (None, Some(r)) => r,
            (None, None) => return Err(NoWay::NotSeen),
        };
        let goal = [samples[rejoin].x_m, samples[rejoin].y_m];
        let keep = Clearances {
            want_m: want,
            floor_m: 0.0,
            ends_m: self.footprint_m + want + self.settings.cell_m,
        };
        let grid = &self.search;
        let lookup = |p: [f64; 2]| {
            if grid.contains(p) {
                grid.clearance(grid.cell_of(p))
            } else {
                -1.0
            }
        };
        let waypoints = grid
            .waypoints([from.x_m, from.y_m], goal, &keep, &lookup)
            .ok_or(NoWay::Enclosed { rejoin })?;
        let length_m = waypoints
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum();
        Ok(Detour {
            waypoints,
            rejoin,
            length_m,
        })
    }

    /// The plan's arc length at sample `i` (m).
    pub fn along_m(&self, i: usize) -> f64 {
        self.along_m[i.min(self.along_m.len() - 1)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight plan along y = 0 from x = 0 to 10 in an empty site, with
    /// the corridor `stretches` and `zones`.
    fn straight_plan(
        stretches: &[(f64, f64)],
        zones: Vec<twindrive_mission::plan::KeepOutZone>,
    ) -> MissionPlan {
        use twindrive_mission::plan::*;
        let samples = (0..=1000)
            .map(|k| PlanSample {
                t_s: k as f64 * 0.05,
                x_m: k as f64 * 0.01,
                y_m: 0.0,
                heading_rad: 0.0,
                v_m_s: 0.2,
                omega_rad_s: 0.0,
                left_rad_s: 6.0,
                right_rad_s: 6.0,
                expected_bump: false,
            })
            .collect();
        let header = PlanHeader {
            robot: RobotInfo {
                scenario: "unit".into(),
                footprint_radius_m: 0.15,
                ticks_per_rev: 512,
                range_sensors: Vec::new(),
            },
            calibrated: twindrive_kinematics::DiffDriveParams::new(0.065, 0.065, 0.27),
            limits: WheelLimits {
                max_speed_rad_s: 12.0,
                max_accel_rad_s2: 30.0,
            },
            time_step_s: 0.05,
            start: Pose::new(0.0, 0.0, 0.0),
            start_covariance: None,
            site_map: SiteMap::default(),
            freedom: Freedom {
                corridor: stretches
                    .iter()
                    .map(|&(from_m, half_width_m)| CorridorStretch {
                        from_m,
                        half_width_m,
                    })
                    .collect(),
                keep_out: zones,
                max_extra_time_s: 60.0,
                max_extra_distance_m: 5.0,
            },
            goals: Default::default(),
            source_log_sha256: "0".repeat(64),
            settings: serde_json::json!({}),
            summary: serde_json::json!({}),
        };
        MissionPlan::new(header, samples)
    }

    /// Beside a directed stretch (half width the footprint) that follows a
    /// wide one, the robot may not stand, though the wide stretch's reach
    /// would cover it; beside the wide one it may. A zone is kept off by
    /// the footprint (to stand) and the margin more (to plan).
    #[test]
    fn the_corridor_is_the_nearest_stretchs_and_zones_keep_a_margin() {
        let zone = twindrive_mission::plan::KeepOutZone {
            name: "pit".into(),
            polygon: vec![[2.0, 0.5], [3.0, 0.5], [3.0, 1.5], [2.0, 1.5]],
        };
        let plan = straight_plan(&[(0.0, 1.2), (5.0, 0.15)], vec![zone]);
        plan.validate().unwrap();
        let p = LocalPlanner::new(
            &plan,
            twindrive_mission::freedom::sample_arc_lengths(&plan.samples).into(),
            450,
            [4.5, 0.0],
            LocalPlannerSettings::default(),
            None,
        );
        assert!(p.in_corridor([4.0, 0.8]));
        assert!(!p.in_corridor([5.6, 0.5]), "beside the directed stretch");
        assert!(p.in_corridor([5.6, 0.0]), "on the path");
        assert!(p.in_corridor([5.6, 0.06]), "tracking the path");
        let plannable = |q: [f64; 2]| p.cell_index(q).is_some_and(|c| p.plannable[c]);
        assert!(
            !plannable([5.6, 0.0]),
            "no room to plan beside a directed stretch"
        );
        // The zone: its footprint reach is out; beyond it, in.
        assert!(!p.in_corridor([2.5, 0.4]));
        assert!(p.in_corridor([2.5, 0.3]));
        assert!(!plannable([2.5, 0.3]), "too near the zone to plan through");
        assert!(plannable([2.5, 0.1]));
    }
}
