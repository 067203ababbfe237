//! The robot's freedom on a plan: where it may go on its own when the site
//! departs from the twin, and what it must never do. The operator stays in
//! charge of *where* (as Mars rover planners draw keep-in and keep-out
//! zones for a drive under onboard autonomy); the robot decides *how*.
//!
//! - The **corridor** (keep-in) is the ground the robot's body may cover:
//!   every point of its footprint within `half_width_m` of the plan's path.
//!   It is given stretch by stretch, by arc length along the path (turns in
//!   place add none), so the operator can hold the robot to its path in one
//!   place (`half_width_m` equal to the footprint radius: directed driving)
//!   and let it go around things in another. A plan without stretches gives
//!   no corridor: the robot drives its path and hands back on anything it
//!   did not expect, as before the corridor existed.
//! - **Keep-out zones** are polygons the robot's footprint never enters,
//!   whatever its path or a detour says.
//! - **Bounds** on a detour: how much longer (time) and further (distance)
//!   the mission may get before the robot stops and hands back instead.
//!
//! Data only: the geometry that uses it (the default corridor from the
//! twin's clearance, the checks on a track) is `twindrive_mission::freedom`.

use serde::{Deserialize, Serialize};

use crate::PlanError;

/// What the robot may decide on its own while it drives the plan.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Freedom {
    /// The corridor, stretch by stretch, in order along the path; the first
    /// starts at 0. Empty: no corridor (the robot keeps to its path).
    pub corridor: Vec<CorridorStretch>,
    /// Polygons the robot's footprint never enters.
    pub keep_out: Vec<KeepOutZone>,
    /// The detours together may make the mission this much later (s) at
    /// most.
    pub max_extra_time_s: f64,
    /// One detour may add this much distance (m) at most.
    pub max_extra_distance_m: f64,
}

/// From `from_m` along the path (arc length, metres) to the next stretch's
/// start, the robot's body stays within `half_width_m` of the path.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorridorStretch {
    pub from_m: f64,
    pub half_width_m: f64,
}

/// A zone the robot never enters: a simple polygon (x, y in the site's
/// frame, metres; either winding, not closed: the last vertex joins the
/// first).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeepOutZone {
    pub name: String,
    pub polygon: Vec<[f64; 2]>,
}

impl Freedom {
    /// The corridor's half width `along_m` metres along the path, or `None`
    /// without a corridor.
    pub fn half_width_at(&self, along_m: f64) -> Option<f64> {
        let k = self
            .corridor
            .partition_point(|s| s.from_m <= along_m)
            .saturating_sub(1);
        self.corridor.get(k).map(|s| s.half_width_m)
    }

    /// Checks the freedom of a plan whose robot has `footprint_radius_m`:
    /// stretches in order from 0, each wide enough for the robot's body;
    /// zones named once each, simple polygons of finite vertices with an
    /// area; bounds finite and not negative. Errors name the field.
    pub fn validate(&self, footprint_radius_m: f64) -> Result<(), PlanError> {
        let bad = |field: String, why: String| Err(PlanError::Invalid(format!("{field}: {why}")));
        let mut previous = f64::NEG_INFINITY;
        for (i, s) in self.corridor.iter().enumerate() {
            let field = |f: &str| format!("header.freedom.corridor[{i}].{f}");
            if !s.from_m.is_finite() || s.from_m <= previous || (i == 0 && s.from_m != 0.0) {
                return bad(
                    field("from_m"),
                    format!(
                        "expected stretches in order along the path, the first at 0 m, got {}",
                        s.from_m
                    ),
                );
            }
            previous = s.from_m;
            if !(s.half_width_m.is_finite() && s.half_width_m >= footprint_radius_m) {
                return bad(
                    field("half_width_m"),
                    format!(
                        "{} m is narrower than the robot's footprint radius {footprint_radius_m} m: the robot would not fit",
                        s.half_width_m
                    ),
                );
            }
        }
        for (i, z) in self.keep_out.iter().enumerate() {
            let field = |f: &str| format!("header.freedom.keep_out[{i}].{f}");
            if z.name.trim().is_empty() {
                return bad(field("name"), "a zone needs a name".into());
            }
            if self.keep_out[..i].iter().any(|o| o.name == z.name) {
                return bad(field("name"), format!("`{}` names two zones", z.name));
            }
            if let Err(why) = check_polygon(&z.polygon) {
                return bad(field("polygon"), format!("zone `{}`: {why}", z.name));
            }
        }
        for (field, v) in [
            ("header.freedom.max_extra_time_s", self.max_extra_time_s),
            (
                "header.freedom.max_extra_distance_m",
                self.max_extra_distance_m,
            ),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(
                    field.into(),
                    format!("expected a finite number >= 0, got {v}"),
                );
            }
        }
        Ok(())
    }
}

