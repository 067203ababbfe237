//! The twin learns from what the robot saw ("continually update the
//! simulated representation", paper section 3), and the operator's
//! continuation is rehearsed on it.
//!
//! From a hand-back the twin takes:
//! - the robot's pose (where the continuation starts), refined against the
//!   twin's map with the hand-back's window of readings, with its
//!   uncertainty ([`crate::refine`]);
//! - its kinematic parameters, when the robot's estimates differ from the
//!   twin's by more than three of their standard deviations (and by more
//!   than a tenth of a millimetre: below that no plan changes);
//! - its world: every range reading in the hand-back's sensor window that
//!   ends well short of where the world the twin knew before learning says
//!   it should (so a block seen again is placed by every sighting), and a bumper
//!   contact the twin did not predict, marks an obstacle point, kept with
//!   where it was seen from; a reading that ends well beyond where the twin
//!   says it should is free space, and removes the points learnt before
//!   along its ray (the twin learnt them wrong). The learnt world is
//!   rebuilt from all the points kept: points within `cluster_m` of each
//!   other make one solid block, given `depth_m` behind the faces seen (a
//!   range sensor sees one face of an obstacle, not its depth) and
//!   `grow_m` along them, never towards where they were seen from, so the
//!   twin predicts the faces where the robot saw them. The window's poses
//!   are moved with the refinement, so the points are placed where the
//!   refined pose says they were. A contact says there is something at the
//!   bumper, not how wide it is: its block reaches `contact_grow_m` along
//!   the face either way.
//!
//! The twin learns only what it did not know. A reading is compared with
//! the twin's geometry where it ended, not only with the range predicted
//! along its beam: a beam that grazes a door frame or a box's corner ends
//! far from where the map predicts on a centimetre of pose error, yet on
//! the frame. A point (or a contact) within `known_margin_m` of what the
//! twin knew (walls, blocks, map cells), or within three standard
//! deviations of where the range noise and the robot's pose uncertainty
//! put it, is explained by that and is no evidence. A learnt block keeps
//! `known_margin_m` clear of what the twin knew: where a block's guessed
//! extent (its depth, its growth along a face, or the gap between its
//! points) would reach it, the block is cut back, keeping its points.
//!
//! Where a continuation leaves the interrupted plan's path (its back-off,
//! its way back, its detours) it keeps three standard deviations of the
//! refined position (towards the nearest wall or block) clear of everything
//! the twin knows, walls and learnt blocks; from where the robot stands it
//! first moves away from what is nearer than that. One that cannot is not
//! sent, and the operator is told where it came too close.

use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::wire::Handback;
use twindrive_mission::PipelineError;
use twindrive_mission::detour::{Block, DetourSettings, distance_to_block};
use twindrive_mission::pipeline::continuation_plan;
use twindrive_mission::plan::MissionPlan;
use twindrive_mission::verify::{self, Criteria, TrackerSettings, Verdict};
use twindrive_sim::{Scenario, SensorModel, World};

use crate::refine::{RefineSettings, RefinedPose, refine};

/// The master's twin: its scenario (world and simulated robot) and the
/// operator's calibrated parameters.
#[derive(Debug, Clone)]
pub struct Twin {
    pub scenario: Scenario,
    pub calibrated: DiffDriveParams,
    /// Blocks learnt from the robot so far (the learnt world now).
    pub learnt: Vec<Block>,
    /// The world as the twin knew it before learning.
    known: World,
    /// Obstacle points learnt, each with where it was seen from.
    evidence: Vec<Evidence>,
    /// Sight lines through where a learnt block was (they cut its guessed
    /// extent back).
    free: Vec<Ray>,
    /// The latest hand-back's pose as refined, with its covariance (the
    /// continuation starts there).
    pub refined: Option<RefinedPose>,
}

/// An obstacle point and the place it was seen from (the sensor's mount,
/// or the robot's centre for a contact).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Evidence {
    point: [f64; 2],
    seen_from: [f64; 2],
    /// A bumper contact (its extent along the face is unknown).
    contact: bool,
}

/// A sight line through free space: from the sensor to short of what it saw.
type Ray = ([f64; 2], [f64; 2]);

/// What a hand-back changed in the twin.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TwinUpdate {
    pub pose: Pose,
    /// The pose as refined against the twin's map, with the robot's own.
    pub refined: RefinedPose,
    /// The new parameters, when they changed.
    pub params: Option<DiffDriveParams>,
    /// Blocks added to the world: `(min, max)` corners (m).
    pub obstacles_added: Vec<Block>,
    /// Learnt blocks taken out (or replaced by a corrected block).
    pub obstacles_removed: Vec<Block>,
    /// Obstacle points behind the new blocks (range endpoints and contacts).
    pub evidence_points: usize,
    /// Points learnt before that free-space readings contradicted.
    pub evidence_removed: usize,
}

impl TwinUpdate {
    /// Whether the twin's world or parameters changed (its pose always does).
    pub fn changed(&self) -> bool {
        self.params.is_some()
            || !self.obstacles_added.is_empty()
            || !self.obstacles_removed.is_empty()
    }
}

