//! Goal-level planning on the twin: the way for the robot's footprint from
//! where it stands through the operator's waypoints, on the twin's map, out
//! of keep-out zones, with the footprint clear of everything by the
//! clearance the operator set.
//!
//! The site is a grid of footprint clearances ([`crate::site_grid`]); the
//! search is the twin's own A* ([`crate::grid_search`], 8-connected) over
//! the cells that keep the clearance, its cells then shortened by line of
//! sight (a leg replaces a run of cells when every point along it keeps
//! the clearance). A differential drive turns in place, so the way is a
//! polyline: the robot turns at each corner and drives each leg straight
//! ([`crate::follower`]). A robot that starts closer to something than the
//! clearance may leave it (within `LEAVE_M` of the start any cell it does
//! not touch in is allowed).
//!
//! A waypoint that cannot be reached is refused with the reason: off the
//! site, too close to something (and how close), or closed off, with where
//! the search got nearest and the cell beyond it that blocks the way.

use std::fmt;

use serde::Serialize;
use twindrive_sim::World;

use crate::grid_search::{ClearanceGrid, Clearances, NEIGHBOURS};
use crate::plan::KeepOutZone;
use crate::site_grid::site_clearances;

/// Within this of the start a robot closer to something than the
/// clearance may still move, to leave it (m).
pub const LEAVE_M: f64 = 0.3;

/// A cell keeps the clearance with this to spare at least (m): the search
/// treats a clearance of 2 mm or less as touching.
const SPARE_M: f64 = 0.003;

/// How the way is planned.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RouteSettings {
    /// The grid's cell (m).
    pub cell_m: f64,
    /// The footprint kept clear of everything by this (m).
    pub clearance_m: f64,
}

impl Default for RouteSettings {
    fn default() -> Self {
        Self {
            cell_m: 0.05,
            clearance_m: 0.1,
        }
    }
}

/// The way through the waypoints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Route {
    /// Corners from the start to the last waypoint.
    pub points: Vec<[f64; 2]>,
    /// Where in `points` each waypoint is.
    pub stops: Vec<usize>,
    pub length_m: f64,
    /// The footprint's lowest clearance along the way (m; from the grid,
    /// never more than the true one).
    pub min_clearance_m: f64,
}

impl Route {
    /// How long a robot takes to drive it at `speed_m_s`, turning in place
    /// at `turn_rad_s` at each corner (s).
    pub fn duration_s(&self, speed_m_s: f64, turn_rad_s: f64) -> f64 {
        let headings: Vec<f64> = self
            .points
            .windows(2)
            .filter(|w| w[0] != w[1])
            .map(|w| (w[1][1] - w[0][1]).atan2(w[1][0] - w[0][0]))
            .collect();
        let turning: f64 = headings
            .windows(2)
            .map(|h| twindrive_kinematics::wrap_angle(h[1] - h[0]).abs())
            .sum();
        self.length_m / speed_m_s + turning / turn_rad_s
    }
}

/// Why a waypoint cannot be reached (`waypoint` counts from 1; 0 is the
/// start).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "why", rename_all = "snake_case")]
pub enum Unreachable {
    /// Outside the twin's site.
    OffSite { waypoint: usize, at: [f64; 2] },
    /// The footprint there is closer to something than the clearance.
    TooClose {
        waypoint: usize,
        at: [f64; 2],
        clearance_m: f64,
        need_m: f64,
    },
    /// No way keeps the clearance: the search got no nearer than
    /// `nearest`, and the way on towards the waypoint is blocked at
    /// `blocked_at`, where the footprint clears only `blocked_clearance_m`.
    Closed {
        waypoint: usize,
        at: [f64; 2],
        nearest: [f64; 2],
        short_m: f64,
        blocked_at: [f64; 2],
        blocked_clearance_m: f64,
        need_m: f64,
    },
}

impl Unreachable {
    /// Which waypoint (from 1; 0 is the start).
    pub fn waypoint(&self) -> usize {
        match self {
            Self::OffSite { waypoint, .. }
            | Self::TooClose { waypoint, .. }
            | Self::Closed { waypoint, .. } => *waypoint,
        }
    }

