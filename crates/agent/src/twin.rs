//! The twin learns from what the robot saw ("continually update the
//! simulated representation", paper section 3), and the operator's
//! continuation is rehearsed on it.
//!
//! From a hand-back the twin takes:
//! - the robot's pose (where the continuation starts);
//! - its kinematic parameters, when the robot's estimates differ from the
//!   twin's by more than three of their standard deviations (and by more
//!   than a tenth of a millimetre: below that no plan changes);
//! - its world: every range reading in the hand-back's sensor window that
//!   ends well short of where the twin's world says it should, and a bumper
//!   contact the twin did not predict, marks an obstacle point; points
//!   within `cluster_m` of each other make one solid block, grown by
//!   `grow_m` (a range sensor sees one face of an obstacle, not its depth).

use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::wire::Handback;
use twindrive_mission::PipelineError;
use twindrive_mission::pipeline::{PipelineSettings, plan_from_log};
use twindrive_mission::plan::{MissionPlan, sha256_hex};
use twindrive_mission::verify::{self, Criteria, TrackerSettings, Verdict};
use twindrive_sim::{Scenario, SensorModel, Simulator};

/// The master's twin: its scenario (world and simulated robot) and the
/// operator's calibrated parameters.
#[derive(Debug, Clone)]
pub struct Twin {
    pub scenario: Scenario,
    pub calibrated: DiffDriveParams,
    /// Blocks learnt from the robot so far.
    pub learnt: Vec<([f64; 2], [f64; 2])>,
}

/// What a hand-back changed in the twin.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TwinUpdate {
    pub pose: Pose,
    /// The new parameters, when they changed.
    pub params: Option<DiffDriveParams>,
    /// Blocks added to the world: `(min, max)` corners (m).
    pub obstacles_added: Vec<([f64; 2], [f64; 2])>,
    /// Obstacle points behind them (range endpoints and contacts).
    pub evidence_points: usize,
}

/// How readings become obstacles.
#[derive(Debug, Clone, Copy)]
pub struct LearnSettings {
    /// A reading this much shorter than the twin's prediction marks an obstacle (m).
    pub shorter_by_m: f64,
    pub cluster_m: f64,
    pub grow_m: f64,
}

impl Default for LearnSettings {
    fn default() -> Self {
        Self {
            shorter_by_m: 0.08,
            cluster_m: 0.3,
            grow_m: 0.05,
        }
    }
}

impl Twin {
    pub fn new(scenario: Scenario, calibrated: DiffDriveParams) -> Self {
        Self {
            scenario,
            calibrated,
            learnt: Vec::new(),
        }
    }

    /// Updates the twin from a hand-back.
    pub fn apply(&mut self, h: &Handback, settings: &LearnSettings) -> TwinUpdate {
        let pose = Pose::new(h.pose[0], h.pose[1], h.pose[2]);
        self.scenario.robot.start = pose;
        // Parameters: only when the robot's estimate is confidently different.
        let twin = [
            self.calibrated.left_diameter_m,
            self.calibrated.right_diameter_m,
            self.calibrated.wheelbase_m,
        ];
        let differs = (0..3).any(|i| {
            let sigma = h.params_covariance[4 * i].max(0.0).sqrt();
            let d = (h.params[i] - twin[i]).abs();
            sigma.is_finite() && d > 3.0 * sigma && d > 1e-4
        });
        let params = differs.then(|| DiffDriveParams {
            left_diameter_m: h.params[0],
            right_diameter_m: h.params[1],
            wheelbase_m: h.params[2],
        });
        if let Some(p) = params.filter(|p| p.validate().is_ok()) {
            self.calibrated = p;
            self.scenario.robot.true_params = p;
            self.scenario.robot.nominal_params = p;
        }
        // The world: points the twin cannot explain.
        let points = self.obstacle_points(h, settings);
        // A block never covers where the robot stands (it touched the
        // obstacle's face, it is not inside it).
        let clear = self.scenario.robot.footprint_radius_m + 0.001;
        let blocks: Vec<_> = cluster(&points, settings)
            .into_iter()
            .filter_map(|b| clip_clear_of(b, [pose.x_m, pose.y_m], clear))
            .collect();
        if !blocks.is_empty() {
            self.scenario.world = self.scenario.world.with_blocks(&blocks);
            self.learnt.extend_from_slice(&blocks);
        }
        TwinUpdate {
            pose,
            params: params.filter(|p| p.validate().is_ok()),
            obstacles_added: blocks,
            evidence_points: points.len(),
        }
    }

    fn obstacle_points(&self, h: &Handback, settings: &LearnSettings) -> Vec<[f64; 2]> {
        let mut model = SensorModel::new(&self.scenario);
        let mut predicted = vec![0.0; model.beams()];
        let mut points = Vec::new();
        let sensors = &self.scenario.range_sensors;
        for w in &h.window {
            let pose = Pose::new(w.pose[0], w.pose[1], w.pose[2]);
            let bump_predicted = model.read(&pose, &mut predicted);
            let mut beam = 0;
            for s in sensors {
                let info = &s.info;
                for k in 0..info.beams {
                    let Some(&measured) = w.ranges_m.get(beam) else {
                        break;
                    };
                    let measured = f64::from(measured);
                    let expected = predicted[beam];
                    beam += 1;
                    if !measured.is_finite()
                        || measured >= info.max_range_m - 0.02
                        || measured > expected - settings.shorter_by_m
                    {
                        continue;
                    }
                    let (mx, my) = pose.transform_point(info.mount.x_m, info.mount.y_m);
                    let angle = pose.heading_rad + info.mount.heading_rad + info.beam_angle_rad(k);
                    points.push([mx + measured * angle.cos(), my + measured * angle.sin()]);
                }
            }
            if w.bump && !bump_predicted {
                let r = self.scenario.robot.footprint_radius_m + 0.005;
                points.push([
                    pose.x_m + r * pose.heading_rad.cos(),
                    pose.y_m + r * pose.heading_rad.sin(),
                ]);
            }
        }
        points
    }

