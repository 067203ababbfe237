//! The SLAM itself, one scan at a time.
//!
//! Local: each scan is matched (PL-ICP, [`register`]) against the older of
//! two active submaps twice, from the pose the odometry predicts since the
//! last scan and from the best pose of a correlative search around it
//! (on the submap's likelihood field, grown node by node); of the two and
//! the prediction itself, the likeliest given the odometry's noise as this
//! drive has measured it ([`MeasuredNoise`]) is kept (a corridor's
//! repeating doors, a person walking ahead of the robot, make a second
//! valley the search may prefer by a few returns; along a bare corridor
//! PL-ICP slides). A scan that moved far enough since the
//! last node becomes a node:
//! a pose of the graph, joined to the previous node and to its submap's
//! first node by what the local matching measured, and its points are
//! inserted into both active submaps. A submap is finished after
//! `submap_nodes` insertions, and a new one starts every half of that.
//!
//! Global: every `loop_every`-th node is searched for, by branch and bound
//! ([`LikelihoodGrid::search`]), in every finished submap that the
//! trajectory estimate puts near it and that local matching does not
//! already join it to; a match scoring at least `min_score` and confirmed by
//! PL-ICP is a loop closure, an edge with a Huber loss. The graph is solved
//! every `optimize_every` nodes once there is a new closure, and closures
//! whose residual stays far beyond their noise after a solve are switched
//! off and the graph solved again (false loops, such as a corridor's
//! repeating doors).

use crate::localize::{PointMap, register};

use super::SlamSettings;
use super::correlative::{LikelihoodGrid, SearchWindow};
use super::odometry::MeasuredNoise;
use super::pose_graph::{Edge, PoseGraph};
use super::se2::{apply, between, compose, inverse, wrap};

/// One node: a scan that became a pose of the graph.
#[derive(Debug)]
pub(super) struct Node {
    /// The robot's pose in the local frame.
    local: [f64; 3],
    /// The scan's points (sensor frame), thinned for the loop search.
    pub(super) points: Vec<[f64; 2]>,
}

/// A submap: the points of the nodes inserted into it, in the frame of
/// its first node's robot pose (the anchor).
#[derive(Debug)]
pub(super) struct Submap {
    /// The node whose robot pose is the submap's frame.
    pub(super) anchor: usize,
    pub(super) points: PointMap,
    /// The nodes inserted.
    pub(super) nodes: Vec<usize>,
    /// Once the submap is finished: the part of it the loop search's grid
    /// covers (submap frame), what a node's points can reach from where
    /// the submap's nodes were.
    pub(super) reach: Option<([f64; 2], [f64; 2])>,
    /// The last node a loop closure joined to it.
    pub(super) closed_at: Option<usize>,
    /// The last node the global search looked for in it.
    pub(super) searched_at: Option<usize>,
    /// For local matching while it is active: the likelihood field of
    /// the returns of the nodes inserted, grown as they are (dropped when
    /// the submap is finished).
    local_grid: Option<LikelihoodGrid>,
}

/// A match of the global search ([`Slam::search_globally`]) waiting for
/// a second that agrees with it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Candidate {
    pub(super) node: usize,
    pub(super) submap: usize,
    /// The node's robot pose in the submap's frame.
    pub(super) measured: [f64; 3],
}

/// What happened to one scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanOutcome {
    /// Whether local matching placed it: at the likeliest of its matches
    /// and the odometry's prediction (else at the prediction, unjudged).
    pub matched: bool,
    /// The match's RMS residual (m), when placed at a match.
    pub rms_m: Option<f64>,
}

/// Counts for the report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct SlamStats {
    pub nodes: usize,
    pub submaps: usize,
    pub loop_searches: usize,
    pub loop_closures: usize,
    /// Searches by the global search, and the closures it found (counted
    /// in `loop_closures` too).
    pub global_searches: usize,
    pub global_closures: usize,
    /// Closures switched off after a solve (false loops).
    pub loops_rejected: usize,
    /// Matches of the global search that no second match confirmed (a
    /// loop the search saw but was not sure of, and did not take).
    pub global_unconfirmed: usize,
    pub solves: usize,
}

