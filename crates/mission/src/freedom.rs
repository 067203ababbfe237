//! The geometry of a plan's [`Freedom`]: the default corridor from the
//! twin's clearance, the operator's corridor regions and keep-out zones
//! applied to a path, and the checks a track is held to (the verification
//! on the twin, the robot's own local planner).
//!
//! **The default corridor.** At each sample of the path, a ray is cast
//! across it to the left and to the right in the twin's world; the wider
//! side's free distance, capped at `max_half_width_m`, is how far the
//! robot's body may stray there: where the twin knows a wall close on one
//! side and open ground on the other, the corridor reaches across the open
//! ground (it may overlap the wall: walls stay obstacles). A stretch of
//! `stretch_m` along the path takes the narrowest of its samples, so a
//! door frame holds its whole stretch to the door's width, and
//! neighbouring stretches of equal width (to `WIDTH_STEP_M`) are merged.
//! The corridor is never narrower than the robot's footprint.
//!
//! **The operator's corridor regions** override the default wherever the
//! path passes through them (the later region wins): a region of half
//! width equal to the footprint radius holds the robot to its path there
//! (directed driving, as rover planners choose on a stretch they trust
//! only their own eyes on).

use serde::{Deserialize, Serialize};
use twindrive_sim::{Vector, World};

use crate::plan::{CorridorStretch, Freedom, KeepOutZone, PlanSample, check_polygon};

/// Corridor widths are rounded down to this (m), so a plan's stretches are
/// few and its bytes stable under noise.
pub const WIDTH_STEP_M: f64 = 0.05;

/// The shortest default stretch, and the narrowest widest half width (m).
pub const MIN_STRETCH_M: f64 = 0.01;

/// How a plan's freedom is made: the operator's settings (a `freedom`
/// TOML for `twindrive plan`, or the console), recorded with the plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FreedomSettings {
    /// The default corridor's widest half width (m).
    pub max_half_width_m: f64,
    /// The length of path one default stretch covers (m).
    pub stretch_m: f64,
    /// Regions where the operator sets the corridor's half width.
    pub corridor: Vec<CorridorRegion>,
    /// Zones the robot never enters.
    pub keep_out: Vec<KeepOutZone>,
    /// The detours together may make the mission this much later (s) at
    /// most.
    pub max_extra_time_s: f64,
    /// One detour may add this much distance (m) at most.
    pub max_extra_distance_m: f64,
}

impl Default for FreedomSettings {
    fn default() -> Self {
        Self {
            max_half_width_m: 1.5,
            stretch_m: 0.5,
            corridor: Vec::new(),
            keep_out: Vec::new(),
            max_extra_time_s: 60.0,
            max_extra_distance_m: 5.0,
        }
    }
}

/// Where the path runs inside `region` (a simple polygon), the corridor's
/// half width is `half_width_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorridorRegion {
    pub region: Vec<[f64; 2]>,
    pub half_width_m: f64,
}