/// How readings become obstacles.
#[derive(Debug, Clone, Copy)]
pub struct LearnSettings {
    /// A reading this much shorter than the twin's prediction marks an
    /// obstacle, and this much longer marks free space (m).
    pub shorter_by_m: f64,
    pub cluster_m: f64,
    /// A block's extent beyond its points along the faces seen (m).
    pub grow_m: f64,
    /// A block's depth behind the faces seen (m).
    pub depth_m: f64,
    /// A contact's block extent along the face either way, and its depth
    /// (m): a bumper says something is there, not how large it is. Readings
    /// through the guess cut it back.
    pub contact_grow_m: f64,
    pub contact_depth_m: f64,
    /// A point or contact nearer than this to what the twin knew (or than
    /// three standard deviations of the range noise and the robot's pose
    /// uncertainty) is explained by it; a learnt block keeps this far from
    /// it (m).
    pub known_margin_m: f64,
    pub refine: RefineSettings,
}

impl Default for LearnSettings {
    fn default() -> Self {
        Self {
            shorter_by_m: 0.08,
            cluster_m: 0.3,
            grow_m: 0.03,
            depth_m: 0.1,
            contact_grow_m: 0.3,
            contact_depth_m: 0.3,
            known_margin_m: 0.06,
            refine: RefineSettings::default(),
        }
    }
}

impl Twin {
    pub fn new(scenario: Scenario, calibrated: DiffDriveParams) -> Self {
        Self {
            known: scenario.world.clone(),
            scenario,
            calibrated,
            learnt: Vec::new(),
            evidence: Vec::new(),
            free: Vec::new(),
            refined: None,
        }
    }

    /// Updates the twin from a hand-back.
    pub fn apply(&mut self, h: &Handback, settings: &LearnSettings) -> TwinUpdate {
        let sensors: Vec<_> = self
            .scenario
            .range_sensors
            .iter()
            .map(|s| s.info.clone())
            .collect();
        // Against the walls the twin knew: a learnt block's extent is
        // partly a guess, no landmark.
        let refined = refine(&self.known, &sensors, &self.calibrated, h, &settings.refine);
        self.refined = Some(refined);
        let pose = Pose::new(refined.pose[0], refined.pose[1], refined.pose[2]);
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
        let params = differs
            .then(|| DiffDriveParams {
                left_diameter_m: h.params[0],
                right_diameter_m: h.params[1],
                wheelbase_m: h.params[2],
            })
            .filter(|p| p.validate().is_ok());
        if let Some(p) = params {
            self.calibrated = p;
            self.scenario.robot.true_params = p;
            self.scenario.robot.nominal_params = p;
        }
        // The world: points the twin cannot explain, and free space where
        // it predicted a learnt obstacle.
        let (points, free_rays) = self.readings(h, &refined, settings);
        let before = self.evidence.len();
        self.evidence.retain(|e| {
            !free_rays
                .iter()
                .any(|&(a, b)| distance_to_segment(e.point, a, b) < 0.5 * settings.shorter_by_m)
        });
        let evidence_removed = before - self.evidence.len();
        self.evidence.extend_from_slice(&points);
        self.free.extend_from_slice(&free_rays);
        // A block never covers where the robot stands (it touched the
        // obstacle's face, it is not inside it).
        let clear =
            self.scenario.robot.footprint_radius_m + 0.1 * self.scenario.bump.contact_margin_m;
        let blocks = self.blocks([pose.x_m, pose.y_m], clear, settings);
        let obstacles_added: Vec<Block> = blocks
            .iter()
            .filter(|b| !self.learnt.contains(b))
            .copied()
            .collect();
        let obstacles_removed: Vec<Block> = self
            .learnt
            .iter()
            .filter(|b| !blocks.contains(b))
            .copied()
            .collect();
        if blocks != self.learnt {
            self.scenario.world = self.known.with_blocks(&blocks);
            self.learnt = blocks;
        }
        TwinUpdate {
            pose,
            refined,
            params,
            obstacles_added,
            obstacles_removed,
            evidence_points: points.len(),
            evidence_removed,
        }
    }