/// The SLAM state: feed scans in time order with [`Slam::add`], then
/// [`Slam::finish`].
#[derive(Debug)]
pub struct Slam {
    pub(super) settings: SlamSettings,
    /// The lidar's pose on the robot.
    pub(super) mount: [f64; 3],
    pub(super) graph: PoseGraph,
    pub(super) nodes: Vec<Node>,
    pub(super) submaps: Vec<Submap>,
    /// Indices of the active submaps (at most two, oldest first).
    active: Vec<usize>,
    /// The last scan's odometry and local poses.
    last: Option<([f64; 3], [f64; 3])>,
    /// The last node's local pose and time.
    last_node: Option<([f64; 3], f64)>,
    /// Each scan: the node it is, or the node before it and its pose seen
    /// from that node.
    scans: Vec<(usize, [f64; 3])>,
    /// The loop search's grids of the finished submaps searched last,
    /// most recent last: a building's worth of them would not fit in
    /// memory (a grid of 7 levels a submap), and a drive searches the few
    /// submaps around it again and again.
    pub(super) grids: Vec<(usize, LikelihoodGrid)>,
    /// Loop edges since the last solve.
    pub(super) fresh_loops: usize,
    /// The global search's matches waiting for one that agrees, and the
    /// closures it made since the last solve (edge indices).
    pub(super) pending: Vec<Candidate>,
    pub(super) fresh_global: Vec<usize>,
    nodes_since_solve: usize,
    pub(super) stats: SlamStats,
    /// The odometry's errors on this drive: each scan's best correlative
    /// match less the odometry's prediction.
    odometry_errors: MeasuredNoise,
}

impl Slam {
    pub fn new(mount: [f64; 3], settings: SlamSettings) -> Self {
        Self {
            settings,
            mount,
            graph: PoseGraph::default(),
            nodes: Vec::new(),
            submaps: Vec::new(),
            active: Vec::new(),
            last: None,
            last_node: None,
            scans: Vec::new(),
            grids: Vec::new(),
            fresh_loops: 0,
            pending: Vec::new(),
            fresh_global: Vec::new(),
            nodes_since_solve: 0,
            stats: SlamStats::default(),
            odometry_errors: MeasuredNoise::new(settings.odometry_window),
        }
    }

