//! The static 2D world: wall segments (from segments, polylines, solid
//! rectangles or an occupancy map) with parry2d geometry queries.

use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;
use parry2d_f64::partitioning::{Bvh, BvhBuildStrategy};
use parry2d_f64::query::{PointQuery, Ray, RayCast};
use parry2d_f64::shape::Segment;

use crate::map::OccupancyGrid;

/// Worlds with more segments than this get a bounding-volume hierarchy; below
/// it a linear scan is faster.
const BVH_THRESHOLD: usize = 48;

/// Walls and solids. Walls are two-sided zero-thickness segments.
#[derive(Clone)]
pub struct World {
    segments: Vec<Segment>,
    /// Box around all segments.
    extent: Aabb,
    solids: Vec<Aabb>,
    grid: Option<OccupancyGrid>,
    bvh: Option<Bvh>,
}

/// The nearest wall point to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nearest {
    pub distance_m: f64,
    pub point: Vector,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("segments", &self.segments.len())
            .field("solids", &self.solids.len())
            .field("grid", &self.grid.as_ref().map(|g| (g.width, g.height)))
            .finish()
    }
}

impl World {
    /// Builds a world from wall segments, solid blocks (whose outlines must
    /// already be among the segments) and an optional occupancy grid.
    pub fn new(segments: Vec<Segment>, solids: Vec<Aabb>, grid: Option<OccupancyGrid>) -> Self {
        let bvh = (segments.len() > BVH_THRESHOLD).then(|| {
            let leaves: Vec<Aabb> = segments.iter().map(|s| s.local_aabb()).collect();
            Bvh::from_leaves(BvhBuildStrategy::Binned, &leaves)
        });
        let extent = if segments.is_empty() {
            Aabb::new_invalid()
        } else {
            Aabb::from_points(segments.iter().flat_map(|s| [s.a, s.b]))
        };
        Self {
            segments,
            extent,
            solids,
            grid,
            bvh,
        }
    }

    /// A world of walls `[x0, y0, x1, y1]` and solid blocks
    /// `[min_x, min_y, max_x, max_y]` (whose outlines are among the walls),
    /// as [`World::walls`] and [`World::blocks`] give them back.
    pub fn from_walls(walls: &[[f64; 4]], blocks: &[[f64; 4]]) -> Self {
        let segments = walls
            .iter()
            .map(|w| Segment::new(Vector::new(w[0], w[1]), Vector::new(w[2], w[3])))
            .collect();
        let solids = blocks
            .iter()
            .map(|b| Aabb::new(Vector::new(b[0], b[1]), Vector::new(b[2], b[3])))
            .collect();
        Self::new(segments, solids, None)
    }

    /// The walls as `[x0, y0, x1, y1]`, in order.
    pub fn walls(&self) -> Vec<[f64; 4]> {
        self.segments
            .iter()
            .map(|s| [s.a.x, s.a.y, s.b.x, s.b.y])
            .collect()
    }

    /// The solid blocks as `[min_x, min_y, max_x, max_y]`, in order.
    pub fn blocks(&self) -> Vec<[f64; 4]> {
        self.solids
            .iter()
            .map(|a| [a.mins.x, a.mins.y, a.maxs.x, a.maxs.y])
            .collect()
    }

    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Solid blocks.
    pub fn solids(&self) -> &[Aabb] {
        &self.solids
    }

    /// This world with solid axis-aligned blocks added (what a robot found
    /// that the map lacked).
    pub fn with_blocks(&self, blocks: &[([f64; 2], [f64; 2])]) -> World {
        let mut segments = self.segments.clone();
        let mut solids = self.solids.clone();
        for &(min, max) in blocks {
            segments.extend(rectangle_segments(min, max));
            solids.push(Aabb::new(
                Vector::new(min[0], min[1]),
                Vector::new(max[0], max[1]),
            ));
        }
        World::new(segments, solids, self.grid.clone())
    }

    /// This world with walls `[x0, y0, x1, y1]` added (the outlines of
    /// zones a planner must keep out of, drawn as walls it cannot cross).
    pub fn with_walls(&self, walls: &[[f64; 4]]) -> World {
        let mut segments = self.segments.clone();
        segments.extend(
            walls
                .iter()
                .map(|w| Segment::new(Vector::new(w[0], w[1]), Vector::new(w[2], w[3]))),
        );
        World::new(segments, self.solids.clone(), self.grid.clone())
    }

    /// The world as a log's `/map` topic draws it.
    pub fn log_map(&self) -> twindrive_log::WorldMap {
        twindrive_log::WorldMap {
            segments: self.walls(),
            boxes: self.blocks(),
            grid: self.grid().map(|g| twindrive_log::MapGrid {
                width: g.width as u32,
                height: g.height as u32,
                resolution_m: g.resolution_m,
                origin: [g.origin_x_m, g.origin_y_m, g.origin_yaw_rad],
                cells: g
                    .cells
                    .iter()
                    .map(|c| match c {
                        crate::map::Cell::Free => 0,
                        crate::map::Cell::Occupied => 100,
                        crate::map::Cell::Unknown => 255,
                    })
                    .collect(),
            }),
        }
    }

    pub fn grid(&self) -> Option<&OccupancyGrid> {
        self.grid.as_ref()
    }

    /// Bounding box of all walls, `None` for an empty world.
    pub fn bounds(&self) -> Option<Aabb> {
        (!self.segments.is_empty()).then_some(self.extent)
    }

