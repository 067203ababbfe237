//! The executive on a site simulator: the case-study plan runs to its end on
//! a site like the twin; a box the twin lacks hands control back before the
//! robot drives through it; a supervised plan stops when the master falls
//! silent. Every stop is decided on the robot.

mod common;

use common::{plan, site, twin};
use twindrive_agent::backend::{RobotBackend, SimBackend};
use twindrive_agent::executive::{Executive, Stop, Tolerances};
use twindrive_agent::localize::LocalizeSettings;
use twindrive_agent::navigator::{Navigator, initial_estimate};
use twindrive_sim::Scenario;

/// Runs the executive until it stops (or `max_s`), hearing from the master
/// every `heard_every_s` if given. Returns the stop, the backend, and the
/// true poses after the stop.
fn run(
    site: Scenario,
    dead_man_s: Option<f64>,
    heard_every_s: Option<f64>,
    max_s: f64,
) -> (
    Option<(f64, Stop)>,
    SimBackend,
    Vec<twindrive_kinematics::Pose>,
    u64,
) {
    let plan = plan();
    let max_wheel = site.robot.max_wheel_speed_rad_s;
    let mut backend = SimBackend::new(site, plan.samples[0].pose(), max_s + 5.0).unwrap();
    let mut exec =
        Executive::new(plan.clone(), Tolerances::default(), dead_man_s, max_wheel).unwrap();
    let initial = initial_estimate(
        pose3(&plan.samples[0].pose()),
        None,
        &plan.header.calibrated,
    );
    let mut nav = Navigator::new(
        plan,
        initial,
        plan.header.robot.ticks_per_rev,
        LocalizeSettings::default(),
    );
    let mut after = Vec::new();
    let mut collisions = 0;
    let mut next_heard = 0.0;
    loop {
        // The master's word arrives between periods.
        let t_next = next_heard;
        let Some(reading) = backend.step(&mut |reading| {
            if heard_every_s.is_some() && reading.t_s >= t_next {
                exec.heard_from_master(reading.t_s);
            }
            let belief = nav.update(reading);
            exec.tick(reading, &belief)
        }) else {
            break;
        };
        if let Some(every) = heard_every_s
            && reading.t_s >= next_heard
        {
            next_heard += every;
        }
        if backend.blocked() {
            collisions += 1;
        }
        if exec.stopped().is_some() {
            after.push(backend.true_pose());
            if after.len() > 100 {
                break;
            }
        }
        if reading.t_s > max_s {
            break;
        }
    }
    (exec.stopped().cloned(), backend, after, collisions)
}

fn pose3(p: &twindrive_kinematics::Pose) -> [f64; 3] {
    [p.x_m, p.y_m, p.heading_rad]
}

#[test]
fn the_plan_runs_to_its_end_on_a_site_like_the_twin() {
    let plan = plan();
    let duration = plan.samples.last().unwrap().t_s - plan.samples[0].t_s;
    let (stop, backend, after, collisions) = run(twin(), None, None, duration + 20.0);
    let (t, stop) = stop.expect("stopped");
    assert_eq!(stop, Stop::Finished, "at {t} s");
    assert_eq!(collisions, 0);
    let end = plan.samples.last().unwrap().pose();
    let at = after[0];
    assert!(
        (at.x_m - end.x_m).hypot(at.y_m - end.y_m) < 0.1,
        "ended at {at:?}, plan ends at {end:?}"
    );
    assert!(backend.wheel_travel_rad() > 100.0);
}

#[test]
fn a_box_the_twin_lacks_hands_control_back_and_the_robot_stays_stopped() {
    // On the first leg (west along y = 1.05 m from x = 3 m).
    let box_world = "rectangles = [{ min = [1.9, 0.9], max = [2.1, 1.2] }]";
    let (stop, _, after, _) = run(site(box_world), None, None, 60.0);
    let (t, stop) = stop.expect("stopped");
    assert!(stop.is_handback(), "{stop:?} at {t} s");
    // Stopped before driving through: still east of the box.
    let at = after[0];
    assert!(at.x_m > 2.1, "stopped at {at:?}");
    // And stays where it stopped.
    let last = after.last().unwrap();
    assert!(
        (last.x_m - at.x_m).hypot(last.y_m - at.y_m) < 0.02,
        "{at:?} -> {last:?}"
    );
}

#[test]
fn a_supervised_plan_stops_when_the_master_falls_silent() {
    let (stop, _, _, _) = run(twin(), Some(1.0), None, 30.0);
    let (t, stop) = stop.expect("stopped");
    assert!(matches!(stop, Stop::DeadMan { .. }), "{stop:?}");
    assert!((1.0..1.2).contains(&t), "stopped at {t} s");

    // Heard every half second: no dead-man stop in 10 s.
    let (stop, _, _, _) = run(twin(), Some(1.0), Some(0.5), 10.0);
    assert!(stop.is_none(), "{stop:?}");
}
