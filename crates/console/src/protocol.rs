//! What the page sends (one JSON object per WebSocket text message) and
//! how a bad one is answered.

use serde::Deserialize;
use twindrive_mission::freedom::FreedomSettings;
use twindrive_mission::goals::Goals;
use twindrive_mission::plan::KeepOutZone;
use twindrive_mission::redundancy::RedundancyConfig;

/// A command from the page.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Drive the twin by hand: `forward` and `turn` in [-1, 1] of its
    /// limits. A dead-man: it lapses unless sent again within 0.4 s.
    Drive {
        forward: f64,
        turn: f64,
    },
    /// Stop the twin's robot (and its wall follower).
    Stop,
    /// Hand the twin's robot to the wall follower.
    WallFollow,
    /// Plan the way from where the twin's robot stands through the goals'
    /// waypoints and areas, out of `keep_out` (the zones on the page; the
    /// last plan's when left out); with `drive`, send the robot along it,
    /// recording a rehearsal that ends at the last stop.
    Goals {
        goals: Goals,
        #[serde(default)]
        drive: bool,
        #[serde(default)]
        keep_out: Option<Vec<KeepOutZone>>,
    },
    /// Forget the way to the goals (and why there was none).
    GoalsClear,
    /// Simulated time per real time.
    Speed {
        factor: f64,
    },
    /// Back to the start pose, idle; drops a recording in progress.
    Reset,
    /// Put the robot here; later resets come back here.
    Place {
        x_m: f64,
        y_m: f64,
        heading_rad: f64,
    },
    RecordStart,
    RecordStop,
    /// Run the pipeline on the rehearsal, with these redundancy settings
    /// (keep regions and time windows included) and this freedom for the
    /// robot (keep-out zones, corridor regions, detour bounds), or the last
    /// ones.
    Plan {
        #[serde(default)]
        redundancy: Option<RedundancyConfig>,
        #[serde(default)]
        freedom: Option<FreedomSettings>,
    },
    /// Replay the plan open and closed loop on the twin.
    Verify,
    /// Sign the plan for `robot` and upload it; only a plan that passed
    /// verification, unless `force` (the operator insists; logged).
    Upload {
        robot: String,
        #[serde(default)]
        force: bool,
    },
    /// After a hand-back: continue with a plan rehearsed on the updated
    /// twin.
    Replan {
        robot: String,
    },
    /// After a hand-back: end the mission there.
    EndMission {
        robot: String,
    },
    /// Which robot's detail (series, hand-back, logs) this page wants.
    Focus {
        robot: Option<String>,
    },
}

/// Parses one message from the page; the error says what was wrong and
/// what was expected.
pub fn parse(text: &str) -> Result<Command, String> {
    if text.len() > 1 << 20 {
        return Err(format!(
            "a command of {} bytes; at most 1 MiB is accepted",
            text.len()
        ));
    }
    serde_json::from_str(text).map_err(|e| {
        format!(
            "not a console command ({e}); expected a JSON object with `cmd` one of drive, stop, \
             wall_follow, goals, goals_clear, speed, reset, place, record_start, record_stop, plan, verify, upload, \
             replan, end_mission, focus"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse() {
        assert_eq!(
            parse(r#"{"cmd":"drive","forward":0.5,"turn":-1}"#),
            Ok(Command::Drive {
                forward: 0.5,
                turn: -1.0
            })
        );
        assert_eq!(parse(r#"{"cmd":"stop"}"#), Ok(Command::Stop));
        assert_eq!(parse(r#"{"cmd":"goals_clear"}"#), Ok(Command::GoalsClear));
        let goals = parse(
            r#"{"cmd":"goals","drive":true,"goals":{"clearance_m":0.05,
                "waypoints":[{"x_m":1,"y_m":2},{"x_m":3,"y_m":4,"heading_rad":1.5}]}}"#,
        )
        .unwrap();
        let Command::Goals { goals, drive, .. } = goals else {
            panic!("{goals:?}")
        };
        assert!(drive);
        assert_eq!(goals.clearance_m, 0.05);
        assert_eq!(goals.waypoints[1].heading_rad, Some(1.5));
        assert_eq!(
            parse(r#"{"cmd":"plan"}"#),
            Ok(Command::Plan {
                redundancy: None,
                freedom: None
            })
        );
        let zoned = parse(
            r#"{"cmd":"plan","freedom":{"max_extra_time_s":30,
                "keep_out":[{"name":"pond","polygon":[[0,0],[1,0],[1,1]]}],
                "corridor":[{"region":[[0,0],[2,0],[2,2]],"half_width_m":0.4}]}}"#,
        )
        .unwrap();
        let Command::Plan {
            freedom: Some(f), ..
        } = zoned
        else {
            panic!("{zoned:?}")
        };
        assert_eq!(f.keep_out[0].name, "pond");
        assert_eq!(f.corridor[0].half_width_m, 0.4);
        assert_eq!(f.max_extra_time_s, 30.0);
        assert_eq!(
            f.max_extra_distance_m, 5.0,
            "unsaid fields keep their defaults"
        );
        let with = parse(
            r#"{"cmd":"plan","redundancy":{"pinch_distance_m":0.15,
                "keep_regions":[{"kind":"circle","x_m":1,"y_m":2,"radius_m":0.5}]}}"#,
        )
        .unwrap();
        let Command::Plan {
            redundancy: Some(r),
            ..
        } = with
        else {
            panic!("{with:?}")
        };
        assert_eq!(r.keep_regions.len(), 1);
        assert_eq!(
            parse(r#"{"cmd":"upload","robot":"r1"}"#),
            Ok(Command::Upload {
                robot: "r1".into(),
                force: false
            })
        );
    }

    #[test]
    fn garbage_gets_a_clear_error() {
        for bad in [
            "",
            "nonsense",
            "[]",
            r#"{"cmd":"fly"}"#,
            r#"{"cmd":"drive","forward":"fast","turn":0}"#,
            r#"{"cmd":"drive","forward":1}"#,
            r#"{"cmd":"drive","forward":1,"turn":0,"extra":1}"#,
            r#"{"cmd":"plan","redundancy":{"pinch_distance_m":"x"}}"#,
            r#"{"cmd":"plan","freedom":{"keep_out":[{"name":"a","polygon":"here"}]}}"#,
            r#"{"cmd":"plan","freedom":{"max_extra_time":3}}"#,
        ] {
            let e = parse(bad).unwrap_err();
            assert!(e.contains("not a console command"), "{bad}: {e}");
        }
        let big = format!(r#"{{"cmd":"stop","x":"{}"}}"#, "a".repeat(2 << 20));
        assert!(parse(&big).unwrap_err().contains("at most 1 MiB"));
    }
}
