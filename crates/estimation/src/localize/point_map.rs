//! A map of points for scan-to-map matching while the map is being drawn:
//! endpoints averaged per voxel, a k-d tree over them (`kiddo`), and the
//! normal of the line each point's neighbours lie along. A point is
//! measured against the tangent line of its nearest map point.

use std::collections::HashMap;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use super::reference::{Anchor, Moments, Reference};

/// Map points within this of a point shape its tangent line (m).
const NEIGHBOURHOOD_M: f64 = 0.25;
/// See `scan_ref`: a neighbourhood this spread across its line is not a line.
const MAX_FLATNESS: f64 = 0.15;

/// Points in a frame of their own (the map's), voxel-averaged.
pub struct PointMap {
    voxel_m: f64,
    reach_m: f64,
    /// Sum of the points in each voxel and their number.
    voxels: HashMap<(i32, i32), ([f64; 2], u32)>,
    points: Vec<[f64; 2]>,
    /// How many returns each point averages.
    counts: Vec<u32>,
    anchors: Vec<Anchor>,
    tree: Option<ImmutableKdTree<f64, 2>>,
    /// Points were added since the tree and the normals were built.
    stale: bool,
}

impl std::fmt::Debug for PointMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointMap")
            .field("voxel_m", &self.voxel_m)
            .field("reach_m", &self.reach_m)
            .field("points", &self.points.len())
            .finish()
    }
}

impl PointMap {
    /// An empty map averaging points per `voxel_m` cell and pairing points
    /// at most `reach_m` from a map point.
    pub fn new(voxel_m: f64, reach_m: f64) -> Self {
        Self {
            voxel_m: voxel_m.max(1e-4),
            reach_m,
            voxels: HashMap::new(),
            points: Vec::new(),
            counts: Vec::new(),
            anchors: Vec::new(),
            tree: None,
            stale: false,
        }
    }

    /// Frees what only adding points needs (the voxels' sums), for a map
    /// that is done growing; [`PointMap::extend`] recovers them.
    pub fn compact(&mut self) {
        self.refresh();
        self.voxels = HashMap::new();
        self.points.shrink_to_fit();
        self.counts.shrink_to_fit();
        self.anchors.shrink_to_fit();
    }

    /// Adds `points` (map frame) and rebuilds the tree and the normals.
    pub fn extend(&mut self, points: impl IntoIterator<Item = [f64; 2]>) {
        self.add(points);
        self.refresh();
    }

    /// Adds `points` (map frame) without rebuilding: the map answers as
    /// before until [`refresh`](Self::refresh) (for a map that takes many
    /// additions between queries).
    pub fn add(&mut self, points: impl IntoIterator<Item = [f64; 2]>) {
        if self.voxels.is_empty() {
            // Compacted: each point is its voxel's mean of `count` returns.
            for (p, n) in self.points.iter().zip(&self.counts) {
                let key = (
                    (p[0] / self.voxel_m).floor() as i32,
                    (p[1] / self.voxel_m).floor() as i32,
                );
                let k = f64::from(*n);
                self.voxels.insert(key, ([p[0] * k, p[1] * k], *n));
            }
        }
        for p in points {
            if !(p[0].is_finite() && p[1].is_finite()) {
                continue;
            }
            let key = (
                (p[0] / self.voxel_m).floor() as i32,
                (p[1] / self.voxel_m).floor() as i32,
            );
            let v = self.voxels.entry(key).or_insert(([0.0, 0.0], 0));
            v.0[0] += p[0];
            v.0[1] += p[1];
            v.1 += 1;
        }
        self.stale = true;
    }

    /// Rebuilds the tree and the normals if points were added since.
    pub fn refresh(&mut self) {
        if self.stale {
            self.rebuild();
        }
    }

    fn rebuild(&mut self) {
        self.stale = false;
        // Voxels in a fixed order, so the same points give the same map.
        let mut keys: Vec<&(i32, i32)> = self.voxels.keys().collect();
        keys.sort_unstable();
        self.counts = keys.iter().map(|k| self.voxels[*k].1).collect();
        self.points = keys
            .into_iter()
            .map(|k| {
                let (sum, n) = self.voxels[k];
                [sum[0] / f64::from(n), sum[1] / f64::from(n)]
            })
            .collect();
        self.tree = ImmutableKdTree::new_from_slice(&self.points).ok();
        let Some(tree) = &self.tree else {
            self.anchors.clear();
            return;
        };
        // Each point's neighbourhood summed as it is visited (no result
        // list, no sort): the reading first, then its neighbours.
        self.anchors = self
            .points
            .iter()
            .map(|p| {
                let mut m = Moments::default();
                m.add(*p);
                tree.query(p)
                    .within::<SquaredEuclidean<f64>>(NEIGHBOURHOOD_M * NEIGHBOURHOOD_M)
                    .unsorted()
                    .visit(|hit| {
                        let q = self.points[hit.item as usize];
                        if q != *p {
                            m.add(q);
                        }
                    });
                Anchor::from_moments(&m, *p, MAX_FLATNESS)
            })
            .collect();
    }