    /// The next scan (sensor-frame points, already thinned and cut to
    /// range) taken at `t_s`, with the robot's odometry pose then.
    pub fn add(&mut self, t_s: f64, odometry: [f64; 3], points: &[[f64; 2]]) -> ScanOutcome {
        let s = self.settings;
        let predicted = match self.last {
            None => odometry,
            Some((o, l)) => compose(l, between(o, odometry)),
        };
        // Local matching against the older active submap.
        let mut outcome = ScanOutcome {
            matched: false,
            rms_m: None,
        };
        let mut local = predicted;
        if let Some(&m) = self.active.first() {
            let frame = self.nodes[self.submaps[m].anchor].local;
            let prior = between(frame, compose(predicted, self.mount));
            let submap = &mut self.submaps[m];
            // Only the submap matched against is kept built.
            submap.points.refresh();
            // A correlative search around the odometry's prediction first
            // (the odometry's heading can be tens of degrees off in a fast
            // turn, where PL-ICP alone settles in the wrong valley), then
            // PL-ICP from the best of it.
            // Odometry that froze and then jumps (a dropped message, a
            // late one) predicts a step it may have half taken already:
            // the search widens by the step the odometry claims.
            let (step_m, step_rad) = match self.last {
                None => (0.0, 0.0),
                Some((o, _)) => {
                    let d = between(o, odometry);
                    (d[0].hypot(d[1]), d[2].abs())
                }
            };
            let window = SearchWindow {
                linear_m: s.local_window.linear_m + step_m,
                angular_rad: s.local_window.angular_rad + step_rad,
                ..s.local_window
            };
            // The search's angular step is set by its farthest point: the
            // near ones give the prior, PL-ICP refines on all.
            // (The points are already cut at `max_range_m`: no copy when
            // the search reaches that far.)
            // At most `local_search_points` of them, evenly through the
            // scan: the search only starts PL-ICP, which uses every point.
            let near: Vec<[f64; 2]>;
            let in_range = points
                .iter()
                .filter(|p| p[0].hypot(p[1]) <= s.local_search_range_m)
                .count();
            let searched = if in_range == points.len() && in_range <= s.local_search_points {
                points
            } else {
                let stride = in_range.div_ceil(s.local_search_points.max(1)).max(1);
                near = points
                    .iter()
                    .filter(|p| p[0].hypot(p[1]) <= s.local_search_range_m)
                    .step_by(stride)
                    .copied()
                    .collect();
                &near
            };
            let start = submap
                .local_grid
                .as_ref()
                .and_then(|g| g.search(searched, prior, window))
                .map_or(prior, |f| f.pose);
            let from_prior = register(&submap.points, points, prior, &s.matching).ok();
            let from_search = if start == prior {
                None
            } else {
                register(&submap.points, points, start, &s.matching).ok()
            };
            // The odometry's noise for this step, scaled by its errors
            // measured before this scan.
            let model = s.odometry_noise.std(step_m, step_rad);
            let scale = self.odometry_errors.scale();
            let odometry_information = [
                (model[0] * scale[0]).powi(-2),
                (model[0] * scale[0]).powi(-2),
                (model[1] * scale[1]).powi(-2),
            ];
            if let Some(q) = from_search.as_ref().or(from_prior.as_ref()) {
                self.odometry_errors.record(
                    (q.pose[0] - prior[0]).hypot(q.pose[1] - prior[1]),
                    wrap(q.pose[2] - prior[2]),
                    model,
                );
            }
            // Of the two matches, the likelier given the odometry: a
            // corridor's repeating doors or a person walking ahead make a
            // second valley the search may prefer by a few returns.
            let likelihood = |pose: [f64; 3]| {
                negative_log_likelihood(
                    &submap.points,
                    points,
                    prior,
                    pose,
                    odometry_information,
                    &s,
                )
            };
            let chosen = match (from_prior, from_search) {
                (Some(p), Some(q)) => Some(if likelihood(q.pose) < likelihood(p.pose) {
                    q
                } else {
                    p
                }),
                (p, q) => p.or(q),
            };
            // The prediction itself competes too, once the odometry's
            // noise is measured: along a corridor PL-ICP can slide a
            // decimetre or more from it (from the prediction and from the
            // search alike) where the scan barely prefers the slide, and
            // of two slides the lesser is still one.
            // Only where the two conflict (the match beyond
            // `odometry_conflict_sigmas` of the prediction): within that,
            // the scan refines the odometry, and keeping the prediction
            // there lets a slight bias of the odometry (a wheel 0.5 % large)
            // bend the drive unchecked.
            let trusted = scale.iter().all(|v| v.is_finite());
            let placed = chosen.map(|m| {
                let sigmas = ((m.pose[0] - prior[0]).hypot(m.pose[1] - prior[1])
                    / (model[0] * scale[0]))
                    .max(wrap(m.pose[2] - prior[2]).abs() / (model[1] * scale[1]));
                if trusted
                    && sigmas > s.odometry_conflict_sigmas
                    && likelihood(prior) < likelihood(m.pose)
                {
                    (prior, None)
                } else {
                    (m.pose, Some(m.rms_m))
                }
            });
            if let Some((pose, rms_m)) = placed {
                let moved = (pose[0] - prior[0]).hypot(pose[1] - prior[1]);
                let turned = wrap(pose[2] - prior[2]).abs();
                if moved <= s.max_correction_m + step_m && turned <= s.max_correction_rad + step_rad
                {
                    local = compose(compose(frame, pose), inverse(self.mount));
                    outcome = ScanOutcome {
                        matched: true,
                        rms_m,
                    };
                }
            }
        }
        self.last = Some((odometry, local));
        let node = match self.last_node {
            None => true,
            Some((n, t)) => {
                (local[0] - n[0]).hypot(local[1] - n[1]) >= s.node_m
                    || wrap(local[2] - n[2]).abs() >= s.node_rad
                    || t_s - t >= s.node_s
            }
        };
        if node {
            let k = self.add_node(local, points, outcome.matched);
            self.last_node = Some((local, t_s));
            self.scans.push((k, [0.0; 3]));
        } else {
            let k = self.nodes.len() - 1;
            self.scans.push((k, between(self.nodes[k].local, local)));
        }
        outcome
    }