    /// Learns what the robot saw on a detour: `points` where its readings
    /// ended on something the map lacks, seen from about `seen_from` (the
    /// robot went around it on its own, so no round trip and no pose to
    /// refine). Returns the blocks added. The same clustering as a
    /// hand-back's; blocks stay clear of `clear_of` (where the robot was).
    ///
    /// The robot chose the points by range, against the map's prediction
    /// at its estimate; here a point that lies on what the twin knew
    /// (within `known_margin_m`, or three standard deviations of its
    /// sensors' range noise) is taken for a reading of that, not of
    /// something new. The report carries no pose covariance: a localizing
    /// robot knows its pose to a centimetre or so, which the margin holds.
    pub fn learn_seen(
        &mut self,
        points: &[[f64; 2]],
        seen_from: [f64; 2],
        settings: &LearnSettings,
    ) -> Vec<Block> {
        let noise = self
            .scenario
            .range_sensors
            .iter()
            .map(|s| s.noise_std_m)
            .fold(0.0, f64::max);
        let explained_m = settings.known_margin_m.max(3.0 * noise);
        let new: Vec<Evidence> = points
            .iter()
            .filter(|p| p[0].is_finite() && p[1].is_finite())
            .filter(|&&p| !self.known_explains(p, explained_m))
            .map(|&point| Evidence {
                point,
                seen_from,
                contact: false,
            })
            .collect();
        self.evidence.extend(new);
        let clear = self.scenario.robot.footprint_radius_m;
        let blocks = self.blocks(seen_from, clear, settings);
        let added: Vec<Block> = blocks
            .iter()
            .filter(|b| !self.learnt.contains(b))
            .copied()
            .collect();
        if blocks != self.learnt {
            self.scenario.world = self.known.with_blocks(&blocks);
            self.learnt = blocks;
        }
        added
    }

    /// The hand-back window's readings against the twin's predictions:
    /// obstacle points (readings well short of what the world known before
    /// learning predicts, contacts the twin did not predict) and free rays (sensor to reading, for readings
    /// well beyond a prediction that ended on a learnt obstacle).
    fn readings(
        &self,
        h: &Handback,
        refined: &RefinedPose,
        settings: &LearnSettings,
    ) -> (Vec<Evidence>, Vec<Ray>) {
        let mut model = SensorModel::new(&self.scenario);
        // What the twin knew before learning: a reading it does not explain
        // is evidence, whether or not a block learnt before explains it
        // too (a face seen again, from elsewhere, places it better).
        let known_site = Scenario {
            world: self.known.clone(),
            ..self.scenario.clone()
        };
        let mut known_model = SensorModel::new(&known_site);
        let mut predicted = vec![0.0; model.beams()];
        let mut predicted_known = vec![0.0; model.beams()];
        let (mut points, mut free) = (Vec::new(), Vec::new());
        let sensors = &self.scenario.range_sensors;
        // Where the refined pose puts a reading's end, to a standard
        // deviation: the position's, the heading's at the point's distance
        // from the robot, and the sensor's noise.
        let position_var = refined.position_std_m().powi(2);
        let heading_var = refined.covariance[8].max(0.0);
        let explained_m = |noise: f64, from_robot_m: f64| {
            let var = noise * noise + position_var + heading_var * from_robot_m * from_robot_m;
            settings.known_margin_m.max(3.0 * var.sqrt())
        };
        for w in &h.window {
            let [x, y, heading] = refined.correct(w.pose);
            let pose = Pose::new(x, y, heading);
            let bump_predicted = model.read(&pose, &mut predicted);
            known_model.read(&pose, &mut predicted_known);
            let mut beam = 0;
            for s in sensors {
                let info = &s.info;
                for k in 0..info.beams {
                    let Some(&measured) = w.ranges_m.get(beam) else {
                        break;
                    };
                    let measured = f64::from(measured);
                    let expected = predicted[beam];
                    let expected_known = predicted_known[beam];
                    beam += 1;
                    if !measured.is_finite() {
                        continue;
                    }
                    let (mx, my) = pose.transform_point(info.mount.x_m, info.mount.y_m);
                    let angle = pose.heading_rad + info.mount.heading_rad + info.beam_angle_rad(k);
                    let (sn, cs) = angle.sin_cos();
                    let at = |r: f64| [mx + r * cs, my + r * sn];
                    if measured < info.max_range_m - 0.02
                        && measured < expected_known - settings.shorter_by_m
                    {
                        // Short of the prediction, but on what the twin
                        // knew (a grazed edge, a pose a little off): no
                        // evidence.
                        let p = at(measured);
                        let from_robot_m = (p[0] - pose.x_m).hypot(p[1] - pose.y_m);
                        if !self.known_explains(p, explained_m(s.noise_std_m, from_robot_m)) {
                            points.push(Evidence {
                                point: p,
                                seen_from: [mx, my],
                                contact: false,
                            });
                        }
                    } else if measured > expected + settings.shorter_by_m
                        && self.on_learnt(at(expected))
                    {
                        // Free up to a little short of what it saw.
                        let end = (measured - settings.shorter_by_m).max(0.0);
                        free.push(([mx, my], at(end)));
                    }
                }
            }
            if w.bump && !bump_predicted {
                // On the footprint, within the bumper's reach (the twin's
                // robot standing there touches it too).
                let r = self.scenario.robot.footprint_radius_m
                    + 0.25 * self.scenario.bump.contact_margin_m;
                let point = [
                    pose.x_m + r * pose.heading_rad.cos(),
                    pose.y_m + r * pose.heading_rad.sin(),
                ];
                // A contact with what the twin knew, a little off where
                // the refined pose says: no evidence either.
                let reach = self.scenario.bump.contact_margin_m + explained_m(0.0, r);
                if !self.known_explains(point, reach) {
                    points.push(Evidence {
                        point,
                        seen_from: [pose.x_m, pose.y_m],
                        contact: true,
                    });
                }
            }
        }
        (points, free)
    }

