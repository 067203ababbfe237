//! Sweeping an area the operator drew: waypoints whose way covers the free
//! ground inside a polygon with the robot's sweep (a disc of
//! `sweep_radius_m` about its centre: its footprint, or its sensor's), and
//! the share of that ground a driven track covered.
//!
//! **Lanes** (boustrophedon): straight lanes along the polygon's longest
//! edge, `2 sweep_radius_m` apart less a tenth for overlap, each cut where
//! the footprint would not keep the clearance or would leave the polygon,
//! driven in turn, back and forth. **Touch-ups**: ground the lanes leave
//! (beside obstacles parallel to them, in corners) is swept by extra
//! stops: for each cell not yet covered, the place nearest it from which
//! the sweep reaches it and the footprint keeps the clearance, taken in
//! nearest-first order. Ground no such place reaches (closer to an
//! obstacle than the clearance, in a corner) stays unswept and counts
//! against the share.
//!
//! Free ground is every cell of the polygon (at the planner's cell) whose
//! centre is outside every obstacle and keep-out zone and that connects to
//! where the robot starts through such cells (ground beyond a wall the
//! polygon was drawn across is not the robot's to sweep).

use serde::Serialize;

use crate::route::RoutePlanner;

/// How an area is swept.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SweepSettings {
    /// The sweep's radius about the robot's centre (m).
    pub sweep_radius_m: f64,
    /// Lanes overlap by this share of the sweep's width.
    pub overlap: f64,
}

/// The waypoints of a sweep and the ground they are planned to cover.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sweep {
    /// In order: lane ends, then touch-ups.
    pub waypoints: Vec<[f64; 2]>,
    pub lanes: usize,
    pub touch_ups: usize,
    /// The polygon's free ground (m²), and the share of it the waypoints'
    /// straight connections cover, as planned (%).
    pub free_m2: f64,
    pub planned_percent: f64,
}

/// The ground cells of `area` (centres, on the planner's grid) that are
/// free (outside every obstacle and zone) and connect to `start`.
fn free_cells(planner: &RoutePlanner, area: &[[f64; 2]], start: [f64; 2]) -> Vec<[f64; 2]> {
    let cell = planner.settings().cell_m;
    let ground = planner.ground_from(start);
    let (lo, hi) = bounds(area);
    let mut out = Vec::new();
    let mut y = (lo[1] / cell).ceil() * cell;
    while y <= hi[1] {
        let mut x = (lo[0] / cell).ceil() * cell;
        while x <= hi[0] {
            let p = [x, y];
            if crate::freedom::inside(area, p) && planner.free_at(p) && planner.reaches(&ground, p)
            {
                out.push(p);
            }
            x += cell;
        }
        y += cell;
    }
    out
}

fn bounds(area: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in area {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// A grid of booleans over the bounds of `area` at `cell_m`: which ground
/// cells a sweep has covered.
struct Covered {
    lo: [f64; 2],
    cell_m: f64,
    size: [usize; 2],
    hit: Vec<bool>,
}

impl Covered {
    fn new(area: &[[f64; 2]], cell_m: f64) -> Self {
        let (lo, hi) = bounds(area);
        let size = [
            ((hi[0] - lo[0]) / cell_m).ceil() as usize + 2,
            ((hi[1] - lo[1]) / cell_m).ceil() as usize + 2,
        ];
        Self {
            lo,
            cell_m,
            size,
            hit: vec![false; size[0] * size[1]],
        }
    }

    fn index(&self, p: [f64; 2]) -> Option<usize> {
        let i = ((p[0] - self.lo[0]) / self.cell_m).round();
        let j = ((p[1] - self.lo[1]) / self.cell_m).round();
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.size[0] && (j as usize) < self.size[1])
            .then(|| i as usize + j as usize * self.size[0])
    }

    /// Marks every cell within `r` of `p`.
    fn disc(&mut self, p: [f64; 2], r: f64) {
        let n = (r / self.cell_m).ceil() as isize + 1;
        // The cell nearest `p`, on or off the grid.
        let ci = ((p[0] - self.lo[0]) / self.cell_m).round() as isize;
        let cj = ((p[1] - self.lo[1]) / self.cell_m).round() as isize;
        for di in -n..=n {
            for dj in -n..=n {
                let (i, j) = (ci + di, cj + dj);
                if i < 0 || j < 0 || i as usize >= self.size[0] || j as usize >= self.size[1] {
                    continue;
                }
                let q = [
                    self.lo[0] + i as f64 * self.cell_m,
                    self.lo[1] + j as f64 * self.cell_m,
                ];
                if (q[0] - p[0]).hypot(q[1] - p[1]) <= r {
                    self.hit[i as usize + j as usize * self.size[0]] = true;
                }
            }
        }
    }

    /// Marks the sweep along the straight leg from `a` to `b`.
    fn leg(&mut self, a: [f64; 2], b: [f64; 2], r: f64) {
        let length = (b[0] - a[0]).hypot(b[1] - a[1]);
        let n = (length / (0.5 * self.cell_m)).ceil().max(1.0) as usize;
        for k in 0..=n {
            let f = k as f64 / n as f64;
            self.disc([a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])], r);
        }
    }

    fn covers(&self, p: [f64; 2]) -> bool {
        self.index(p).is_some_and(|k| self.hit[k])
    }
}