    /// The operator's continuation: the mission's controller re-run on the
    /// updated twin from the hand-back pose for `duration_s`, through the
    /// pipeline, and verified on the twin the way the robot drives it,
    /// closed loop (no contact, within `criteria`'s deviation of its own
    /// path, ending within it of its end) before it
    /// is returned. The twin's robot moves with the parameters the plan is
    /// made with (one robot model for the rehearsal and the plan) and
    /// without the wheel slip the simulated site adds: slip belongs to the
    /// real ground, which the twin does not know; the robot's closed-loop
    /// tracking and its hand-back tolerances absorb it.
    pub fn continuation(
        &self,
        duration_s: f64,
        settings: &PipelineSettings,
        criteria: &Criteria,
    ) -> Result<MissionPlan, PipelineError> {
        let mut scenario = self.scenario.clone();
        scenario.robot.true_params = self.calibrated;
        scenario.robot.slip_std = 0.0;
        scenario
            .set_duration_s(duration_s)
            .map_err(|e| PipelineError::Infeasible(format!("continuation duration: {e}")))?;
        let log = Simulator::new(scenario.clone()).run(|_, _| {});
        let log_sha = sha256_hex(format!("continuation:{:?}", log.header.start).as_bytes());
        let (plan, _) =
            plan_from_log(&log, &log_sha, &self.calibrated, &scenario, settings, false)?;
        let closed = verify::closed_loop(
            &plan.samples,
            scenario,
            &self.calibrated,
            &TrackerSettings::default(),
        )?;
        let verdict = Verdict::judge_closed_loop(&closed.report, criteria);
        if !verdict.passed {
            return Err(PipelineError::Infeasible(format!(
                "the continuation fails verification on the twin: {}",
                verdict.reasons.join("; ")
            )));
        }
        Ok(plan)
    }
}

/// Single-linkage clusters of points within `cluster_m`, each as a grown
/// axis-aligned block.
fn cluster(points: &[[f64; 2]], settings: &LearnSettings) -> Vec<([f64; 2], [f64; 2])> {
    let n = points.len();
    let mut label: Vec<Option<usize>> = vec![None; n];
    let mut blocks = Vec::new();
    for start in 0..n {
        if label[start].is_some() {
            continue;
        }
        let id = blocks.len();
        label[start] = Some(id);
        let mut stack = vec![start];
        let (mut min, mut max) = (points[start], points[start]);
        while let Some(i) = stack.pop() {
            let p = points[i];
            min = [min[0].min(p[0]), min[1].min(p[1])];
            max = [max[0].max(p[0]), max[1].max(p[1])];
            for j in 0..n {
                if label[j].is_none()
                    && (points[j][0] - p[0]).hypot(points[j][1] - p[1]) <= settings.cluster_m
                {
                    label[j] = Some(id);
                    stack.push(j);
                }
            }
        }
        let g = settings.grow_m;
        blocks.push(([min[0] - g, min[1] - g], [max[0] + g, max[1] + g]));
    }
    blocks
}

/// Moves the face of `block` nearest to `centre` back until the disc of
/// `radius` around `centre` is clear of it; `None` if nothing is left.
fn clip_clear_of(
    (mut min, mut max): ([f64; 2], [f64; 2]),
    centre: [f64; 2],
    radius: f64,
) -> Option<([f64; 2], [f64; 2])> {
    let nearest = [
        centre[0].clamp(min[0], max[0]),
        centre[1].clamp(min[1], max[1]),
    ];
    if (nearest[0] - centre[0]).hypot(nearest[1] - centre[1]) >= radius {
        return Some((min, max));
    }
    // Push the face along the axis where the block lies most to one side.
    let mid = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
    let axis = usize::from((mid[1] - centre[1]).abs() > (mid[0] - centre[0]).abs());
    if mid[axis] >= centre[axis] {
        min[axis] = min[axis].max(centre[axis] + radius);
    } else {
        max[axis] = max[axis].min(centre[axis] - radius);
    }
    // A contact's block keeps some depth behind the face.
    if max[axis] - min[axis] < 0.1 {
        if mid[axis] >= centre[axis] {
            max[axis] = min[axis] + 0.1;
        } else {
            min[axis] = max[axis] - 0.1;
        }
    }
    Some((min, max))
}

/// Wraps an updated twin's plan-making for the operator: the mission
/// duration left after a hand-back at `plan_t_s` of a plan lasting
/// `plan_duration_s`, at least `min_s`.
pub fn remaining_s(plan_duration_s: f64, plan_t_s: f64, min_s: f64) -> f64 {
    (plan_duration_s - plan_t_s).max(min_s)
}