    /// The map's points (voxel averages), in a fixed order.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// The distance from (x, y) to the nearest map point, if one is within
    /// the map's reach.
    pub fn distance_to_nearest(&self, x: f64, y: f64) -> Option<f64> {
        let tree = self.tree.as_ref()?;
        let hit = tree
            .query(&[x, y])
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        (!hit.distance.is_nan() && hit.distance <= self.reach_m * self.reach_m)
            .then(|| hit.distance.sqrt())
    }

    /// The map point nearest (x, y) within the map's reach: its index, its
    /// anchor (the line its neighbours lie along, if they do) and how many
    /// returns it averages.
    pub fn nearest(&self, x: f64, y: f64) -> Option<(usize, Anchor, u32)> {
        let tree = self.tree.as_ref()?;
        let hit = tree
            .query(&[x, y])
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        if hit.distance.is_nan() || hit.distance > self.reach_m * self.reach_m {
            return None;
        }
        let i = hit.item as usize;
        Some((i, self.anchors[i], self.counts[i]))
    }

    /// Calls `visit(index)` for every map point within `radius_m` of (x, y).
    pub fn within(&self, x: f64, y: f64, radius_m: f64, mut visit: impl FnMut(usize)) {
        if let Some(tree) = &self.tree {
            tree.query(&[x, y])
                .within::<SquaredEuclidean<f64>>(radius_m * radius_m)
                .unsorted()
                .visit(|hit| visit(hit.item as usize));
        }
    }

    /// How many returns each point averages, in the order of [`points`](Self::points).
    pub fn counts(&self) -> &[u32] {
        &self.counts
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

impl Reference for PointMap {
    type Feature = Anchor;

    #[inline]
    fn measure(&self, feature: &Anchor, x: f64, y: f64) -> (f64, [f64; 2]) {
        feature.residual([x, y])
    }

    #[inline]
    fn associate(&self, x: f64, y: f64) -> Option<Anchor> {
        self.nearest(x, y).map(|(_, a, _)| a)
    }
}

#[cfg(test)]
mod tests {
    use rand::RngExt;

    use super::super::testkit::{Lidar, compose, free_pose, rng, room, scan};
    use super::super::{MatchSettings, register};
    use super::*;

    #[test]
    fn the_nearest_point_is_the_brute_force_one() {
        let mut rng = rng(1);
        let mut map = PointMap::new(0.025, 10.0);
        map.extend((0..2_000).map(|_| [rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0)]));
        for _ in 0..500 {
            let q = [rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0)];
            let brute = map
                .points()
                .iter()
                .map(|p| (q[0] - p[0]).hypot(q[1] - p[1]))
                .fold(f64::INFINITY, f64::min);
            let tree = map.tree.as_ref().unwrap();
            let hit = tree
                .query(&q)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            assert!((hit.distance.sqrt() - brute).abs() < 1e-12);
        }
    }

    #[test]
    fn scans_match_a_map_drawn_from_other_scans() {
        // A map of the endpoints of four scans from known poses; a scan
        // from a fifth pose is matched to it from a prior 5 cm and 3
        // degrees off.
        let mut rng = rng(77);
        let lidar = Lidar {
            beams: 360,
            noise_std_m: 0.02,
            dropout: 0.02,
            max_range_m: 8.0,
        };
        let mut worst = [0.0f64; 2];
        for _ in 0..12 {
            let walls = room(&mut rng);
            let mut map = PointMap::new(0.025, 0.4);
            for _ in 0..4 {
                let pose = free_pose(&walls, 0.5, &mut rng);
                let s = scan(&walls, pose, lidar, &mut rng);
                map.extend(s.points().into_iter().map(|p| {
                    let w = compose(pose, [p[0], p[1], 0.0]);
                    [w[0], w[1]]
                }));
            }
            let truth = free_pose(&walls, 0.5, &mut rng);
            let points = scan(&walls, truth, lidar, &mut rng).points();
            let prior = compose(truth, [0.04, -0.03, 0.05]);
            let m = register(&map, &points, prior, &MatchSettings::scan_to_scan())
                .expect("a match against the map");
            let e = (m.pose[0] - truth[0]).hypot(m.pose[1] - truth[1]);
            let eh = twindrive_kinematics::wrap_angle(m.pose[2] - truth[2]).abs();
            worst = [worst[0].max(e), worst[1].max(eh)];
        }
        assert!(
            worst[0] < 0.01 && worst[1] < 0.3f64.to_radians(),
            "worst {worst:?}"
        );
    }

    #[test]
    fn an_empty_map_pairs_nothing_and_the_same_points_give_the_same_map() {
        let map = PointMap::new(0.025, 0.4);
        assert!(map.residual(0.0, 0.0).is_none());
        let pts = [[1.0, 2.0], [1.01, 2.0], [3.0, -1.0], [f64::NAN, 0.0]];
        let mut a = PointMap::new(0.025, 0.4);
        a.extend(pts);
        let mut b = PointMap::new(0.025, 0.4);
        b.extend(pts.into_iter().rev());
        assert_eq!(a.points(), b.points());
        assert_eq!(a.len(), 2, "two voxels; the NaN is dropped");
    }
}
