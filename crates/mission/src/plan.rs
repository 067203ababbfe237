//! The mission plan ([`twindrive_plan`], data only) and what needs the
//! simulator: the plan's map as a world, and the robot's range predictions
//! from it ([`PlanGeometry::range_model`]: the same code and the same walls
//! as the twin, so the same bits); the TUM export; a plan sample from the
//! pipeline's path and command.

use std::io::Write;

pub use twindrive_plan::*;

/// The plan's map as the simulator's geometry.
pub trait SiteMapGeometry {
    /// The walls and blocks of the twin's `world`.
    fn of(world: &twindrive_sim::World) -> Self;
    /// The map as a world for geometry queries (no occupancy grid: cells
    /// travel as their outlines).
    fn world(&self) -> twindrive_sim::World;
    /// The map without its blocks ([`SiteMap::walls_without_boxes`]).
    fn without_boxes(&self) -> twindrive_sim::World;
}

impl SiteMapGeometry for SiteMap {
    fn of(world: &twindrive_sim::World) -> Self {
        Self {
            segments: world.walls(),
            boxes: world.blocks(),
        }
    }

    fn world(&self) -> twindrive_sim::World {
        twindrive_sim::World::from_walls(&self.segments, &self.boxes)
    }

    fn without_boxes(&self) -> twindrive_sim::World {
        twindrive_sim::World::from_walls(&self.walls_without_boxes(), &[])
    }
}

/// What the robot predicts from its plan, and the plan's TUM export.
pub trait PlanGeometry {
    /// What the robot's range sensors read, free of noise, at any pose on
    /// the plan's map: the twin's predictions, bit for bit.
    fn range_model(&self) -> twindrive_sim::RangeModel;
    /// The robot's range predictions from the map without its blocks
    /// ([`SiteMapGeometry::without_boxes`]); `None` when the map has none.
    fn range_model_without_boxes(&self) -> Option<twindrive_sim::RangeModel>;
    /// The plan's poses as a TUM trajectory.
    fn write_tum(&self, out: impl Write) -> std::io::Result<()>;
}

impl PlanGeometry for MissionPlan {
    fn range_model(&self) -> twindrive_sim::RangeModel {
        twindrive_sim::RangeModel::new(
            self.header.site_map.world(),
            &self.header.robot.range_sensors,
        )
    }

    fn range_model_without_boxes(&self) -> Option<twindrive_sim::RangeModel> {
        (!self.header.site_map.boxes.is_empty()).then(|| {
            twindrive_sim::RangeModel::new(
                self.header.site_map.without_boxes(),
                &self.header.robot.range_sensors,
            )
        })
    }

    fn write_tum(&self, out: impl Write) -> std::io::Result<()> {
        let ns = |t: f64| (t * 1e9).round().max(0.0) as u64;
        twindrive_log::write_tum(self.samples.iter().map(|s| (ns(s.t_s), s.pose())), out)
    }
}

/// The plan's step at a path sample driven with `command`, with whether
/// the twin's bumper touches there.
pub fn plan_sample(
    at: &crate::PathSample,
    command: &crate::control::WheelCommand,
    expected_bump: bool,
) -> PlanSample {
    PlanSample {
        t_s: at.t_s,
        x_m: at.pose.x_m,
        y_m: at.pose.y_m,
        heading_rad: at.pose.heading_rad,
        v_m_s: command.v_m_s,
        omega_rad_s: command.omega_rad_s,
        left_rad_s: command.left_rad_s,
        right_rad_s: command.right_rad_s,
        expected_bump,
    }
}