    /// Calls `f` with the index of every segment whose box meets `query`
    /// (every segment for small worlds, or when `query` covers much of the
    /// world, where walking the tree costs more than it saves).
    #[inline]
    pub fn for_each_candidate(&self, query: &Aabb, mut f: impl FnMut(usize)) {
        match &self.bvh {
            Some(bvh)
                if query
                    .intersection(&self.extent)
                    .is_none_or(|i| 4.0 * i.volume() < self.extent.volume()) =>
            {
                bvh.intersect_aabb(query).for_each(|i| f(i as usize))
            }
            _ => (0..self.segments.len()).for_each(f),
        }
    }

    /// The nearest wall point if it lies within `cutoff_m` of `p`.
    #[inline]
    pub fn nearest_within(&self, p: Vector, cutoff_m: f64) -> Option<Nearest> {
        let query = Aabb::new(p - Vector::splat(cutoff_m), p + Vector::splat(cutoff_m));
        let mut best: Option<Nearest> = None;
        let mut best_d = cutoff_m;
        self.for_each_candidate(&query, |i| {
            let proj = self.segments[i].project_local_point(p, false);
            let d = (proj.point - p).length();
            if d <= best_d {
                best_d = d;
                best = Some(Nearest {
                    distance_m: d,
                    point: proj.point,
                });
            }
        });
        best
    }

    /// Distance along a ray (unit direction) to the first wall, or `max_range_m`.
    #[inline]
    pub fn cast_ray(&self, origin: Vector, dir: Vector, max_range_m: f64) -> f64 {
        let ray = Ray::new(origin, dir);
        let end = origin + dir * max_range_m;
        let query = Aabb::new(origin.min(end), origin.max(end));
        let mut best = max_range_m;
        self.for_each_candidate(&query, |i| {
            if let Some(t) = self.segments[i].cast_local_ray(&ray, best, false) {
                best = best.min(t);
            }
        });
        best
    }

    /// Distance from `(x_m, y_m)` to the nearest wall, at most `cutoff_m`;
    /// 0 inside a solid block or an occupied or unknown map cell.
    pub fn clearance_m(&self, x_m: f64, y_m: f64, cutoff_m: f64) -> f64 {
        let p = Vector::new(x_m, y_m);
        if self.inside_obstacle(p) {
            return 0.0;
        }
        self.nearest_within(p, cutoff_m)
            .map_or(cutoff_m, |n| n.distance_m)
    }

    /// True if `p` is inside a solid block or an occupied or unknown map cell.
    pub fn inside_obstacle(&self, p: Vector) -> bool {
        self.solids.iter().any(|s| s.contains_local_point(p))
            || self.grid.as_ref().is_some_and(|g| g.blocked_at(p.x, p.y))
    }
}

/// Segments of a polyline, optionally closed.
pub fn polyline_segments(points: &[[f64; 2]], closed: bool) -> Vec<Segment> {
    let v: Vec<Vector> = points.iter().map(|p| Vector::new(p[0], p[1])).collect();
    let mut out: Vec<Segment> = v.windows(2).map(|w| Segment::new(w[0], w[1])).collect();
    if closed && v.len() > 2 {
        out.push(Segment::new(v[v.len() - 1], v[0]));
    }
    out
}

/// The four outline segments of an axis-aligned block.
pub fn rectangle_segments(min: [f64; 2], max: [f64; 2]) -> Vec<Segment> {
    polyline_segments(&[min, [max[0], min[1]], max, [min[0], max[1]]], true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn room() -> World {
        World::new(rectangle_segments([0.0, 0.0], [4.0, 3.0]), vec![], None)
    }

    #[test]
    fn nearest_and_rays_in_a_room() {
        let w = room();
        let n = w.nearest_within(Vector::new(1.0, 0.5), 1.0).unwrap();
        assert!((n.distance_m - 0.5).abs() < 1e-12);
        assert!((n.point - Vector::new(1.0, 0.0)).length() < 1e-12);
        assert!(w.nearest_within(Vector::new(2.0, 1.5), 1.0).is_none());
        let r = w.cast_ray(Vector::new(1.0, 1.0), Vector::new(1.0, 0.0), 10.0);
        assert!((r - 3.0).abs() < 1e-12);
        let r = w.cast_ray(Vector::new(1.0, 1.0), Vector::new(1.0, 0.0), 2.0);
        assert_eq!(r, 2.0);
    }

    #[test]
    fn bvh_and_linear_scan_agree() {
        // A grid of many small blocks forces the BVH path.
        let mut segs = rectangle_segments([0.0, 0.0], [20.0, 20.0]);
        for i in 0..8 {
            for j in 0..8 {
                let (x, y) = (1.0 + 2.3 * i as f64, 1.2 + 2.2 * j as f64);
                segs.extend(rectangle_segments([x, y], [x + 0.7, y + 0.4]));
            }
        }
        let with_bvh = World::new(segs.clone(), vec![], None);
        assert!(with_bvh.bvh.is_some());
        let linear = World {
            bvh: None,
            ..with_bvh.clone()
        };
        for k in 0..500 {
            let a = k as f64 * 0.37;
            let o = Vector::new(10.0 + 8.0 * (a * 0.3).sin(), 10.0 + 8.0 * (a * 0.7).cos());
            let d = Vector::new(a.cos(), a.sin());
            assert_eq!(with_bvh.cast_ray(o, d, 6.0), linear.cast_ray(o, d, 6.0));
            assert_eq!(
                with_bvh.nearest_within(o, 1.5),
                linear.nearest_within(o, 1.5)
            );
        }
    }
}