/// Why `polygon` is not a simple polygon with an area, if it is not.
pub fn check_polygon(polygon: &[[f64; 2]]) -> Result<(), String> {
    let n = polygon.len();
    if n < 3 {
        return Err(format!("a polygon needs at least 3 vertices, got {n}"));
    }
    if let Some(k) = polygon
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        return Err(format!("vertex {k} is not finite: {:?}", polygon[k]));
    }
    // Edges that are not neighbours must not touch.
    for i in 0..n {
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            let e = |k: usize| (polygon[k], polygon[(k + 1) % n]);
            if segments_touch(e(i), e(j)) {
                return Err(format!(
                    "edges {i} and {j} cross: the polygon must not cross itself"
                ));
            }
        }
    }
    let twice_area: f64 = (0..n)
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum();
    if twice_area.abs() < 1e-9 {
        return Err("it has no area".into());
    }
    Ok(())
}

fn segments_touch((a, b): ([f64; 2], [f64; 2]), (c, d): ([f64; 2], [f64; 2])) -> bool {
    let cross = |o: [f64; 2], p: [f64; 2], q: [f64; 2]| {
        (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])
    };
    let on = |o: [f64; 2], p: [f64; 2], q: [f64; 2]| {
        q[0] >= o[0].min(p[0])
            && q[0] <= o[0].max(p[0])
            && q[1] >= o[1].min(p[1])
            && q[1] <= o[1].max(p[1])
    };
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on(c, d, a))
        || (d2 == 0.0 && on(c, d, b))
        || (d3 == 0.0 && on(a, b, c))
        || (d4 == 0.0 && on(a, b, d))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn freedom() -> Freedom {
        Freedom {
            corridor: vec![
                CorridorStretch {
                    from_m: 0.0,
                    half_width_m: 0.6,
                },
                CorridorStretch {
                    from_m: 2.5,
                    half_width_m: 0.2,
                },
            ],
            keep_out: vec![KeepOutZone {
                name: "crater".into(),
                polygon: vec![[1.0, 1.0], [2.0, 1.0], [2.0, 2.0], [1.0, 2.0]],
            }],
            max_extra_time_s: 30.0,
            max_extra_distance_m: 4.0,
        }
    }

    #[test]
    fn the_half_width_is_the_stretch_in_progress() {
        let f = freedom();
        assert_eq!(f.half_width_at(0.0), Some(0.6));
        assert_eq!(f.half_width_at(2.4999), Some(0.6));
        assert_eq!(f.half_width_at(2.5), Some(0.2));
        assert_eq!(f.half_width_at(1e6), Some(0.2));
        assert_eq!(f.half_width_at(-1.0), Some(0.6));
        assert_eq!(Freedom::default().half_width_at(1.0), None);
        f.validate(0.15).unwrap();
    }

    #[test]
    fn a_freedom_that_cannot_be_kept_is_refused_by_field() {
        type Change = Box<dyn Fn(&mut Freedom)>;
        let cases: Vec<(Change, &str)> = vec![
            (
                Box::new(|f| f.corridor[1].half_width_m = 0.1),
                "corridor[1].half_width_m: 0.1 m is narrower than the robot's footprint radius 0.15 m",
            ),
            (
                Box::new(|f| f.corridor[0].from_m = 0.5),
                "corridor[0].from_m",
            ),
            (
                Box::new(|f| f.corridor[1].from_m = 0.0),
                "corridor[1].from_m",
            ),
            (
                Box::new(|f| f.corridor[1].from_m = f64::NAN),
                "corridor[1].from_m",
            ),
            (
                Box::new(|f| f.keep_out[0].polygon.truncate(2)),
                "keep_out[0].polygon: zone `crater`: a polygon needs at least 3 vertices, got 2",
            ),
            (
                Box::new(|f| f.keep_out[0].polygon.swap(1, 2)),
                "edges 0 and 2 cross",
            ),
            (
                Box::new(|f| f.keep_out[0].polygon = vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]),
                "it has no area",
            ),
            (
                Box::new(|f| f.keep_out[0].polygon[2][0] = f64::INFINITY),
                "vertex 2 is not finite",
            ),
            (
                Box::new(|f| f.keep_out.push(f.keep_out[0].clone())),
                "keep_out[1].name: `crater` names two zones",
            ),
            (
                Box::new(|f| f.max_extra_time_s = -1.0),
                "max_extra_time_s: expected a finite number >= 0, got -1",
            ),
        ];
        for (change, want) in cases {
            let mut f = freedom();
            change(&mut f);
            let e = f.validate(0.15).unwrap_err().to_string();
            assert!(e.contains(want), "{want}: {e}");
        }
    }
}
