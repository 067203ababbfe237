//! Whether a plan that arrived whole is driven: the gate (signature,
//! counter, expiry), the robot and site it was made for, and where it
//! starts.

use std::sync::Arc;

use serde_json::json;
use twindrive_link::wire::{PlanPhase, TransferId};
use twindrive_mission::plan::{MissionPlan, hex};

use super::{RobotAgent, START_HEADING_RAD, pose3};
use crate::backend::RobotBackend;
use crate::store::RobotStore;

impl<B: RobotBackend, S: RobotStore> RobotAgent<B, S> {
    /// A whole plan file arrived: through the gate, or refused.
    pub(super) fn consider(&mut self, transfer: TransferId, file: Vec<u8>, now_ns: u64) {
        let now_unix = self.unix_now_s(now_ns);
        let checked = self
            .gate
            .check(&file, self.last_counter, now_unix)
            .map_err(|r| r.to_string())
            .and_then(|accepted| {
                self.fits(&accepted.plan)?;
                self.at_start(&accepted.plan, &accepted.envelope.tolerances)?;
                Ok(accepted)
            });
        match checked {
            Err(reason) => {
                self.record(
                    now_ns,
                    "plan_rejected",
                    json!({ "transfer": hex(&transfer), "reason": reason }),
                );
                self.set_phase(transfer, PlanPhase::Rejected { reason });
            }
            Ok(accepted) => {
                let sha = accepted.plan.sha256.clone();
                let stored = self
                    .store
                    .store_plan(&sha, &accepted.plan_json)
                    .and_then(|()| self.store.store_counter(accepted.envelope.counter));
                if let Err(e) = stored {
                    let reason = format!("storing the plan: {e}");
                    self.record(
                        now_ns,
                        "plan_rejected",
                        json!({ "transfer": hex(&transfer), "reason": reason }),
                    );
                    self.set_phase(transfer, PlanPhase::Rejected { reason });
                    return;
                }
                self.last_counter = accepted.envelope.counter;
                self.record(
                    now_ns,
                    "plan_accepted",
                    json!({
                        "transfer": hex(&transfer),
                        "plan_sha256": sha,
                        "counter": accepted.envelope.counter,
                        "samples": accepted.plan.samples.len(),
                        "path": format!("plans/{sha}.json"),
                    }),
                );
                let env = accepted.envelope;
                self.start(transfer, Arc::new(accepted.plan), &env, now_ns);
            }
        }
        self.next_status_ns = now_ns;
    }

    /// Whether a plan was made for this robot at this site: the site its
    /// twin copies, the encoder resolution and the range beams it predicts.
    fn fits(&self, plan: &MissionPlan) -> Result<(), String> {
        let me = self.backend.log_header();
        let robot = &plan.header.robot;
        if robot.scenario != me.scenario {
            return Err(format!(
                "the plan was rehearsed for site `{}`, this robot is at `{}`",
                robot.scenario, me.scenario
            ));
        }
        if robot.ticks_per_rev != me.ticks_per_rev {
            return Err(format!(
                "the plan is for encoders of {} ticks per revolution, this robot's have {}",
                robot.ticks_per_rev, me.ticks_per_rev
            ));
        }
        let sensors = |s: &[twindrive_log::RangeSensorInfo]| -> Vec<String> {
            s.iter()
                .map(|r| format!("{} ({}, {} beams)", r.name, r.kind, r.beams))
                .collect()
        };
        if sensors(&robot.range_sensors) != sensors(&me.range_sensors) {
            return Err(format!(
                "the plan predicts range sensors [{}], this robot has [{}]",
                sensors(&robot.range_sensors).join(", "),
                sensors(&me.range_sensors).join(", ")
            ));
        }
        Ok(())
    }

    /// Where the robot believes it is: its estimate at the end of the last
    /// plan it drove, or (before any) what its backend says (a simulated
    /// site's start, a ROS robot's pose or odometry).
    pub fn believed_pose(&self) -> [f64; 3] {
        if self.pose.iter().all(|v| v.is_finite()) {
            self.pose
        } else {
            pose3(&self.backend.log_header().start)
        }
    }

    /// Whether the robot stands where the plan starts: within the plan's
    /// deviation tolerance, and facing its way within [`START_HEADING_RAD`].
    /// A plan that starts elsewhere would be driven from the wrong place,
    /// every step off by the same offset: it is refused before anything
    /// moves, with what to do.
    fn at_start(
        &self,
        plan: &MissionPlan,
        tolerances: &crate::executive::Tolerances,
    ) -> Result<(), String> {
        let [x, y, heading] = self.believed_pose();
        let s = plan.header.start;
        let away_m = (x - s.x_m).hypot(y - s.y_m);
        let turn_rad = twindrive_kinematics::wrap_angle(heading - s.heading_rad).abs();
        if away_m <= tolerances.max_deviation_m && turn_rad <= START_HEADING_RAD {
            return Ok(());
        }
        Err(format!(
            "not at the plan's start: the robot is at ({x:.2}, {y:.2}) m heading {:.0} deg, the plan starts at ({:.2}, {:.2}) m heading {:.0} deg, {away_m:.2} m and {:.0} deg away (at most {:.2} m and {:.0} deg). Nothing moved. Bring the robot to the plan's start, or plan from where it stands (rehearse on the twin from this pose)",
            heading.to_degrees(),
            s.x_m,
            s.y_m,
            s.heading_rad.to_degrees(),
            turn_rad.to_degrees(),
            tolerances.max_deviation_m,
            START_HEADING_RAD.to_degrees(),
        ))
    }
}