impl FreedomSettings {
    /// Checks the settings for a robot of `footprint_radius_m`; errors name
    /// the field (`corridor[1].half_width_m`).
    pub fn validate(&self, footprint_radius_m: f64) -> Result<(), String> {
        for (field, v) in [
            ("max_half_width_m", self.max_half_width_m),
            ("stretch_m", self.stretch_m),
        ] {
            if !(v.is_finite() && v >= MIN_STRETCH_M) {
                return Err(format!(
                    "field `{field}`: expected a finite number of at least {MIN_STRETCH_M} m, got {v}"
                ));
            }
        }
        for (field, v) in [
            ("max_extra_time_s", self.max_extra_time_s),
            ("max_extra_distance_m", self.max_extra_distance_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "field `{field}`: expected a finite number >= 0, got {v}"
                ));
            }
        }
        for (i, c) in self.corridor.iter().enumerate() {
            check_polygon(&c.region).map_err(|e| format!("field `corridor[{i}].region`: {e}"))?;
            if !(c.half_width_m.is_finite() && c.half_width_m >= footprint_radius_m) {
                return Err(format!(
                    "field `corridor[{i}].half_width_m`: {} m is narrower than the robot's footprint radius {footprint_radius_m} m (the robot would not fit; the footprint radius itself holds it to its path)",
                    c.half_width_m
                ));
            }
        }
        let probe = Freedom {
            keep_out: self.keep_out.clone(),
            ..Freedom::default()
        };
        probe.validate(footprint_radius_m).map_err(|e| {
            e.to_string()
                .replace("header.freedom.", "field `")
                .replacen(':', "`:", 1)
        })
    }

    /// The freedom of a plan along `path` (positions, in order) for a robot
    /// of `footprint_radius_m` in the twin's `world`.
    pub fn freedom_along(
        &self,
        path: &[[f64; 2]],
        world: &World,
        footprint_radius_m: f64,
    ) -> Freedom {
        Freedom {
            corridor: self.corridor_along(path, world, footprint_radius_m),
            keep_out: self.keep_out.clone(),
            max_extra_time_s: self.max_extra_time_s,
            max_extra_distance_m: self.max_extra_distance_m,
        }
    }

    /// The corridor's stretches along `path` (see the module docs).
    pub fn corridor_along(
        &self,
        path: &[[f64; 2]],
        world: &World,
        footprint_radius_m: f64,
    ) -> Vec<CorridorStretch> {
        if path.is_empty() {
            return Vec::new();
        }
        let along = arc_lengths(path);
        let cap = self.max_half_width_m.max(footprint_radius_m);
        let width_at = |k: usize| -> f64 {
            let p = path[k];
            if let Some(region) = self.corridor.iter().rev().find(|c| inside(&c.region, p)) {
                return region.half_width_m;
            }
            let d = direction_at(path, k);
            let across = |sign: f64| {
                world.cast_ray(
                    Vector::new(p[0], p[1]),
                    Vector::new(-d[1] * sign, d[0] * sign),
                    cap,
                )
            };
            let free = across(1.0).max(across(-1.0));
            // Whole steps, divided (not multiplied) so 1.2 is 1.2.
            let per_m = (1.0 / WIDTH_STEP_M).round();
            let stepped = (free * per_m + 1e-9).floor() / per_m;
            stepped.clamp(footprint_radius_m, cap)
        };
        let mut stretches: Vec<CorridorStretch> = Vec::new();
        let mut k = 0;
        while k < path.len() {
            let from_m = along[k];
            let mut width = f64::INFINITY;
            while k < path.len() && along[k] < from_m + self.stretch_m {
                width = width.min(width_at(k));
                k += 1;
            }
            match stretches.last() {
                Some(last) if (last.half_width_m - width).abs() < 1e-9 => {}
                _ => stretches.push(CorridorStretch {
                    from_m,
                    half_width_m: width,
                }),
            }
        }
        stretches
    }
}

/// `world` with the outlines of `zones` as walls: what a planner that
/// must keep out of them plans in (a robot outside a zone cannot reach
/// its inside without crossing its outline).
pub fn with_zones_as_walls(world: &World, zones: &[KeepOutZone]) -> World {
    if zones.is_empty() {
        return world.clone();
    }
    let walls: Vec<[f64; 4]> = zones
        .iter()
        .flat_map(|z| {
            let n = z.polygon.len();
            (0..n).map(move |i| {
                let (a, b) = (z.polygon[i], z.polygon[(i + 1) % n]);
                [a[0], a[1], b[0], b[1]]
            })
        })
        .collect();
    world.with_walls(&walls)
}

/// Cumulative distance along the positions of plan `samples` at each.
pub fn sample_arc_lengths(samples: &[PlanSample]) -> Vec<f64> {
    let path: Vec<[f64; 2]> = samples.iter().map(|s| [s.x_m, s.y_m]).collect();
    arc_lengths(&path)
}

/// Cumulative distance along `path` at each of its points.
pub fn arc_lengths(path: &[[f64; 2]]) -> Vec<f64> {
    let mut s = 0.0;
    let mut out = Vec::with_capacity(path.len());
    for (k, p) in path.iter().enumerate() {
        if k > 0 {
            let q = path[k - 1];
            s += (p[0] - q[0]).hypot(p[1] - q[1]);
        }
        out.push(s);
    }
    out
}

/// The path's direction at point `k` (unit), from its neighbours; along x
/// where the path does not move.
fn direction_at(path: &[[f64; 2]], k: usize) -> [f64; 2] {
    let a = path[k.saturating_sub(1)];
    let b = path[(k + 1).min(path.len() - 1)];
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let n = dx.hypot(dy);
    if n > 1e-12 {
        [dx / n, dy / n]
    } else {
        [1.0, 0.0]
    }
}

/// Whether `p` is inside the simple polygon `polygon` (crossing number; a
/// point on the boundary may go either way).
pub fn inside(polygon: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = polygon.len();
    let mut odd = false;
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                odd = !odd;
            }
        }
    }
    odd
}

/// Distance from `p` to the boundary of `polygon`.
pub fn distance_to_boundary(polygon: &[[f64; 2]], p: [f64; 2]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| segment_distance(polygon[i], polygon[(i + 1) % n], p))
        .fold(f64::INFINITY, f64::min)
}

fn segment_distance(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let u = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - u * dx).hypot(p[1] - a[1] - u * dy)
}

/// A plan's freedom laid on its samples, for checking tracks against it.
#[derive(Debug, Clone)]
pub struct FreedomMap<'a> {
    freedom: &'a Freedom,
    footprint_radius_m: f64,
    /// Arc length at each plan sample.
    along_m: Vec<f64>,
}