    /// Whether `p` lies within `within_m` of what the twin knew before
    /// learning (a wall, a block, an occupied or unknown map cell).
    fn known_explains(&self, p: [f64; 2], within_m: f64) -> bool {
        self.known.clearance_m(p[0], p[1], within_m) < within_m
    }

    /// The learnt world from the evidence kept: its clusters' blocks, each
    /// clear of the disc of `clear` around `centre` (where the robot
    /// stands) and cut back to keep `known_margin_m` from what the twin
    /// knew (a block that cannot is dropped).
    fn blocks(&self, centre: [f64; 2], clear: f64, settings: &LearnSettings) -> Vec<Block> {
        clusters(&self.evidence, &self.free, settings)
            .into_iter()
            .filter_map(|(b, members)| {
                let b = clip_clear_of(b, centre, clear)?;
                clip_off_known(b, &members, &self.known, settings.known_margin_m)
            })
            .collect()
    }

    /// Whether `p` lies on (within a centimetre of) a learnt block.
    fn on_learnt(&self, p: [f64; 2]) -> bool {
        self.learnt.iter().any(|b| distance_to_block(p, b) <= 0.01)
    }

    /// The operator's continuation of `interrupted`, which the robot
    /// handed back `plan_t_s` into: from the hand-back pose back onto the
    /// rest of the plan and around every stretch of it that now passes a
    /// learnt block ([`twindrive_mission::detour`]), so the mission's route
    /// is still covered; verified on the twin the way the robot drives it,
    /// closed loop (no contact, within `criteria`'s deviation of its own
    /// path, ending within it of its end) before it is returned. The twin's
    /// robot moves with the parameters the plan is made with (one robot
    /// model for the plan and its verification) and without the wheel slip
    /// the simulated site adds: slip belongs to the real ground, which the
    /// twin does not know; the robot's closed-loop tracking and its
    /// hand-back tolerances absorb it.
    pub fn continuation(
        &self,
        interrupted: &MissionPlan,
        plan_t_s: f64,
        settings: &ContinuationSettings,
        criteria: &Criteria,
    ) -> Result<MissionPlan, PipelineError> {
        let mut scenario = self.scenario.clone();
        scenario.robot.true_params = self.calibrated;
        scenario.robot.slip_std = 0.0;
        // Three standard deviations of where the robot stands, and at least
        // the clearance wanted anyway.
        let required_m = 3.0 * self.refined.map_or(0.0, |r| r.position_std_m());
        let mut detour = settings.detour;
        detour.clearance_m = detour.clearance_m.max(required_m);
        detour.min_clearance_m = detour.min_clearance_m.max(required_m);
        let plan = continuation_plan(
            interrupted,
            plan_t_s,
            &self.calibrated,
            &scenario,
            &self.learnt,
            &detour,
            settings.pace,
        )?;
        let plan = match &self.refined {
            Some(r) => plan.with_start_covariance(r.covariance),
            None => plan,
        };
        self.check_clearance(&plan, interrupted, plan_t_s)?;
        let closed = verify::closed_loop(
            &plan.samples,
            scenario,
            &self.calibrated,
            &TrackerSettings::default(),
            &twindrive_mission::freedom::FreedomMap::of_plan(&plan),
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

    /// Whether `plan`, the continuation of `interrupted` from `plan_t_s`,
    /// keeps its footprint three standard deviations of the robot's
    /// position clear of everything the twin knows until the robot can have
    /// localized again: wherever it leaves the interrupted plan's path (its
    /// back-off, its way back onto the plan, its detours: the geometry the
    /// twin made for a robot it knows only that well), and on the plan's
    /// path within its first [`SETTLE_M`] of driving (after that the robot
    /// has localized again, and the plan was verified for a robot that
    /// does). A leg off the plan
    /// never needs more than the plan keeps where the leg leaves or joins
    /// it. The deviation is taken towards the nearest wall or block: a robot
    /// that followed a wall knows its distance from it well and its place
    /// along it less. Where the robot stands it may be nearer (it handed
    /// back against an obstacle): from there the continuation may only move
    /// away, and must be clear within [`LEAVE_M`] of driving.
    fn check_clearance(
        &self,
        plan: &MissionPlan,
        interrupted: &MissionPlan,
        plan_t_s: f64,
    ) -> Result<(), PipelineError> {
        let Some(refined) = self.refined else {
            return Ok(());
        };
        let t_start = interrupted.samples.first().map_or(0.0, |s| s.t_s) + plan_t_s;
        let k0 = interrupted.samples.partition_point(|s| s.t_s < t_start);
        let remaining = &interrupted.samples[k0..];
        // The next sample of the interrupted plan the continuation may
        // still pass (it follows the plan in order).
        let mut next = 0;
        let c = &refined.covariance;
        let sigma_towards = |n: [f64; 2]| {
            (n[0] * n[0] * c[0] + 2.0 * n[0] * n[1] * c[1] + n[1] * n[1] * c[4])
                .max(0.0)
                .sqrt()
        };
        let footprint = self.scenario.robot.footprint_radius_m;
        let cutoff = footprint + 3.0 * refined.position_std_m() + 0.05;
        let world = &self.scenario.world;
        // Each sample: on the interrupted plan's path or not, its clearance,
        // the position's deviation towards what is nearest.
        let mut samples = Vec::with_capacity(plan.samples.len());
        for s in &plan.samples {
            // On the plan's path: at one of its samples or between two
            // (re-timing puts samples between the plan's own).
            let at = [s.x_m, s.y_m];
            let on_plan = remaining[next..].iter().enumerate().position(|(j, r)| {
                let a = [r.x_m, r.y_m];
                let b = remaining.get(next + j + 1).map_or(a, |r| [r.x_m, r.y_m]);
                distance_to_segment(at, a, b) < 1e-4
            });
            if let Some(j) = on_plan {
                next += j;
            }
            let p = twindrive_sim::Vector::new(s.x_m, s.y_m);
            let (clear, sigma) = if world.inside_obstacle(p) {
                (-footprint, refined.position_std_m())
            } else {
                match world.nearest_within(p, cutoff) {
                    None => (cutoff - footprint, 0.0),
                    Some(n) => {
                        let d = n.distance_m.max(1e-9);
                        let towards = [(n.point.x - p.x) / d, (n.point.y - p.y) / d];
                        (n.distance_m - footprint, sigma_towards(towards))
                    }
                }
            };
            samples.push((on_plan.is_some(), clear, sigma));
        }
        // A leg off the plan never needs more clearance than the plan it
        // leaves or joins keeps there (the robot drives that anyway).
        let mut join = vec![None; samples.len()];
        let mut previous: Option<f64> = None;
        for (k, &(on, clear, _)) in samples.iter().enumerate() {
            if on {
                previous = Some(clear);
            } else {
                join[k] = previous;
            }
        }
        let mut following: Option<f64> = None;
        for (k, &(on, clear, _)) in samples.iter().enumerate().rev() {
            if on {
                following = Some(clear);
            } else if let Some(f) = following {
                join[k] = Some(join[k].map_or(f, |p: f64| p.max(f)));
            }
        }
        let mut leaving = true;
        let mut last = f64::NEG_INFINITY;
        // Driven so far (m).
        let mut travel_m = 0.0;
        let t0 = plan.samples.first().map_or(0.0, |s| s.t_s);
        for (k, (s, &(on_plan, clear, sigma))) in plan.samples.iter().zip(&samples).enumerate() {
            if k > 0 {
                let p = &plan.samples[k - 1];
                travel_m += (s.x_m - p.x_m).hypot(s.y_m - p.y_m);
            }
            let required_m = join[k].map_or(3.0 * sigma, |j| (3.0 * sigma).min(j));
            if leaving && clear >= required_m {
                leaving = false;
            }
            let closing = if leaving {
                clear < last - 1e-3 || travel_m > LEAVE_M
            } else {
                !(on_plan && travel_m >= SETTLE_M) && clear < required_m - 1e-6
            };
            if closing {
                let what =
                    if self.known.clearance_m(s.x_m, s.y_m, cutoff) - footprint <= clear + 1e-6 {
                        "a wall the twin knew"
                    } else {
                        "a block learnt from the robot"
                    };
                return Err(PipelineError::Infeasible(format!(
                    "the continuation comes within {clear:.3} m of {what} at ({:.2}, {:.2}) m, {:.1} s in; the robot's position is known to {sigma:.3} m that way (one standard deviation, refined against the twin's map), and a continuation keeps three of them ({:.3} m) clear of everything the twin knows where it leaves the plan, and moves away from what it stands near",
                    s.x_m,
                    s.y_m,
                    s.t_s - t0,
                    3.0 * sigma,
                )));
            }
            last = last.max(clear);
        }
        Ok(())
    }
}

/// A continuation's first metre of driving keeps three standard deviations
/// of the hand-back pose on the plan's path too: by then the robot has
/// localized again.
pub const SETTLE_M: f64 = 1.0;

/// A continuation that starts nearer than that to something is clear of it
/// within this much driving (m).
pub const LEAVE_M: f64 = 0.3;

/// How continuations are made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContinuationSettings {
    pub detour: DetourSettings,
    /// The share of the robot's wheel speed and acceleration limits the
    /// continuation is timed for.
    pub pace: f64,
}

impl Default for ContinuationSettings {
    fn default() -> Self {
        Self {
            detour: DetourSettings::default(),
            pace: 0.5,
        }
    }
}

/// Single-linkage clusters of points within `cluster_m`, each as one
/// block: the union of its points' boxes, each point's box `depth_m` deep
/// behind the face it lies on (away from where it was seen from, across the
/// axis its sight line mostly runs along) and `grow_m` wide along it.
///
/// A block is then cut back by every sight line through it that passes
/// none of its points (the guessed part of a contact's block, or a grown
/// edge, that a reading went through). Each block comes with its points.
fn clusters(
    evidence: &[Evidence],
    free: &[Ray],
    settings: &LearnSettings,
) -> Vec<(Block, Vec<[f64; 2]>)> {
    let n = evidence.len();
    let mut label: Vec<Option<usize>> = vec![None; n];
    let mut blocks = Vec::new();
    for start in 0..n {
        if label[start].is_some() {
            continue;
        }
        label[start] = Some(blocks.len());
        let mut stack = vec![start];
        let mut members = Vec::new();
        let mut block = point_box(&evidence[start], settings);
        while let Some(i) = stack.pop() {
            members.push(evidence[i].point);
            let b = point_box(&evidence[i], settings);
            block = (
                [block.0[0].min(b.0[0]), block.0[1].min(b.0[1])],
                [block.1[0].max(b.1[0]), block.1[1].max(b.1[1])],
            );
            let p = evidence[i].point;
            for j in 0..n {
                let q = evidence[j].point;
                if label[j].is_none() && (q[0] - p[0]).hypot(q[1] - p[1]) <= settings.cluster_m {
                    label[j] = Some(blocks.len());
                    stack.push(j);
                }
            }
        }
        for ray in free {
            block = cut(block, &members, ray);
        }
        blocks.push((block, members));
    }
    blocks
}

/// `block` cut back so that `ray` no longer passes through it, keeping every
/// point of `members` and as much of it as can be: along one axis, the slab
/// the ray crosses and everything beyond it on the side without points is
/// taken off. Unchanged when the ray misses it or runs between its points.
fn cut((min, max): Block, members: &[[f64; 2]], &(a, b): &Ray) -> Block {
    // The part of the ray inside the block (Liang-Barsky).
    let d = [b[0] - a[0], b[1] - a[1]];
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..2 {
        if d[k] == 0.0 {
            if a[k] <= min[k] || a[k] >= max[k] {
                return (min, max);
            }
            continue;
        }
        let (u, v) = ((min[k] - a[k]) / d[k], (max[k] - a[k]) / d[k]);
        t0 = t0.max(u.min(v));
        t1 = t1.min(u.max(v));
    }
    if t0 >= t1 {
        return (min, max);
    }
    let p = [a[0] + t0 * d[0], a[1] + t0 * d[1]];
    let q = [a[0] + t1 * d[0], a[1] + t1 * d[1]];
    let mut best: Option<(f64, Block)> = None;
    for k in 0..2 {
        let (lo, hi) = (p[k].min(q[k]), p[k].max(q[k]));
        let options = [
            (members.iter().all(|m| m[k] >= hi), true, hi),
            (members.iter().all(|m| m[k] <= lo), false, lo),
        ];
        for (valid, keep_above, at) in options {
            let (mut nmin, mut nmax) = (min, max);
            if keep_above {
                nmin[k] = at;
            } else {
                nmax[k] = at;
            }
            let area = (nmax[0] - nmin[0]) * (nmax[1] - nmin[1]);
            if valid && nmax[k] > nmin[k] && best.is_none_or(|(b, _)| area > b) {
                best = Some((area, (nmin, nmax)));
            }
        }
    }
    best.map_or((min, max), |(_, b)| b)
}

/// The box one obstacle point stands for (see [`cluster`]).
fn point_box(e: &Evidence, settings: &LearnSettings) -> Block {
    let p = e.point;
    let sight = [p[0] - e.seen_from[0], p[1] - e.seen_from[1]];
    let across = usize::from(sight[1].abs() > sight[0].abs());
    let (mut min, mut max) = (p, p);
    let (grow, depth) = if e.contact {
        (settings.contact_grow_m, settings.contact_depth_m)
    } else {
        (settings.grow_m, settings.depth_m)
    };
    if sight[across] > 0.0 {
        max[across] += depth;
    } else {
        min[across] -= depth;
    }
    min[1 - across] -= grow;
    max[1 - across] += grow;
    (min, max)
}

/// `block` cut back until it keeps `margin_m` from everything in `known`,
/// keeping as many of its points `members` as can be, then as much of its
/// area. The block is sampled on a grid of at most [`KNOWN_STEP_M`] that
/// spans it (a sample nearer than the margin and half the grid's diagonal
/// is too near: then so may be the ground around it); the slab from the
/// too-near sample nearest its points outwards is taken off, along the
/// axis and to the side that keep the most, until none is left in it; the
/// block left is sampled again, until one has none. `None` when nothing
/// is left.
fn clip_off_known(
    (mut min, mut max): Block,
    members: &[[f64; 2]],
    known: &World,
    margin_m: f64,
) -> Option<Block> {
    let near_m = margin_m + KNOWN_STEP_M * std::f64::consts::FRAC_1_SQRT_2;
    let inside = |p: &[f64; 2], min: [f64; 2], max: [f64; 2]| {
        (0..2).all(|k| min[k] <= p[k] && p[k] <= max[k])
    };
    // Each round cuts at least a step off: the rounds end.
    loop {
        let steps = |k: usize| ((max[k] - min[k]) / KNOWN_STEP_M).ceil().max(1.0) as usize;
        let (nx, ny) = (steps(0), steps(1));
        let mut near = Vec::new();
        for i in 0..=nx {
            for j in 0..=ny {
                let p = [
                    min[0] + (max[0] - min[0]) * i as f64 / nx as f64,
                    min[1] + (max[1] - min[1]) * j as f64 / ny as f64,
                ];
                if known.clearance_m(p[0], p[1], near_m) < near_m {
                    near.push(p);
                }
            }
        }
        if near.is_empty() {
            return Some((min, max));
        }
        while !near.is_empty() {
            let kept: Vec<[f64; 2]> = members
                .iter()
                .filter(|p| inside(p, min, max))
                .copied()
                .collect();
            let to_kept = |p: &[f64; 2]| {
                kept.iter()
                    .map(|m| (m[0] - p[0]).hypot(m[1] - p[1]))
                    .fold(f64::INFINITY, f64::min)
            };
            let worst = near
                .iter()
                .map(|p| (to_kept(p), *p))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, p)| p)?;
            // The cut keeping the most points, then the most area.
            let mut best: Option<((usize, f64), Block)> = None;
            for k in 0..2 {
                for above in [true, false] {
                    let (mut nmin, mut nmax) = (min, max);
                    if above {
                        nmin[k] = worst[k] + KNOWN_STEP_M;
                    } else {
                        nmax[k] = worst[k] - KNOWN_STEP_M;
                    }
                    if nmax[k] <= nmin[k] {
                        continue;
                    }
                    let count = kept.iter().filter(|p| inside(p, nmin, nmax)).count();
                    let area = (nmax[0] - nmin[0]) * (nmax[1] - nmin[1]);
                    if best.is_none_or(|((c, a), _)| (count, area) > (c, a)) {
                        best = Some(((count, area), (nmin, nmax)));
                    }
                }
            }
            (min, max) = best?.1;
            near.retain(|p| inside(p, min, max));
        }
    }
}