    /// The reason, with the waypoint called `name`.
    pub fn naming(&self, name: &str) -> String {
        match self {
            Self::OffSite { at, .. } => format!(
                "{name} at ({:.2}, {:.2}) is off the twin's site",
                at[0], at[1]
            ),
            Self::TooClose {
                at,
                clearance_m,
                need_m,
                ..
            } => format!(
                "{name} at ({:.2}, {:.2}): the robot's footprint there clears the nearest obstacle by {:.3} m, the route keeps {need_m:.3} m",
                at[0],
                at[1],
                clearance_m.max(0.0)
            ),
            Self::Closed {
                at,
                nearest,
                short_m,
                blocked_at,
                blocked_clearance_m,
                need_m,
                ..
            } => format!(
                "{name} at ({:.2}, {:.2}) cannot be reached keeping {need_m:.3} m clear: the nearest the robot gets is ({:.2}, {:.2}), {short_m:.2} m short; the way on is blocked at ({:.2}, {:.2}), where its footprint clears {:.3} m",
                at[0],
                at[1],
                nearest[0],
                nearest[1],
                blocked_at[0],
                blocked_at[1],
                blocked_clearance_m.max(0.0)
            ),
        }
    }
}

impl fmt::Display for Unreachable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self.waypoint() {
            0 => "the start".to_string(),
            k => format!("waypoint {k}"),
        };
        f.write_str(&self.naming(&name))
    }
}

impl std::error::Error for Unreachable {}

/// The twin's site, ready to plan ways on.
#[derive(Debug, Clone)]
pub struct RoutePlanner {
    /// Footprint clearances (m).
    site: ClearanceGrid,
    settings: RouteSettings,
    footprint_m: f64,
}

impl RoutePlanner {
    /// The planner for a robot of `footprint_m` on `world`, `zones` kept
    /// out of; `None` for a world with nothing in it.
    pub fn new(
        world: &World,
        zones: &[KeepOutZone],
        footprint_m: f64,
        settings: RouteSettings,
    ) -> Option<Self> {
        Some(Self {
            site: site_clearances(world, zones, footprint_m, settings.cell_m)?,
            settings,
            footprint_m,
        })
    }

    /// Whether the ground at `p` is free: its cell's centre outside every
    /// obstacle and zone.
    pub fn free_at(&self, p: [f64; 2]) -> bool {
        self.site.contains(p)
            && self.site.clearance(self.site.cell_of(p)) + self.footprint_m + self.half_diagonal()
                > 1e-9
    }

    /// The cells the robot's centre can get to from `start` keeping the
    /// clearance (8-connected, as the search moves): for
    /// [`RoutePlanner::reaches`].
    pub fn reachable_from(&self, start: [f64; 2]) -> Vec<bool> {
        self.flood(
            start,
            self.settings.clearance_m + self.half_diagonal() + SPARE_M,
        )
    }

    /// The free ground connected to `start` (8-connected through cells
    /// whose centres are outside every obstacle): the site's ground the
    /// robot is in, not what lies beyond a wall.
    pub fn ground_from(&self, start: [f64; 2]) -> Vec<bool> {
        self.flood(start, -self.footprint_m - self.half_diagonal() + 1e-9)
    }

    /// The cells connected to `start` through cells of clearance `floor`
    /// at least.
    fn flood(&self, start: [f64; 2], floor: f64) -> Vec<bool> {
        let need = floor;
        let [w, h] = self.site.size();
        let mut seen = vec![false; w * h];
        let first = self.site.cell_of(start);
        seen[first] = true;
        let mut stack = vec![first];
        while let Some(c) = stack.pop() {
            let (i, j) = ((c % w) as isize, (c / w) as isize);
            for (di, dj) in NEIGHBOURS {
                let (ni, nj) = (i + di, j + dj);
                if ni < 0 || nj < 0 || ni as usize >= w || nj as usize >= h {
                    continue;
                }
                let n = ni as usize + nj as usize * w;
                if !seen[n] && self.site.clearance(n) >= need {
                    seen[n] = true;
                    stack.push(n);
                }
            }
        }
        seen
    }

    /// Whether `p` is among the `reachable` cells ([`RoutePlanner::reachable_from`]).
    pub fn reaches(&self, reachable: &[bool], p: [f64; 2]) -> bool {
        self.site.contains(p) && reachable[self.site.cell_of(p)]
    }