/// No corridor, no zones: a path replayed for itself.
static UNCONSTRAINED: Freedom = Freedom {
    corridor: Vec::new(),
    keep_out: Vec::new(),
    max_extra_time_s: 0.0,
    max_extra_distance_m: 0.0,
};

impl FreedomMap<'static> {
    /// A path with no freedom to check (a replay of a bare path, not of a
    /// plan): nothing is out of bounds.
    pub fn unconstrained() -> Self {
        Self {
            freedom: &UNCONSTRAINED,
            footprint_radius_m: 0.0,
            along_m: Vec::new(),
        }
    }
}

impl<'a> FreedomMap<'a> {
    /// The freedom `plan` carries, on its own samples.
    pub fn of_plan(plan: &'a crate::plan::MissionPlan) -> Self {
        Self::new(
            &plan.samples,
            &plan.header.freedom,
            plan.header.robot.footprint_radius_m,
        )
    }

    /// `freedom` on the plan `samples` for a robot of `footprint_radius_m`.
    pub fn new(samples: &[PlanSample], freedom: &'a Freedom, footprint_radius_m: f64) -> Self {
        Self {
            freedom,
            footprint_radius_m,
            along_m: sample_arc_lengths(samples),
        }
    }

    /// The keep-out zone the robot's footprint at `(x, y)` overlaps, if any.
    pub fn zone_hit(&self, p: [f64; 2]) -> Option<&'a KeepOutZone> {
        self.freedom.keep_out.iter().find(|z| {
            inside(&z.polygon, p) || distance_to_boundary(&z.polygon, p) < self.footprint_radius_m
        })
    }

    /// How far the footprint of a robot `distance_m` from the plan's path,
    /// level with plan sample `k`, reaches beyond the corridor there (m;
    /// 0 or less inside it), or `None` without a corridor.
    pub fn corridor_excess_m(&self, k: usize, distance_m: f64) -> Option<f64> {
        let along = self.along_m.get(k).copied().unwrap_or(0.0);
        self.freedom
            .half_width_at(along)
            .map(|w| distance_m + self.footprint_radius_m - w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2 m wide corridor along x from 0 to 10 with a 0.9 m door at x = 5.
    fn corridor_world() -> World {
        World::from_walls(
            &[
                [0.0, -1.0, 10.0, -1.0],
                [0.0, 1.0, 4.9, 1.0],
                [5.1, 1.0, 10.0, 1.0],
                [4.9, 1.0, 4.9, 0.45],
                [5.1, 1.0, 5.1, 0.45],
                [4.9, 0.45, 5.1, 0.45],
                [4.9, -1.0, 4.9, -0.45],
                [5.1, -1.0, 5.1, -0.45],
                [4.9, -0.45, 5.1, -0.45],
            ],
            &[],
        )
    }

    fn straight(y: f64) -> Vec<[f64; 2]> {
        (0..=400).map(|k| [0.5 + k as f64 * 0.02, y]).collect()
    }

    #[test]
    fn the_default_corridor_reaches_the_far_wall_narrows_at_a_door_and_merges() {
        let s = FreedomSettings::default();
        let c = s.corridor_along(&straight(0.3), &corridor_world(), 0.15);
        // Off centre: the wider side is 1.3 m to the far wall.
        assert_eq!(c[0].from_m, 0.0);
        assert!((c[0].half_width_m - 1.3).abs() < 1e-9, "{c:?}");
        let door = c
            .iter()
            .find(|s| s.half_width_m < 1.0)
            .expect("the door narrows a stretch");
        // Through the door, 0.75 m: from the path at y = 0.3 down to the
        // door's far jamb at y = -0.45.
        assert!((door.half_width_m - 0.75).abs() < 1e-9, "{c:?}");
        // The door stretch is the one around x = 5 (arc 4.5 m).
        assert!((3.9..=4.6).contains(&door.from_m), "{c:?}");
        // Merged: a handful of stretches for 8 m.
        assert!(c.len() <= 4, "{c:?}");
        for w in c.windows(2) {
            assert!(w[0].from_m < w[1].from_m && w[0].half_width_m != w[1].half_width_m);
        }
        // In the open, the cap.
        let open = s.corridor_along(&straight(50.0), &corridor_world(), 0.15);
        assert_eq!(open.len(), 1);
        assert_eq!(open[0].half_width_m, 1.5);
    }

    #[test]
    fn an_operators_region_overrides_the_default_where_the_path_runs_through_it() {
        let s = FreedomSettings {
            corridor: vec![CorridorRegion {
                region: vec![[1.0, -2.0], [3.0, -2.0], [3.0, 2.0], [1.0, 2.0]],
                half_width_m: 0.15,
            }],
            ..FreedomSettings::default()
        };
        s.validate(0.15).unwrap();
        let c = s.corridor_along(&straight(0.0), &corridor_world(), 0.15);
        let f = Freedom {
            corridor: c,
            ..Freedom::default()
        };
        assert_eq!(f.half_width_at(0.2), Some(1.0));
        assert_eq!(f.half_width_at(1.5), Some(0.15));
        assert_eq!(f.half_width_at(3.0), Some(1.0));
        let narrow = FreedomSettings {
            corridor: vec![CorridorRegion {
                half_width_m: 0.1,
                ..s.corridor[0].clone()
            }],
            ..s.clone()
        };
        let e = narrow.validate(0.15).unwrap_err();
        assert!(
            e.contains("field `corridor[0].half_width_m`: 0.1 m is narrower"),
            "{e}"
        );
        let zone = FreedomSettings {
            keep_out: vec![KeepOutZone {
                name: "pit".into(),
                polygon: vec![[0.0, 0.0], [1.0, 0.0]],
            }],
            ..FreedomSettings::default()
        };
        let e = zone.validate(0.15).unwrap_err();
        assert!(
            e.starts_with("field `keep_out[0].polygon`: zone `pit`"),
            "{e}"
        );
    }

    /// A block on a straight route in a room and a keep-out zone of random
    /// size beside it on a random side: the detour around the block, planned
    /// with the zone's outline as walls, never puts the footprint in the
    /// zone, and goes round the block's other side.
    #[test]
    fn detours_around_a_block_keep_out_of_a_random_zone_beside_it() {
        use crate::PathSample;
        use crate::detour::{DetourSettings, continuation_path};
        use rand::{RngExt, SeedableRng};
        use twindrive_kinematics::Pose;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(41);
        let r = 0.15;
        for _ in 0..10 {
            let block = ([2.8, 1.8], [3.2, 2.2]);
            let room = twindrive_sim::polyline_segments(
                &[[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]],
                true,
            );
            let world = World::new(room, Vec::new(), None).with_blocks(&[block]);
            let side: f64 = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let (x0, x1) = (rng.random_range(2.2..2.8), rng.random_range(3.2..3.8));
            let reach = rng.random_range(0.6..1.5);
            let (near, far) = (2.0 + side * 0.25, 2.0 + side * (0.25 + reach));
            let zone = KeepOutZone {
                name: "pit".into(),
                polygon: vec![[x0, near], [x1, near], [x1, far], [x0, far]],
            };
            let route: Vec<PathSample> = (0..=480)
                .map(|k| PathSample {
                    t_s: k as f64 * 0.02,
                    pose: Pose::new(0.6 + k as f64 * 0.01, 2.0, 0.0),
                    v_m_s: 0.0,
                    omega_rad_s: 0.0,
                })
                .collect();
            let start = Pose::new(block.0[0] - r - 0.3, 2.0, 0.0);
            let k = route.iter().position(|s| s.pose.x_m > start.x_m).unwrap();
            let walled = with_zones_as_walls(&world, std::slice::from_ref(&zone));
            let path = continuation_path(
                &walled,
                r,
                start,
                &route[k..],
                &[block],
                &DetourSettings::default(),
            )
            .unwrap();
            let freedom = Freedom {
                keep_out: vec![zone.clone()],
                ..Freedom::default()
            };
            let map = FreedomMap::new(&[], &freedom, r);
            for s in &path {
                assert!(
                    map.zone_hit(s.position()).is_none(),
                    "in the zone at {:?}: {zone:?}",
                    s.pose
                );
            }
            let passing = path
                .iter()
                .find(|s| (2.9..3.1).contains(&s.pose.x_m))
                .expect("the detour passes the block");
            assert!(
                (passing.pose.y_m - 2.0) * side < 0.0,
                "round the zone's side at {:?}",
                passing.pose
            );
        }
    }

    #[test]
    fn a_footprint_overlapping_a_zone_is_caught_inside_and_at_the_edge() {
        let freedom = Freedom {
            keep_out: vec![KeepOutZone {
                name: "pit".into(),
                polygon: vec![[2.0, -0.5], [3.0, -0.5], [3.0, 0.5], [2.0, 0.5]],
            }],
            ..Freedom::default()
        };
        let samples: Vec<PlanSample> = Vec::new();
        let map = FreedomMap::new(&samples, &freedom, 0.2);
        assert_eq!(
            map.zone_hit([2.5, 0.0]).map(|z| z.name.as_str()),
            Some("pit")
        );
        assert!(
            map.zone_hit([1.85, 0.0]).is_some(),
            "the footprint reaches in"
        );
        assert!(map.zone_hit([1.79, 0.0]).is_none());
        assert!(map.zone_hit([2.5, 0.71]).is_none());
        assert_eq!(map.corridor_excess_m(0, 0.3), None);
    }
}