/// The largest spacing a block is sampled at for its distance from what
/// the twin knew (m).
const KNOWN_STEP_M: f64 = 0.01;

/// Distance from `p` to the segment `a`-`b`.
fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let s = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a[0] + s * dx - p[0]).hypot(a[1] + s * dy - p[1])
}

/// Moves the face of `block` nearest to `centre` back until the disc of
/// `radius` around `centre` is clear of it; `None` if nothing is left.
fn clip_clear_of((mut min, mut max): Block, centre: [f64; 2], radius: f64) -> Option<Block> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use twindrive_link::wire::WindowSample;

    /// The blocks of [`clusters`] alone.
    fn cluster(evidence: &[Evidence], free: &[Ray], settings: &LearnSettings) -> Vec<Block> {
        clusters(evidence, free, settings)
            .into_iter()
            .map(|(b, _)| b)
            .collect()
    }

    /// A hand-back whose window holds what the site's sensors read at `poses`.
    fn handback(site: &Scenario, poses: &[Pose]) -> Handback {
        let mut model = SensorModel::new(site);
        let mut ranges = vec![0.0; model.beams()];
        let window = poses
            .iter()
            .map(|p| {
                let bump = model.read(p, &mut ranges);
                WindowSample {
                    plan_t_s: 0.0,
                    pose: [p.x_m, p.y_m, p.heading_rad],
                    ranges_m: ranges.iter().map(|&r| r as f32).collect(),
                    bump,
                }
            })
            .collect();
        let last = poses.last().unwrap();
        Handback {
            plan: [0; 32],
            reason: "range_residual".into(),
            plan_t_s: 1.0,
            progress: 0,
            pose: [last.x_m, last.y_m, last.heading_rad],
            pose_covariance: [1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4],
            params: [0.0652, 0.0665, 0.2678],
            params_covariance: [1.0; 9],
            window,
        }
    }

    /// Drives westwards past the box's south face (the side IR looks at it)
    /// and on beyond its west edge.
    fn sweep(min: [f64; 2], max: [f64; 2]) -> Vec<Pose> {
        let mut poses = Vec::new();
        let y = min[1] - 0.3;
        let mut x = max[0] + 0.3;
        while x > min[0] - 0.6 {
            poses.push(Pose::new(x, y, std::f64::consts::PI));
            x -= 0.01;
        }
        poses
    }

    /// Random boxes the twin lacks, seen by the side IR from random
    /// distances: the learnt block's seen face is where the box's is (within
    /// the sensor's noise and a centimetre), and it never reaches towards
    /// the robot; a wrong point learnt earlier is removed once a reading
    /// passes through it.
    #[test]
    fn learnt_blocks_sit_on_the_faces_seen_and_free_readings_clear_wrong_ones() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let twin_site = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        for _ in 0..10 {
            let (w, h) = (rng.random_range(0.15..0.4), rng.random_range(0.15..0.4));
            let min = [rng.random_range(1.5..3.5), rng.random_range(0.7..1.0)];
            let max = [min[0] + w, min[1] + h];
            let mut site = twin_site.clone();
            site.world = site.world.with_blocks(&[(min, max)]);
            let mut twin = Twin::new(twin_site.clone(), twin_site.robot.true_params);
            // A wrong point first: a block in free space west of the box.
            let wrong = [min[0] - 0.45, min[1] + 0.05];
            twin.evidence.push(Evidence {
                point: wrong,
                seen_from: [wrong[0], wrong[1] - 0.3],
                contact: false,
            });
            twin.learnt = cluster(&twin.evidence, &[], &LearnSettings::default());
            twin.scenario.world = twin.known.with_blocks(&twin.learnt);
            let update = twin.apply(
                &handback(&site, &sweep(min, max)),
                &LearnSettings::default(),
            );
            assert!(update.evidence_points > 5, "{update:?}");
            let seen = twin
                .learnt
                .iter()
                .find(|b| b.0[0] < max[0] && b.1[0] > min[0])
                .unwrap_or_else(|| panic!("nothing learnt on {min:?}-{max:?}: {:?}", twin.learnt));
            assert!(
                (seen.0[1] - min[1]).abs() < 0.01,
                "south face at {} for {}",
                seen.0[1],
                min[1]
            );
            assert!(
                seen.0[0] >= min[0] - 0.05 && seen.1[0] <= max[0] + 0.05,
                "{seen:?}"
            );
            // The readings past the box's west edge went through the wrong
            // point: it is gone, and no block stands there.
            assert!(!twin.evidence.iter().any(|e| e.point == wrong));
            assert!(!twin.learnt.iter().any(|b| {
                b.0[0] <= wrong[0] && b.1[0] >= wrong[0] && b.0[1] <= wrong[1] && b.1[1] >= wrong[1]
            }));
            assert_eq!(update.obstacles_removed.len(), 1, "{update:?}");
            assert_eq!(update.evidence_removed, 1);
        }
    }

    /// A block learnt a few centimetres off from one side (the hand-back's
    /// pose was), then seen by a lidar from another, with sight lines that
    /// run along the face it first saw: the twin still holds the whole box.
    /// A face seen again is evidence again, so readings that end beyond the
    /// old guess but on the box do not simply erase it. (Whole but for its
    /// edges: a face seen at a grazing angle is not seen to its very end,
    /// and a sight line past the end cuts the block back to the last point
    /// seen.)
    #[test]
    fn a_block_seen_again_from_elsewhere_still_holds_the_whole_box() {
        const EDGE_M: f64 = 0.04;
        let text = format!(
            "{}{}",
            twindrive_sim::builtin::WALL_FOLLOWING,
            r#"
[[range_sensors]]
name = "lidar"
kind = "lidar"
mount = { x_m = 0.0, y_m = 0.0, heading_rad = 0.0 }
beams = 181
fov_rad = 3.141592653589793
max_range_m = 4.0
noise_std_m = 0.01
rate_hz = 10.0
"#
        );
        let twin_site = Scenario::from_toml(&text, std::path::Path::new("<lidar>.toml")).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for _ in 0..10 {
            let (w, h) = (rng.random_range(0.15..0.3), rng.random_range(0.2..0.35));
            let min = [rng.random_range(1.8..3.3), rng.random_range(0.75..0.95)];
            let max = [min[0] + w, min[1] + h];
            let mut site = twin_site.clone();
            site.world = site.world.with_blocks(&[(min, max)]);
            let mut twin = Twin::new(twin_site.clone(), twin_site.robot.true_params);
            // The east face, learnt from the east, `off` too far east.
            let off = rng.random_range(0.015..0.03);
            let mut y = min[1];
            while y <= max[1] {
                twin.evidence.push(Evidence {
                    point: [max[0] + off, y],
                    seen_from: [max[0] + 0.9, y],
                    contact: false,
                });
                y += 0.01;
            }
            twin.learnt = cluster(&twin.evidence, &[], &LearnSettings::default());
            twin.scenario.world = twin.known.with_blocks(&twin.learnt);
            // Then the lidar, standing south-east of it and facing west.
            let at = Pose::new(
                max[0] + rng.random_range(0.05..0.15),
                min[1] - rng.random_range(0.25..0.35),
                std::f64::consts::PI,
            );
            twin.apply(&handback(&site, &[at; 5]), &LearnSettings::default());
            let inside = |p: [f64; 2]| {
                twin.learnt
                    .iter()
                    .any(|b| b.0[0] <= p[0] && p[0] <= b.1[0] && b.0[1] <= p[1] && p[1] <= b.1[1])
            };
            for i in 0..=10 {
                for j in 0..=10 {
                    let p = [
                        min[0] + EDGE_M + (w - 2.0 * EDGE_M) * f64::from(i) / 10.0,
                        min[1] + EDGE_M + (h - 2.0 * EDGE_M) * f64::from(j) / 10.0,
                    ];
                    assert!(
                        inside(p),
                        "{p:?} of the box {min:?}-{max:?} is in no learnt block: {:?}",
                        twin.learnt
                    );
                }
            }
        }
    }
}