    fn add_node(&mut self, local: [f64; 3], points: &[[f64; 2]], matched: bool) -> usize {
        let s = self.settings;
        let k = self.nodes.len();
        let global = match k {
            0 => local,
            _ => compose(
                self.graph.poses[k - 1],
                between(self.nodes[k - 1].local, local),
            ),
        };
        self.graph.add_pose(global);
        let thinned: Vec<[f64; 2]> = {
            let stride = points.len().div_ceil(s.loop_points.max(1)).max(1);
            points
                .iter()
                .filter(|p| p[0].hypot(p[1]) <= s.loop_range_m)
                .step_by(stride)
                .copied()
                .collect()
        };
        self.nodes.push(Node {
            local,
            points: thinned,
        });
        if k > 0 {
            let std = if matched { s.local_std } else { s.odometry_std };
            self.graph.add_edge(Edge {
                from: k - 1,
                to: k,
                measured: between(self.nodes[k - 1].local, local),
                std,
                huber: None,
                active: true,
            });
        }
        // A new submap every half submap.
        let start_new = match self.active.last() {
            None => true,
            Some(&m) => self.submaps[m].nodes.len() >= s.submap_nodes / 2,
        };
        if start_new {
            self.submaps.push(Submap {
                anchor: k,
                points: PointMap::new(s.voxel_m, s.matching.outlier_m),
                nodes: Vec::new(),
                reach: None,
                closed_at: None,
                searched_at: None,
                local_grid: Some(LikelihoodGrid::new(
                    &[],
                    s.grid_resolution_m,
                    s.grid_sigma_m,
                    s.local_levels,
                )),
            });
            self.active.push(self.submaps.len() - 1);
            self.stats.submaps += 1;
        }
        let sensor = compose(local, self.mount);
        for &m in &self.active {
            let frame = self.nodes[self.submaps[m].anchor].local;
            let in_submap = between(frame, sensor);
            let submap = &mut self.submaps[m];
            // The likelihood field grows now; the point map is built when
            // next matched against (the newer submap only once the older
            // is finished) or when finished (`compact`).
            let seen: Vec<[f64; 2]> = points.iter().map(|p| apply(in_submap, *p)).collect();
            if let Some(grid) = &mut submap.local_grid {
                grid.insert(&seen);
            }
            submap.points.add(seen);
            submap.nodes.push(k);
        }
        // The oldest is finished once full.
        if let Some(&m) = self.active.first()
            && self.submaps[m].nodes.len() >= s.submap_nodes
        {
            self.active.remove(0);
            // The loop search's grid covers what a node's points (within
            // `loop_range_m`) can reach from where the submap's nodes were.
            let frame = self.nodes[self.submaps[m].anchor].local;
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for &n in &self.submaps[m].nodes {
                let p = between(frame, self.nodes[n].local);
                for c in 0..2 {
                    lo[c] = lo[c].min(p[c] - s.loop_range_m);
                    hi[c] = hi[c].max(p[c] + s.loop_range_m);
                }
            }
            let submap = &mut self.submaps[m];
            submap.local_grid = None;
            submap.reach = Some((lo, hi));
            submap.points.compact();
        }
        self.stats.nodes += 1;
        self.nodes_since_solve += 1;
        if k.is_multiple_of(s.loop_every.max(1)) {
            self.close_loops(k);
        }
        if k.is_multiple_of(s.global_every.max(1)) {
            self.search_globally(k);
        }
        if self.fresh_loops > 0 && self.nodes_since_solve >= s.optimize_every {
            self.solve(s.solve_iterations);
        }
        k
    }

    /// The finished submaps node `k` may be searched for in: started
    /// `loop_min_separation` nodes before it, and not closed to a node a
    /// few nodes back (that one ties them already: a drive that circles
    /// one room would otherwise search every submap at every chance).
    pub(super) fn searchable(&self, k: usize) -> impl Iterator<Item = (usize, &Submap)> {
        let s = self.settings;
        self.submaps
            .iter()
            .enumerate()
            .filter(move |(_, m)| m.reach.is_some() && m.anchor + s.loop_min_separation <= k)
            .filter(move |(_, m)| m.closed_at.is_none_or(|c| c + s.loop_rest_nodes <= k))
    }

