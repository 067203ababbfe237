//! The global search: loop closures after more drift than the loop
//! window allows.
//!
//! A drive that explores for a kilometre before it comes back to where it
//! started returns metres off (the Freiburg hospital's 12 m after a
//! kilometre), beyond the loop search's window. Every `global_every`-th
//! node is therefore also searched for in the finished submaps that the
//! drift since the graph last tied them to it could have put it in: the
//! window around the estimate grows with the length of the shortest path
//! between the node and the submap through the graph (local matching's
//! edges count their length, odometry's more, loop closures nothing), up
//! to `global_max_m`; its headings grow with that path too
//! (`global_drift_rad_per_m`: the hospital comes back 20° off when local
//! matching drifts a little more). A wide window finds a corridor that
//! merely looks alike, so a match is only a candidate: two candidates from different
//! nodes that move the drive's recent stretch the same way (within
//! `global_agree_m` and `global_agree_rad`) become loop closures, and the
//! graph is solved at once with them as least-squares edges (a correction
//! of metres is far beyond a Huber loss's quadratic part) before their
//! Huber losses return.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::localize::register;

use super::builder::{Candidate, Slam};
use super::correlative::SearchWindow;
use super::pose_graph::Edge;
use super::se2::{between, compose, inverse, wrap};

impl Slam {
    /// Searches node `k` in the finished submaps beyond the loop window
    /// that the drift since the graph last joined them could reach.
    pub(super) fn search_globally(&mut self, k: usize) {
        let s = self.settings;
        let global = self.graph.poses[k];
        let along = self.path_lengths(k);
        // (window, distance, submap) of the submaps worth searching.
        let mut wanted: Vec<(SearchWindow, f64, usize)> = self
            .searchable(k)
            .filter_map(|(i, m)| {
                let nearest = self.nearest_node_m(m, global);
                let path = m
                    .nodes
                    .iter()
                    .map(|&n| along[n])
                    .fold(f64::INFINITY, f64::min);
                let window = SearchWindow {
                    linear_m: (s.loop_window.linear_m + s.global_drift_m_per_m * path)
                        .min(s.global_max_m),
                    angular_rad: (s.loop_window.angular_rad + s.global_drift_rad_per_m * path)
                        .min(std::f64::consts::PI),
                    min_score: s.global_min_score,
                };
                (nearest > s.loop_window.linear_m && nearest <= window.linear_m)
                    .then_some((window, nearest, i))
            })
            .collect();
        // The least recently searched first, so that a drive that stays
        // in reach of many submaps tries each in turn.
        wanted.sort_by(|a, b| {
            let last = |m: usize| self.submaps[m].searched_at.map_or(-1, |n| n as i64);
            last(a.2).cmp(&last(b.2)).then(a.1.total_cmp(&b.1))
        });
        wanted.truncate(s.global_max_submaps);
        for (window, _, m) in wanted {
            self.submaps[m].searched_at = Some(k);
            self.stats.global_searches += 1;
            let Some(measured) = self.match_in_submap(k, m, window) else {
                continue;
            };
            self.consider(Candidate {
                node: k,
                submap: m,
                measured,
            });
        }
    }

    /// Keeps `c` until a candidate from another node agrees with it; then
    /// both become loop closures and the graph is solved.
    fn consider(&mut self, c: Candidate) {
        let s = self.settings;
        let before = self.pending.len();
        self.pending
            .retain(|p| p.node + s.global_pending_nodes >= c.node);
        self.stats.global_unconfirmed += before - self.pending.len();
        let implied = |p: &Candidate| {
            let anchor = self.graph.poses[self.submaps[p.submap].anchor];
            // Where the match puts the current estimate's frame.
            compose(
                compose(anchor, p.measured),
                inverse(self.graph.poses[p.node]),
            )
        };
        let here = self.graph.poses[c.node];
        let moved = compose(implied(&c), here);
        let agreeing = self.pending.iter().position(|p| {
            if p.node == c.node {
                return false;
            }
            let other = compose(implied(p), here);
            (other[0] - moved[0]).hypot(other[1] - moved[1]) <= s.global_agree_m
                && wrap(other[2] - moved[2]).abs() <= s.global_agree_rad
        });
        let Some(at) = agreeing else {
            self.pending.push(c);
            return;
        };
        let first = self.pending.remove(at);
        self.stats.global_unconfirmed += self.pending.len();
        self.pending.clear();
        for p in [first, c] {
            let edge = self.graph.add_edge(Edge {
                from: self.submaps[p.submap].anchor,
                to: p.node,
                measured: p.measured,
                std: s.loop_std,
                huber: Some(s.loop_huber),
                active: true,
            });
            self.fresh_global.push(edge);
            self.submaps[p.submap].closed_at = Some(p.node);
            self.stats.loop_closures += 1;
            self.stats.global_closures += 1;
        }
        self.solve(s.solve_iterations);
    }

    /// The branch-and-bound search for node `k` in finished submap `m`
    /// within `window` of the estimate, confirmed by PL-ICP: the node's
    /// robot pose in the submap's frame.
    pub(super) fn match_in_submap(
        &mut self,
        k: usize,
        m: usize,
        window: SearchWindow,
    ) -> Option<[f64; 3]> {
        let s = self.settings;
        self.cache_loop_grid(m);
        let grid = &self.grids.last().expect("just cached").1;
        let submap = &self.submaps[m];
        let frame = self.graph.poses[submap.anchor];
        let guess = between(frame, compose(self.graph.poses[k], self.mount));
        let points = &self.nodes[k].points;
        let found = grid.search(points, guess, window)?;
        let refined = register(&submap.points, points, found.pose, &s.loop_matching).ok()?;
        if (refined.pose[0] - found.pose[0]).hypot(refined.pose[1] - found.pose[1])
            > 2.0 * s.grid_resolution_m
        {
            return None;
        }
        Some(compose(refined.pose, inverse(self.mount)))
    }

    /// The length of the shortest path from node `k` to every node through
    /// the graph: an edge measured by local matching counts the distance
    /// it spans, one by odometry alone (the scan did not match) that many
    /// times more as its drift exceeds local matching's, a loop closure
    /// nothing (the drift between two poses grows with the first, not the
    /// second).
    fn path_lengths(&self, k: usize) -> Vec<f64> {
        let n = self.graph.poses.len();
        let mut next: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        let s = self.settings;
        for e in self.graph.edges.iter().filter(|e| e.active) {
            let length = match e.huber {
                Some(_) => 0.0,
                None if e.std == s.odometry_std => {
                    e.measured[0].hypot(e.measured[1]) * s.global_blind_drift_m_per_m
                        / s.global_drift_m_per_m
                }
                None => e.measured[0].hypot(e.measured[1]),
            };
            next[e.from].push((e.to, length));
            next[e.to].push((e.from, length));
        }
        let mut along = vec![f64::INFINITY; n];
        let mut heap = BinaryHeap::new();
        along[k] = 0.0;
        // Lengths are non-negative: their bits order as the numbers do.
        heap.push(Reverse((0.0f64.to_bits(), k)));
        while let Some(Reverse((bits, i))) = heap.pop() {
            let d = f64::from_bits(bits);
            if d > along[i] {
                continue;
            }
            for &(j, length) in &next[i] {
                let via = d + length;
                if via < along[j] {
                    along[j] = via;
                    heap.push(Reverse((via.to_bits(), j)));
                }
            }
        }
        along
    }
}