    pub fn settings(&self) -> &RouteSettings {
        &self.settings
    }

    /// The footprint's clearance at `p` (m), never more than the true
    /// one: the best of the four cells around `p`, each less the way from
    /// its centre (clearance changes no faster than the way).
    pub fn clearance_at(&self, p: [f64; 2]) -> f64 {
        if !self.site.contains(p) {
            return -1.0;
        }
        let g = &self.site;
        let [w, h] = g.size();
        let o = g.centre(0);
        let i0 = ((p[0] - o[0]) / g.cell_m()).floor() as isize;
        let j0 = ((p[1] - o[1]) / g.cell_m()).floor() as isize;
        let mut best = f64::NEG_INFINITY;
        for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (i, j) = (i0 + di, j0 + dj);
            if i < 0 || j < 0 || i as usize >= w || j as usize >= h {
                continue;
            }
            let c = i as usize + j as usize * w;
            let q = g.centre(c);
            best = best.max(g.clearance(c) - (p[0] - q[0]).hypot(p[1] - q[1]));
        }
        best
    }

    /// Whether the footprint at `p` keeps the clearance (what every point
    /// of a straight leg of a way does).
    pub fn keeps_clearance(&self, p: [f64; 2]) -> bool {
        self.clearance_at(p) - self.settings.clearance_m > SPARE_M
    }

    fn half_diagonal(&self) -> f64 {
        self.settings.cell_m * std::f64::consts::FRAC_1_SQRT_2
    }

    /// The way from `start` through `waypoints` in order.
    pub fn route(&self, start: [f64; 2], waypoints: &[[f64; 2]]) -> Result<Route, Unreachable> {
        let need = self.settings.clearance_m;
        let check = |k: usize, at: [f64; 2], floor: f64| {
            if !self.site.contains(at) {
                return Err(Unreachable::OffSite { waypoint: k, at });
            }
            let clearance_m = self.clearance_at(at);
            if clearance_m < floor {
                return Err(Unreachable::TooClose {
                    waypoint: k,
                    at,
                    clearance_m,
                    need_m: need,
                });
            }
            Ok(())
        };
        // The start only has to be free of contact; the waypoints keep the
        // clearance.
        check(0, start, SPARE_M)?;
        for (k, &w) in waypoints.iter().enumerate() {
            check(k + 1, w, need)?;
        }
        // The search's grid: the clearance above what is kept anywhere in
        // the cell (cells keeping it are positive), near a start that is
        // too close, any cell free of contact.
        let mut kept = self.site.clone();
        let half_diagonal = self.half_diagonal();
        let near_start = self.clearance_at(start) < need + SPARE_M;
        for c in 0..kept.clearances_len() {
            let raw = self.site.clearance(c) - half_diagonal;
            let mut v = raw - need;
            if near_start && raw > SPARE_M {
                let p = self.site.centre(c);
                if (p[0] - start[0]).hypot(p[1] - start[1]) <= LEAVE_M {
                    v = v.max(SPARE_M);
                }
            }
            kept.clearances_mut()[c] = v;
        }
        let keep = Clearances {
            want_m: 1e-3,
            floor_m: 0.0,
            ends_m: 0.0,
        };
        let mut points = vec![start];
        let mut stops = Vec::with_capacity(waypoints.len());
        let mut from = start;
        for (k, &to) in waypoints.iter().enumerate() {
            let cells = kept
                .search_or_nearest(from, to, &keep)
                .map_err(|nearest| self.closed(&kept, k + 1, to, nearest))?;
            // Each point between `from` and its cell's centre lies in that
            // cell, and so on: every step is through cells that keep the
            // clearance.
            let mut leg = Vec::with_capacity(cells.len() + 2);
            leg.push(from);
            leg.extend(cells.iter().map(|&c| kept.centre(c)));
            leg.push(to);
            let short = shorten(&leg, &kept, &|p| self.clearance_at(p) - need);
            points.extend_from_slice(&short[1..]);
            stops.push(points.len() - 1);
            from = to;
        }
        let length_m = points
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum();
        let min_clearance_m = points
            .windows(2)
            .map(|w| {
                self.site
                    .leg_clearance(w[0], w[1], &|p| self.clearance_at(p))
            })
            .fold(self.clearance_at(start), f64::min);
        Ok(Route {
            points,
            stops,
            length_m,
            min_clearance_m,
        })
    }

    /// Why the way to waypoint `k` at `to` is closed: from `nearest`, the
    /// cell the search reached nearest to it, the first cell on the
    /// straight line on towards it that does not keep the clearance.
    fn closed(&self, kept: &ClearanceGrid, k: usize, to: [f64; 2], nearest: usize) -> Unreachable {
        let at = kept.centre(nearest);
        let short_m = (to[0] - at[0]).hypot(to[1] - at[1]);
        let steps = (short_m / (0.25 * self.settings.cell_m)).ceil().max(1.0) as usize;
        let blocked_at = (1..=steps)
            .map(|s| {
                let f = s as f64 / steps as f64;
                [at[0] + f * (to[0] - at[0]), at[1] + f * (to[1] - at[1])]
            })
            .find(|&p| kept.clearance(kept.cell_of(p)) <= SPARE_M)
            .map(|p| kept.centre(kept.cell_of(p)))
            .unwrap_or(to);
        Unreachable::Closed {
            waypoint: k,
            at: to,
            nearest: at,
            short_m,
            blocked_at,
            blocked_clearance_m: self.clearance_at(blocked_at),
            need_m: self.settings.clearance_m,
        }
    }
}