    /// How far `at` is from the nearest of submap `m`'s nodes, by the
    /// current estimate (m).
    pub(super) fn nearest_node_m(&self, m: &Submap, at: [f64; 3]) -> f64 {
        m.nodes
            .iter()
            .map(|&n| {
                let p = self.graph.poses[n];
                (p[0] - at[0]).hypot(p[1] - at[1])
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Searches node `k` in every finished submap near it that local
    /// matching does not already join it to.
    fn close_loops(&mut self, k: usize) {
        let s = self.settings;
        let global = self.graph.poses[k];
        let window = s.loop_window;
        // The finished submaps near the node, nearest first (by their
        // nearest node), at most `loop_max_submaps` of them.
        let mut near: Vec<(f64, usize)> = self
            .searchable(k)
            .filter_map(|(i, m)| {
                let d = self.nearest_node_m(m, global);
                (d <= window.linear_m).then_some((d, i))
            })
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        near.truncate(s.loop_max_submaps);
        for (_, m) in near {
            self.stats.loop_searches += 1;
            let Some(measured) = self.match_in_submap(k, m, window) else {
                continue;
            };
            self.graph.add_edge(Edge {
                from: self.submaps[m].anchor,
                to: k,
                measured,
                std: s.loop_std,
                huber: Some(s.loop_huber),
                active: true,
            });
            self.submaps[m].closed_at = Some(k);
            self.stats.loop_closures += 1;
            self.fresh_loops += 1;
        }
    }

    /// Puts the loop search's grid of finished submap `m` last in the
    /// cache: found there, or built from its points (the same grid either
    /// way).
    pub(super) fn cache_loop_grid(&mut self, m: usize) {
        let s = self.settings;
        match self.grids.iter().position(|(i, _)| *i == m) {
            Some(at) => {
                let hit = self.grids.remove(at);
                self.grids.push(hit);
            }
            None => {
                let submap = &self.submaps[m];
                let (lo, hi) = submap.reach.unwrap_or_default();
                let reachable: Vec<[f64; 2]> = submap
                    .points
                    .points()
                    .iter()
                    .filter(|p| (0..2).all(|c| p[c] >= lo[c] && p[c] <= hi[c]))
                    .copied()
                    .collect();
                let grid = LikelihoodGrid::new(
                    &reachable,
                    s.grid_resolution_m,
                    s.grid_sigma_m,
                    s.grid_levels,
                );
                if self.grids.len() >= s.loop_grids_kept.max(1) {
                    self.grids.remove(0);
                }
                self.grids.push((m, grid));
            }
        }
    }

    /// Solves the graph: first with the closures' losses nearly quadratic
    /// (a closure found after metres of drift is far from the estimate
    /// until the graph bends to it) and the global search's new ones
    /// quadratic (already checked against each other, and metres away),
    /// then with their Huber losses; then switches off the closures still
    /// far from the rest (false loops) and solves again.
    pub(super) fn solve(&mut self, iterations: usize) {
        let s = self.settings;
        self.stats.solves += 1;
        self.fresh_loops = 0;
        self.nodes_since_solve = 0;
        let fresh_global = std::mem::take(&mut self.fresh_global);
        for first in [true, false] {
            let huber = if first {
                s.loop_huber * 10.0
            } else {
                s.loop_huber
            };
            for e in self.graph.edges.iter_mut().filter(|e| e.huber.is_some()) {
                e.huber = Some(huber);
            }
            if first {
                for &e in &fresh_global {
                    self.graph.edges[e].huber = None;
                }
            }
            let solved = self.graph.optimize(iterations);
            for &e in &fresh_global {
                self.graph.edges[e].huber = Some(s.loop_huber);
            }
            if solved.is_err() {
                return;
            }
        }
        let mut rejected = 0;
        for e in self.graph.edges.iter_mut() {
            if e.active && e.huber.is_some() && e.chi(&self.graph.poses) > s.loop_reject_chi {
                e.active = false;
                rejected += 1;
            }
        }
        if rejected > 0 {
            self.stats.loops_rejected += rejected;
            let _ = self.graph.optimize(iterations);
        }
    }

    /// Solves the whole graph once more and gives the robot's pose at
    /// every scan added, in the frame of the first.
    pub fn finish(mut self) -> (Vec<[f64; 3]>, SlamStats) {
        self.stats.global_unconfirmed += self.pending.len();
        if self.stats.loop_closures > 0 {
            self.solve(self.settings.final_iterations);
        }
        let poses = self
            .scans
            .iter()
            .map(|&(k, rel)| compose(self.graph.poses[k], rel))
            .collect();
        (poses, self.stats)
    }
}

/// How unlikely a match is given the scan and the odometry's prediction:
/// the scan's robust cost in units of its readings' variance (as many
/// readings' worth as are independent) plus the odometry's Mahalanobis
/// distance (squared, halved, up to `odometry_conflict_sigmas`; linear
/// beyond). Of the local optima and the prediction, the likeliest is kept.
fn negative_log_likelihood(
    map: &PointMap,
    points: &[[f64; 2]],
    prior: [f64; 3],
    pose: [f64; 3],
    odometry: [f64; 3],
    s: &SlamSettings,
) -> f64 {
    let m = &s.matching;
    let scan = crate::localize::cost(map, points, pose, m) / m.point_std_m.powi(2)
        * (m.independent_points / points.len().max(1) as f64).min(1.0);
    let d = [
        pose[0] - prior[0],
        pose[1] - prior[1],
        wrap(pose[2] - prior[2]),
    ];
    // Huber beyond the conflict threshold: real odometry's errors are
    // heavy-tailed (a wheel slips), so a match far from the prediction
    // pays linearly, not quadratically, for the distance.
    let squared = (0..3).map(|i| d[i] * d[i] * odometry[i]).sum::<f64>();
    let (distance, k) = (squared.sqrt(), s.odometry_conflict_sigmas);
    scan + if distance <= k {
        0.5 * squared
    } else {
        k * distance - 0.5 * k * k
    }
}