/// The share of `area`'s free ground (m², %; the ground connected to the
/// track's start) a robot sweeping `sweep_radius_m` about its centre
/// covered along `track`.
pub fn covered_share(
    planner: &RoutePlanner,
    area: &[[f64; 2]],
    track: &[[f64; 2]],
    sweep_radius_m: f64,
) -> (f64, f64) {
    let cell = planner.settings().cell_m;
    let Some(&start) = track.first() else {
        return (0.0, 0.0);
    };
    let free = free_cells(planner, area, start);
    let mut covered = Covered::new(area, cell);
    for leg in track.windows(2) {
        covered.leg(leg[0], leg[1], sweep_radius_m);
    }
    if track.len() == 1 {
        covered.disc(track[0], sweep_radius_m);
    }
    let hit = free.iter().filter(|&&p| covered.covers(p)).count();
    let free_m2 = free.len() as f64 * cell * cell;
    let percent = if free.is_empty() {
        100.0
    } else {
        100.0 * hit as f64 / free.len() as f64
    };
    (free_m2, percent)
}

/// The waypoints that sweep `area` (a simple polygon) from `start`.
pub fn sweep(
    planner: &RoutePlanner,
    area: &[[f64; 2]],
    start: [f64; 2],
    settings: &SweepSettings,
) -> Result<Sweep, String> {
    crate::plan::check_polygon(area).map_err(|e| format!("the area: {e}"))?;
    let r = settings.sweep_radius_m;
    if !(r.is_finite() && r > 0.0 && (0.0..0.9).contains(&settings.overlap)) {
        return Err(format!(
            "a sweep radius > 0 and an overlap in [0, 0.9) are needed, got {r} m and {}",
            settings.overlap
        ));
    }
    let cell = planner.settings().cell_m;
    let reachable = planner.reachable_from(start);
    // Every place a lane keeps is one a straight leg of the way may pass
    // (sampled as the way's legs are), so lanes are driven straight.
    let ok = |p: [f64; 2]| {
        crate::freedom::inside(area, p)
            && planner.keeps_clearance(p)
            && planner.reaches(&reachable, p)
    };
    // Lanes along the longest edge.
    let n = area.len();
    let (a, b) = (0..n)
        .map(|i| (area[i], area[(i + 1) % n]))
        .max_by(|x, y| {
            let l = |e: &([f64; 2], [f64; 2])| (e.1[0] - e.0[0]).hypot(e.1[1] - e.0[1]);
            l(x).total_cmp(&l(y))
        })
        .expect("a polygon has edges");
    let length = (b[0] - a[0]).hypot(b[1] - a[1]);
    let u = [(b[0] - a[0]) / length, (b[1] - a[1]) / length];
    let v = [-u[1], u[0]];
    let to_world = |s: f64, t: f64| [a[0] + s * u[0] + t * v[0], a[1] + s * u[1] + t * v[1]];
    let (mut s_lo, mut s_hi, mut t_lo, mut t_hi) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in area {
        let d = [p[0] - a[0], p[1] - a[1]];
        let (s, t) = (d[0] * u[0] + d[1] * u[1], d[0] * v[0] + d[1] * v[1]);
        s_lo = s_lo.min(s);
        s_hi = s_hi.max(s);
        t_lo = t_lo.min(t);
        t_hi = t_hi.max(t);
    }
    let spacing = 2.0 * r * (1.0 - settings.overlap);
    let mut waypoints = Vec::new();
    let mut lanes = 0;
    let mut t = t_lo + r.min(0.5 * (t_hi - t_lo));
    let mut forward = true;
    while t <= t_hi + 1e-9 {
        // The lane's runs of places that keep the clearance inside the area.
        let mut runs: Vec<(f64, f64)> = Vec::new();
        let mut s = s_lo;
        let mut open: Option<f64> = None;
        let mut last = s_lo;
        while s <= s_hi + 1e-9 {
            if ok(to_world(s, t)) {
                open.get_or_insert(s);
                last = s;
            } else if let Some(from) = open.take() {
                runs.push((from, last));
            }
            s += 0.25 * cell;
        }
        if let Some(from) = open {
            runs.push((from, last));
        }
        if !forward {
            runs.reverse();
        }
        for (from, to) in runs {
            let (x, y) = if forward { (from, to) } else { (to, from) };
            waypoints.push(to_world(x, t));
            if (to - from).abs() > 1e-9 {
                waypoints.push(to_world(y, t));
            }
            lanes += 1;
        }
        forward = !forward;
        t += spacing;
    }
    // What the way through the lanes covers (around what lies between two
    // runs of a lane, not through it), then touch-ups for the rest,
    // nearest first, each counted for the sweep where it stops.
    let free = free_cells(planner, area, start);
    let mut covered = Covered::new(area, cell);
    let mut from = start;
    if !waypoints.is_empty() {
        let way = planner
            .route(start, &waypoints)
            .map_err(|why| format!("the lanes: {why}"))?;
        for leg in way.points.windows(2) {
            covered.leg(leg[0], leg[1], r);
        }
        from = *waypoints.last().expect("not empty");
    }
    let mut touch_ups = 0;
    let mut left: Vec<[f64; 2]> = free
        .iter()
        .copied()
        .filter(|&p| !covered.covers(p))
        .collect();
    while !left.is_empty() {
        // The uncovered cell nearest the robot's last stop.
        let (k, _) = left
            .iter()
            .enumerate()
            .map(|(k, p)| (k, (p[0] - from[0]).hypot(p[1] - from[1])))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .expect("not empty");
        let target = left.swap_remove(k);
        // The place nearest it the sweep reaches it from.
        let reach = (r / cell).floor() as isize;
        let mut best: Option<([f64; 2], f64)> = None;
        for di in -reach..=reach {
            for dj in -reach..=reach {
                let p = [target[0] + di as f64 * cell, target[1] + dj as f64 * cell];
                let d = (p[0] - target[0]).hypot(p[1] - target[1]);
                if d <= r && ok(p) && best.is_none_or(|(_, bd)| d < bd) {
                    best = Some((p, d));
                }
            }
        }
        if let Some((p, _)) = best {
            covered.disc(p, r);
            waypoints.push(p);
            from = p;
            touch_ups += 1;
            left.retain(|&q| !covered.covers(q));
        }
    }
    let hit = free.iter().filter(|&&p| covered.covers(p)).count();
    let free_m2 = free.len() as f64 * cell * cell;
    if waypoints.is_empty() {
        return Err("no place inside the area keeps the clearance: nothing to sweep".into());
    }
    Ok(Sweep {
        waypoints,
        lanes,
        touch_ups,
        free_m2,
        planned_percent: if free.is_empty() {
            100.0
        } else {
            100.0 * hit as f64 / free.len() as f64
        },
    })
}