/// `leg`'s points shortened by line of sight: from each corner, on to the
/// next point while the straight leg there stays `clear` (every point
/// along it, sampled as `grid` samples a leg).
fn shorten(
    leg: &[[f64; 2]],
    grid: &ClearanceGrid,
    clear: &dyn Fn([f64; 2]) -> f64,
) -> Vec<[f64; 2]> {
    let sees = |a: [f64; 2], b: [f64; 2]| grid.leg_clearance(a, b, clear) > SPARE_M;
    let last = leg.len() - 1;
    let mut out = vec![leg[0]];
    let mut at = 0;
    while at < last {
        let mut next = at + 1;
        while next < last && sees(leg[at], leg[next + 1]) {
            next += 1;
        }
        out.push(leg[next]);
        at = next;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use twindrive_sim::World;

    /// A random site: a room with random blocks (clutter) and, half the
    /// time, a wall across it with a door (a corridor of a room).
    fn site(rng: &mut rand_chacha::ChaCha8Rng) -> World {
        let (w, h) = (rng.random_range(4.0..12.0), rng.random_range(4.0..12.0));
        let mut walls = vec![
            [0.0, 0.0, w, 0.0],
            [w, 0.0, w, h],
            [w, h, 0.0, h],
            [0.0, h, 0.0, 0.0],
        ];
        if rng.random_bool(0.5) {
            let x = rng.random_range(0.3 * w..0.7 * w);
            let door = rng.random_range(1.0..h - 1.5);
            walls.push([x, 0.0, x, door]);
            walls.push([x, door + 0.8, x, h]);
        }
        let blocks: Vec<([f64; 2], [f64; 2])> = (0..rng.random_range(3..12))
            .map(|_| {
                let (x, y) = (
                    rng.random_range(0.3..w - 0.3),
                    rng.random_range(0.3..h - 0.3),
                );
                (
                    [x, y],
                    [
                        x + rng.random_range(0.1..0.8),
                        y + rng.random_range(0.1..0.8),
                    ],
                )
            })
            .collect();
        World::from_walls(&walls, &[]).with_blocks(&blocks)
    }

    /// The shortest way on a grid of 2.5 cm cells keeping `need` clear,
    /// 16-connected (within 2.6 % of the straight distance; a move is
    /// taken when the cells along it keep the clearance): the reference the
    /// planner's way is held to.
    fn reference_length(
        world: &World,
        footprint: f64,
        need: f64,
        a: [f64; 2],
        b: [f64; 2],
    ) -> Option<f64> {
        #[derive(PartialEq)]
        struct Open(f64, usize);
        impl Eq for Open {}
        impl Ord for Open {
            fn cmp(&self, o: &Self) -> std::cmp::Ordering {
                o.0.total_cmp(&self.0)
            }
        }
        impl PartialOrd for Open {
            fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
                Some(self.cmp(o))
            }
        }
        let cell = 0.025;
        let grid = site_clearances(world, &[], footprint, cell).unwrap();
        let moves = [
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
            (1, 2),
            (2, 1),
            (-1, 2),
            (-2, 1),
            (1, -2),
            (2, -1),
            (-1, -2),
            (-2, -1),
        ];
        let (start, goal) = (grid.cell_of(a), grid.cell_of(b));
        let mut cost = vec![f64::INFINITY; grid.clearances_len()];
        let mut heap = std::collections::BinaryHeap::new();
        cost[start] = 0.0;
        heap.push(Open(0.0, start));
        while let Some(Open(c, here)) = heap.pop() {
            if here == goal {
                return Some(c);
            }
            if c > cost[here] {
                continue;
            }
            let p = grid.centre(here);
            for (di, dj) in moves {
                let q = [p[0] + di as f64 * cell, p[1] + dj as f64 * cell];
                if !grid.contains(q) {
                    continue;
                }
                let clear = (0..=4).all(|k| {
                    let f = k as f64 / 4.0;
                    let m = [p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])];
                    grid.clearance(grid.cell_of(m)) >= need
                });
                if !clear {
                    continue;
                }
                let next = grid.cell_of(q);
                let nc = c + cell * ((di * di + dj * dj) as f64).sqrt();
                if nc < cost[next] {
                    cost[next] = nc;
                    heap.push(Open(nc, next));
                }
            }
        }
        None
    }

    /// Random sites and random goals: every goal the reference reaches is
    /// reached, the footprint clear by the clearance all along (by the true
    /// distances of the twin's world), the way within 10 % of the shortest;
    /// a goal the reference cannot reach is refused.
    #[test]
    fn reachable_goals_are_reached_clear_and_near_the_shortest_way() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(410);
        let footprint = 0.15;
        let settings = RouteSettings::default();
        let (mut reached, mut refused) = (0, 0);
        while reached < 12 {
            let world = site(&mut rng);
            let planner = RoutePlanner::new(&world, &[], footprint, settings).unwrap();
            let b = world.bounds().unwrap();
            let mut free = || loop {
                let p = [
                    rng.random_range(b.mins.x + 0.3..b.maxs.x - 0.3),
                    rng.random_range(b.mins.y + 0.3..b.maxs.y - 0.3),
                ];
                if planner.clearance_at(p) >= settings.clearance_m + 0.02 {
                    return p;
                }
            };
            let (start, goal) = (free(), free());
            let reference = reference_length(&world, footprint, settings.clearance_m, start, goal);
            match (planner.route(start, &[goal]), reference) {
                (Ok(route), Some(shortest)) => {
                    let slack = 2.0 * settings.cell_m;
                    assert!(
                        route.length_m <= 1.10 * shortest + slack,
                        "{} m against the shortest {shortest} m",
                        route.length_m
                    );
                    for leg in route.points.windows(2) {
                        let n = 200;
                        for s in 0..=n {
                            let f = s as f64 / n as f64;
                            let p = [
                                leg[0][0] + f * (leg[1][0] - leg[0][0]),
                                leg[0][1] + f * (leg[1][1] - leg[0][1]),
                            ];
                            let clear = world.clearance_m(p[0], p[1], 5.0) - footprint;
                            assert!(
                                clear >= settings.clearance_m - 1e-6
                                    && !world
                                        .inside_obstacle(twindrive_sim::Vector::new(p[0], p[1])),
                                "{p:?} clears {clear} m"
                            );
                        }
                    }
                    assert_eq!(route.points.first(), Some(&start));
                    assert_eq!(route.points.last(), Some(&goal));
                    assert!(
                        route.min_clearance_m >= settings.clearance_m - 1e-9,
                        "{} m reported",
                        route.min_clearance_m
                    );
                    reached += 1;
                }
                (Err(why), None) => {
                    assert!(matches!(why, Unreachable::Closed { .. }), "{why}");
                    refused += 1;
                }
                (got, want) => panic!("planner {got:?}, reference {want:?}"),
            }
        }
        eprintln!("{reached} reached, {refused} refused");
    }

    /// A goal inside a block, one too near a wall, one off the site and
    /// one shut in a closed box are refused, each with its reason.
    #[test]
    fn unreachable_goals_say_why() {
        let walls = [
            [0.0, 0.0, 6.0, 0.0],
            [6.0, 0.0, 6.0, 4.0],
            [6.0, 4.0, 0.0, 4.0],
            [0.0, 4.0, 0.0, 0.0],
            // A closed box around (4.5, 2).
            [4.0, 1.5, 5.0, 1.5],
            [5.0, 1.5, 5.0, 2.5],
            [5.0, 2.5, 4.0, 2.5],
            [4.0, 2.5, 4.0, 1.5],
        ];
        let world = World::from_walls(&walls, &[]).with_blocks(&[([2.0, 2.0], [2.5, 2.5])]);
        let planner = RoutePlanner::new(&world, &[], 0.15, RouteSettings::default()).unwrap();
        let start = [1.0, 1.0];
        let why = planner.route(start, &[[2.2, 2.2]]).unwrap_err();
        assert!(
            matches!(why, Unreachable::TooClose { waypoint: 1, .. }),
            "{why}"
        );
        let why = planner
            .route(start, &[[3.0, 1.0], [5.85, 1.0]])
            .unwrap_err();
        assert!(
            matches!(why, Unreachable::TooClose { waypoint: 2, .. }),
            "{why}"
        );
        assert!(
            why.to_string().contains("waypoint 2 at (5.85, 1.00)"),
            "{why}"
        );
        let why = planner.route(start, &[[40.0, 1.0]]).unwrap_err();
        assert!(matches!(why, Unreachable::OffSite { .. }), "{why}");
        let why = planner.route(start, &[[4.5, 2.0]]).unwrap_err();
        let Unreachable::Closed {
            blocked_at,
            nearest,
            ..
        } = why
        else {
            panic!("{why}")
        };
        // The cell named is on the box's wall (within a cell of it and
        // the footprint), beyond the nearest the robot got.
        let to_wall = world.clearance_m(blocked_at[0], blocked_at[1], 5.0);
        assert!(
            to_wall <= 0.15 + 0.1 + 0.05,
            "{blocked_at:?} is {to_wall} m from a wall"
        );
        assert!((nearest[0] - 4.5).hypot(nearest[1] - 2.0) > 0.5);
        // Between two waypoints the way on is found.
        let route = planner
            .route(start, &[[3.0, 3.2], [5.5, 3.3], [5.5, 0.6]])
            .unwrap();
        assert_eq!(route.stops.len(), 3);
        assert_eq!(route.points[*route.stops.last().unwrap()], [5.5, 0.6]);
    }

    /// A keep-out zone across a room's only way round is kept out of: the
    /// way goes the other way round, or is refused when there is none.
    #[test]
    fn keep_out_zones_are_walls_to_the_route() {
        let walls = [
            [0.0, 0.0, 8.0, 0.0],
            [8.0, 0.0, 8.0, 4.0],
            [8.0, 4.0, 0.0, 4.0],
            [0.0, 4.0, 0.0, 0.0],
            [2.0, 2.0, 6.0, 2.0],
        ];
        let world = World::from_walls(&walls, &[]);
        let zone = KeepOutZone {
            name: "pond".into(),
            polygon: vec![[3.0, 0.0], [4.0, 0.0], [4.0, 2.0], [3.0, 2.0]],
        };
        let open = RoutePlanner::new(&world, &[], 0.15, RouteSettings::default()).unwrap();
        let zoned = RoutePlanner::new(
            &world,
            std::slice::from_ref(&zone),
            0.15,
            RouteSettings::default(),
        )
        .unwrap();
        let (a, b) = ([1.0, 1.0], [7.0, 1.0]);
        let direct = open.route(a, &[b]).unwrap();
        let around = zoned.route(a, &[b]).unwrap();
        assert!(direct.length_m < 6.5, "{}", direct.length_m);
        // Over the wall's end and back down: 7.4 m or so.
        assert!(
            around.length_m > direct.length_m + 1.0,
            "{}",
            around.length_m
        );
        assert!(
            around
                .points
                .iter()
                .all(|p| p[1] > 2.0 || p[0] < 2.5 || p[0] > 4.5)
        );
    }
}
