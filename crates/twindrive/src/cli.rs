//! Command-line arguments (clap derive). Checked and resolved into typed
//! configuration by each command before any work starts.

use std::path::PathBuf;

use clap::{Parser, Subcommand, ValueEnum};

use crate::usage;

/// Operate differential-drive robots over slow, lossy links through a digital twin.
#[derive(Debug, Parser)]
#[command(name = "twindrive", version, about, propagate_version = true)]
pub struct Args {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a scenario on the twin and write its mission log and figures.
    ///
    /// Writes log.csv, log.meta.json, log.mcap, ground_truth.tum,
    /// summary.json and figures (path, wheel_speeds, side_ir as SVG and PNG)
    /// into DIR. Files are staged beside DIR and moved in only when all are
    /// written; a failed move puts back the previous files. Files in DIR that
    /// twindrive did not write are never replaced.
    Simulate {
        /// Scenario TOML file.
        scenario: PathBuf,
        /// Output directory (created if missing; files twindrive did not write are kept).
        #[arg(long)]
        out: PathBuf,
        /// Override the scenario's random seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Override the scenario's duration, in seconds.
        #[arg(long, value_name = "SECONDS", value_parser = usage::seconds)]
        duration_s: Option<f64>,
    },
    /// Rehearse from goals: plan the way from the scenario's start through
    /// the waypoints of --goals on the twin's map, drive it on the twin and
    /// write the mission log a manual rehearsal would.
    ///
    /// GOALS (`mission.toml`): `clearance_m` (0.1: the footprint kept clear
    /// of everything by this), `speed_m_s` (0.2), and an ordered
    /// `[[waypoints]]` list of `x_m`, `y_m` and optionally `heading_rad`
    /// (turn to it there), `dwell_s` (stand there) and `speed_m_s` (the leg
    /// to there at most this fast); the last is the goal; then `[[areas]]`
    /// to sweep, in order (`polygon`, `sweep_radius_m`: default the
    /// footprint, `overlap`: 0.1): lanes back and forth along each area's
    /// longest edge, then touch-ups for the ground the lanes left, and the
    /// share of its free ground the twin swept is printed. The way is the
    /// shortest for the robot's footprint on a 5 cm grid of the twin's map
    /// keeping the clearance (A*, then straight legs by line of sight), out
    /// of the keep-out zones of --freedom; the twin's robot turns in place
    /// at each corner and drives each leg straight. Writes into DIR what
    /// `simulate` writes (log, ground truth, summary, figures) and
    /// route.json (the way, its length, clearance and time). A waypoint
    /// that cannot be reached is refused with the reason (off the site, too
    /// close to something, or closed off, with the cell that blocks the
    /// way): exit 1 and nothing written.
    Rehearse {
        /// The twin's scenario TOML (its world, its robot and its start).
        scenario: PathBuf,
        /// The goals (mission.toml).
        #[arg(long, value_name = "GOALS.toml")]
        goals: PathBuf,
        /// Keep-out zones (a --freedom file of `twindrive plan`; its
        /// `[[keep_out]]` zones are walls to the way).
        #[arg(long, value_name = "FREEDOM.toml")]
        freedom: Option<PathBuf>,
        /// Print the way (JSON) and exit without driving it or writing.
        #[arg(long)]
        route_only: bool,
        /// Output directory (created if missing; files twindrive did not write are kept).
        #[arg(long, required_unless_present = "route_only")]
        out: Option<PathBuf>,
        /// Override the scenario's random seed.
        #[arg(long)]
        seed: Option<u64>,
    },
    /// Estimate wheel diameters and wheelbase from encoders and an absolute
    /// pose, or with no pose reference (self-calibration) the wheels, the
    /// lidar's mount and a gyro's errors from encoders, scans and gyro.
    ///
    /// Input: a simulator output directory (log.csv + log.meta.json), or
    /// --encoders E.csv (`t,left_ticks,right_ticks` cumulative counts, or
    /// `t,left_rad_s,right_rad_s`) with --poses P.csv (`t,x,y,theta`; theta
    /// may be empty for position-only references), or --bag BAG (a rosbag2
    /// recording, MCAP or sqlite3: JointState wheels or a tick topic, and a
    /// PoseStamped, Odometry or TF reference). Self-calibration: a
    /// simulator log with a lidar and no --poses, or --bag BAG with
    /// --scan-topic (and --imu-topic for a gyro) and no pose topic. A
    /// calibration the data do not support (too few reference poses
    /// accepted, most rejected, or motion that leaves a parameter unpinned)
    /// exits 1 and writes nothing.
    /// Writes --out (JSON) and,
    /// beside it, figures of each parameter over time with its ±3σ band and
    /// of the innovations, and TUM trajectories of the reference and of dead
    /// reckoning with the initial and calibrated parameters.
    Calibrate(Box<CalibrateArgs>),
    /// Draw the site's map from a drive's lidar scans and its motion.
    ///
    /// Input: a simulator output directory with a lidar, or --bag BAG with
    /// --scan-topic and the robot's motion: its own odometry (--odom-topic:
    /// a nav_msgs/msg/Odometry topic such as /odom, or TF odom -> base; no
    /// calibration needed), or the wheel joints of a JointState topic or
    /// the wheel speeds of two std_msgs/msg/Float64 topics (or two elements
    /// of a Float64MultiArray) with --calibration (the wheels, and the
    /// lidar's mount when it is a self-calibration) or the nominal
    /// --wheel-diameter-m and --wheelbase-m, or --carmen LOG: a CARMEN log (.clf, .clf.gz, as
    /// the 2D SLAM benchmark publishes them), read directly, with the
    /// robot's odometry it carries. The lidar's mount is otherwise the
    /// recording's (/tf_static in a bag, the laser lines' laser pose on the
    /// robot in a CARMEN log). --until-s T maps only the first T seconds.
    /// The motion predicts each scan's pose; the SLAM matches it against
    /// a submap of the last few metres, and searches for it in the submaps
    /// drawn earlier (loop closure, tolerating metres of drift), so a drive
    /// that comes back to where it started does not draw the walls twice:
    /// the map is drawn from the optimized poses. Writes into --out a ROS map_server map
    /// (map.pgm, map.yaml: occupancy from log-odds, unknown where no beam
    /// reached), site.toml (a scenario on that map that simulate, plan,
    /// verify-plan, console and robot take as the twin's site), poses.tum
    /// (the drive in the map, each pose stamped with its scan's own time on
    /// the recording's clock: `twindrive relations` scores it) and
    /// map_report.json. The map's frame is the log's (its start pose), or
    /// the robot's first pose in a bag or a CARMEN log.
    ///
    /// Not mapped (an error that says which): a recording without a
    /// LaserScan topic, or with neither odometry nor wheel joints nor wheel
    /// speeds, and a log without a
    /// lidar of at least 30 beams. `twindrive bag info` suggests the
    /// command line for what a bag has.
    Map(Box<MapArgs>),
    /// Turn a mission run on the twin into a plan for the real robot.
    ///
    /// The executed path from the log's encoders and the calibrated
    /// parameters; redundancy (retraced loops, bump-and-back-up kinks, a
    /// trailing retrace) removed without dropping explored ground; wheel
    /// speeds re-computed; control spikes filtered within the robot's wheel
    /// limits; the twin's site map (its walls and blocks), which the robot
    /// localizes against and predicts its readings from. Writes --out
    /// (versioned JSON with a SHA-256 over its content) and beside it
    /// <stem>.csv, <stem>.tum, <stem>_stages.mcap (every stage, for
    /// Foxglove) and the figures <stem>_executed (pinch points),
    /// <stem>_cleaned (spikes), <stem>_filtered and <stem>_wheel_speeds.
    Plan(PlanArgs),
    /// Replay a plan on the twin's robot (hidden true parameters and noise).
    ///
    /// Open loop (the plan's wheel speeds, and the same path's speeds through
    /// the operator's nominal parameters for comparison) and closed loop (a
    /// trajectory tracker on the robot's odometry). Writes
    /// report.json (collisions, bumps, max/mean deviation from the plan's
    /// path, duration, path length for each replay), the replayed tracks as
    /// TUM and an overlay figure into DIR. Exit status 0: the plan passed;
    /// 3: it failed verification (the report says why); 1: it could not be
    /// verified (a bad file); 2: a usage error.
    VerifyPlan {
        /// The plan JSON.
        plan: PathBuf,
        /// The twin's scenario TOML (default: the built-in scenario the plan names).
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Remove retraced loops, kinks and a trailing retrace from any path
    /// file and write the rest.
    ///
    /// PATH is a CSV with header `t,x,y,theta` or a TUM file. A cut may only
    /// delete samples within the coverage radius of the path that remains;
    /// where two passes cover the same ground the first is kept. Prints a
    /// summary: what was removed, the cuts refused for coverage counted by
    /// kind, and the coverage of the input by the output; -v prints, and
    /// --details FILE writes, each cut made and refused. --out is a CSV in
    /// the same columns.
    Prune(PruneArgs),
    /// Score a trajectory on the 2D SLAM benchmark's relations (Kümmerle et
    /// al., "On measuring the accuracy of SLAM algorithms", 2009).
    ///
    /// TRAJECTORY is a TUM file (`t x y z qx qy qz qw`, such as `map`'s
    /// poses.tum) stamped with the scans' own times; --relations FILE holds
    /// `t1 t2 x y z roll pitch yaw` per line (the benchmark's `.relations`).
    /// Each relation's error is the trajectory's relative pose
    /// T(t1)⁻¹ T(t2) minus the relation, per component. Prints the mean ±
    /// standard deviation (the sample's, n - 1) of the absolute and squared
    /// translational error (m, m²) and rotational error (deg, deg²), and how
    /// many relations matched: a relation counts only when the trajectory
    /// has a pose within 1 ms of both its stamps. Exit status 1 when none
    /// matched.
    Relations(RelationsArgs),
    /// Run the paper's case study end to end into ./twindrive-out/.
    ///
    /// The built-in calibration drive on the twin (calibration_drive/), its
    /// calibration (calibration/calib.json), the paper's Table 1 and Section
    /// 6 (evidence/), the wall-following mission (wall_following/), the plan
    /// made from it (plan/), its verification on the twin (verification/),
    /// the plan signed and sent over an emulated lunar link to a robot whose
    /// site has a box the twin lacks, with hand-backs, twin updates and
    /// continuations in virtual time (decoupled/), a short version of
    /// `experiment latency` (direct against decoupled operation at 0, 0.5
    /// and 2 s one way: experiment/), the twin built from the robot's own
    /// sensors on a site it has never seen (self-calibration from encoders,
    /// lidar and gyro, the site's map, the mission planned on the mapped
    /// twin and executed on the true site: mapped_site/), and report.md /
    /// report.html that tell the story with the figures.
    Demo {
        /// Output directory.
        #[arg(long, default_value = "twindrive-out")]
        out: PathBuf,
    },
    /// Write the office occupancy map (ROS map_server PGM + YAML) that the
    /// project draws itself into DIR.
    DrawMap {
        /// Directory for office.pgm and office.yaml.
        dir: PathBuf,
    },
    /// Make an ed25519 key pair: the master's, DIR/master.key (PKCS#8 PEM,
    /// mode 0600) and DIR/master.pub (public key PEM, for robots' --trust);
    /// with --robot ID a robot's, DIR/ID.key (its `robot --key`) and
    /// DIR/ID.pub (for the master's --trust-robot).
    ///
    /// The master's key signs plans; both seal every message between them.
    /// Refuses to replace an existing key.
    Keygen {
        /// Directory for the key pair (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Make robot ID's key pair instead of the master's.
        #[arg(long, value_name = "ID", value_parser = usage::robot_id)]
        robot: Option<String>,
    },
    /// Make a small certificate authority, certificates and zenoh
    /// configurations for a fleet over TLS with mutual authentication.
    ///
    /// Writes into DIR: ca.pem and ca.key (the CA: keep ca.key offline),
    /// router.pem/.key and router.json5 (TLS only, client certificates
    /// required, access control: each robot publishes only on
    /// twindrive/ID/down and subscribes only to twindrive/ID/up),
    /// master.pem/.key and master.json5, and for each robot ID.pem/.key and
    /// ID.json5 (clients of the router). Give a process its file with
    /// --zenoh-config. Private keys are mode 0600; DIR must be new or empty.
    Certs {
        /// Directory for the files (new or empty).
        #[arg(long)]
        out: PathBuf,
        /// A robot of the fleet; repeatable.
        #[arg(long = "robot", value_name = "ID", required = true, value_parser = usage::robot_id)]
        robots: Vec<String>,
        /// A name or address the router is reached at (its certificate is
        /// valid for each; clients connect to the first); repeatable.
        #[arg(long, value_name = "HOST", default_values_t = ["localhost".to_string(), "127.0.0.1".to_string()])]
        router_host: Vec<String>,
        /// The router's TLS port.
        #[arg(long, default_value_t = 7447)]
        port: u16,
        /// Certificates are valid for this many days.
        #[arg(long, default_value_t = 825, value_parser = clap::value_parser!(u32).range(1..=3650))]
        days: u32,
    },
    /// Sign a plan for one robot (on any machine, offline if need be).
    ///
    /// Writes a signed plan: an envelope (the plan's SHA-256s, robot id, a
    /// counter that only grows, validity window, the hash of the twin's
    /// world, the supervision policy) signed with ed25519, and the plan
    /// document compressed. A robot accepts it only if every part checks.
    Sign(SignArgs),
    /// Run the robot agent: receive signed plans over zenoh, drive them on
    /// the robot (a simulated site, or a ROS 2 robot when the site has a
    /// `[ros]` section) and hand control back when
    /// reality departs from the twin.
    ///
    /// Keeps its journal (journal.jsonl), accepted plans (plans/<sha256>.json),
    /// uploads in progress and its own logs in --state-dir, so a restart
    /// resumes an upload and never drives a plan twice. Runs until stopped
    /// (Ctrl-C) or --run-for.
    Robot(RobotArgs),
    /// Run the master: upload a plan to a robot (or to each of a fleet)
    /// over zenoh, supervise it, receive telemetry and the robot's log,
    /// handle hand-backs (update the twin; stop or replan) and write
    /// DIR/report.json and DIR/fleet.json (a fleet: DIR/ID/ per robot).
    ///
    /// Exits 0 when the mission completed, 3 when it ended handed back, 4
    /// when the robot rejected the plan, 1 when it failed (in a fleet, the
    /// worst robot's).
    Master(MasterArgs),
    /// The operator's console: an interactive master with a web page.
    ///
    /// Serves one page (every asset embedded: it works offline) at --listen
    /// and prints its address with an access token; every request needs the
    /// token and WebSocket upgrades must come from the console's own origin.
    /// On the page: drive the twin (arrows/WASD or the joystick, both
    /// dead-man; or the wall follower), record a rehearsal, run the
    /// pipeline on it and see each stage on the map, keep regions and
    /// times, verify on the twin, sign and upload to a robot (--robot, over
    /// zenoh, through --link's emulator), and supervise it: progress, link,
    /// stream ages, reported against predicted pose, residuals, hand-back
    /// banner, re-plan. Files go to --out (plans, rehearsals, robot logs,
    /// reports, console.token). Runs until Ctrl-C.
    Console(ConsoleArgs),
    /// Write a mission log as a rosbag2 recording (MCAP or sqlite3) that ROS 2 tools play.
    ///
    /// Standard types only: /joint_states (JointState), /odom (Odometry, dead
    /// reckoning with the nominal parameters), /ground_truth (Odometry),
    /// /tracker/pose (PoseStamped), /cmd_vel (Twist), /bump
    /// (irobot_create_msgs HazardDetectionVector), one Range (INFRARED) or
    /// LaserScan topic per range sensor, /imu (Imu, the gyro's yaw rate)
    /// when the log has a gyro, /tf (odom->base_link, map->odom),
    /// /tf_static (base_link-><sensor>_link, base_link->imu_link), /map
    /// (OccupancyGrid, latched) and /plan (Path, latched) with --plan.
    /// Writes DIR/metadata.yaml and DIR/<name>_0.mcap (or <name>_0.db3 with
    /// --storage sqlite3); `ros2 bag play DIR` plays it.
    Rosbag(RosbagArgs),
    /// Look into a rosbag2 recording.
    Bag {
        #[command(subcommand)]
        command: BagCommand,
    },
    /// Run a site's simulator behind a pipe, as a stand-in for a robot's
    /// hardware (scripts/ros/fake_driver.py puts ROS 2 drivers around it).
    ///
    /// Reads lines `LEFT_RAD_S RIGHT_RAD_S STEPS` on stdin; drives the site's
    /// robot that many simulation steps with those wheel speeds and answers
    /// each line with one JSON line: `t_s`, `wheel_rad` (cumulative wheel
    /// angles from the encoders), `wheel_rad_s`, `bump`, `blocked` (during
    /// those steps), `ranges_m` (the latest reading of every beam, null
    /// before the first), `pose` (the true pose, x y heading). Ends at end
    /// of input.
    SiteSim {
        /// The site scenario TOML.
        #[arg(long, value_name = "SITE.toml")]
        site: PathBuf,
    },
    /// Measure what decoupling buys: direct against decoupled operation
    /// over latency and loss, the upload against the link's ideal, and one
    /// master supervising a fleet through a zenoh router.
    Experiment {
        #[command(subcommand)]
        command: ExperimentCommand,
    },
    /// Run a zenoh router for a fleet: robots and masters connect to it
    /// (`--connect tcp/HOST:PORT`) instead of to each other.
    ///
    /// Listens where --listen says; without it, where --zenoh-config's
    /// listen.endpoints say (`twindrive certs`' router.json5: TLS on the
    /// port it was made for); with neither, on tcp/127.0.0.1:7447.
    Router {
        /// Endpoint to listen on, in place of the configuration's;
        /// repeatable (default without --zenoh-config: tcp/127.0.0.1:7447).
        #[arg(long, value_name = "ENDPOINT")]
        listen: Vec<String>,
        /// A zenoh JSON5 configuration file (its mode is set to router;
        /// certificate paths in it are relative to the file).
        #[arg(long, value_name = "FILE")]
        zenoh_config: Option<PathBuf>,
    },
}

#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// Direct tele-operation (a: the robot holds the last command; b: it
    /// zeroes its wheels after a timeout; c: move-and-wait) against
    /// decoupled operation, on the same robot site, seeds and link, over a
    /// grid of one-way latencies and losses, in virtual time.
    ///
    /// The twin rehearses the mission (default: the wall-following case
    /// study) and the plan's path is the intended route. The site is the
    /// twin with other true kinematics (wheel diameters x1.004 and x0.996,
    /// wheelbase x1.01) unless --site. Per run: completion time (upload
    /// included), collisions, bumps, time in contact, coverage of the route
    /// within --coverage-radius, path error against the route, bytes each
    /// way. Writes results.csv (one row per run), results.md (tables) and
    /// the figures completion_time, collisions and paths (SVG and PNG) into
    /// --out.
    Latency(LatencyExperimentArgs),
    /// Upload the office drive's lidar plan (52 kB signed), the case-study
    /// plan (110 kB) and a one-hour plan (5.8 MB) over each named profile at 0, 1, 10 and 30 % loss, and
    /// through a 60 s outage mid-upload, in virtual time; print the time
    /// until the robot holds the file against the ideal
    /// `D + S(1+h)/(B(1-p))`. The target: within 1.1x at loss up to 10 %.
    Upload(UploadExperimentArgs),
    /// One master supervising N robot agents through a zenoh router: the
    /// router, the master and N robot processes on loopback, each robot
    /// with its own site (the case study with other true kinematics), id
    /// and state directory; a plan uploaded to each and supervised to the
    /// end (a hand-back and a continuation each). Prints and writes
    /// (results.json) the master's CPU time and peak memory, the time to
    /// upload to all, the hand-back reaction time, telemetry against the
    /// budget and the logs back-filled; with --cost, the master's protocol
    /// cost per robot in virtual time as N grows.
    Fleet(FleetExperimentArgs),
    /// Decoupled operation as the site's kinematics depart from the twin's:
    /// the case study's plan, made with the twin's parameters, on sites
    /// whose true wheel diameters and wheelbase each differ by --errors
    /// (random signs per seed) and that have no tracker, for the paper's
    /// one-IR robot and the same robot with a 181-beam 2D lidar, with and
    /// without the demo's box the twin lacks, handing back on it or going
    /// around it inside the plan's corridor, localizing against the plan's
    /// map or on dead reckoning, over a link profile in virtual time. Per
    /// run: completed, completion time, hand-backs, contacts with what the
    /// twin knew and with what it did not, the true path's largest distance
    /// from the plan's. Writes results.csv and results.md into --out.
    Mismatch(MismatchExperimentArgs),
}

/// The robot's range sensors in `experiment mismatch`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SensorsArg {
    /// The paper's one side IR.
    Ir,
    /// The side IR and a 181-beam 2D lidar (4 m, 10 Hz).
    Lidar,
}

/// What the robot may do about an obstacle the twin lacks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AutonomyArg {
    /// The plan gives no corridor: the robot stops and hands back.
    Handback,
    /// The plan's corridor from the twin's clearance: a robot that can see
    /// ahead (the lidar) goes around inside it.
    Detour,
}

/// An unknown obstacle on the route, or none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ObstacleArg {
    None,
    /// The demo's box on the route, which the twin lacks.
    Box,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

#[derive(Debug, clap::Args)]
pub struct MismatchExperimentArgs {
    /// Output directory.
    #[arg(long, default_value = "twindrive-out/experiment-mismatch")]
    pub out: PathBuf,
    /// Kinematic errors (fractions: 0.01 is 1 %), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0,0.005,0.01,0.02,0.03", value_parser = usage::kinematic_error)]
    pub errors: Vec<f64>,
    /// The robot's sensors, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "ir,lidar")]
    pub sensors: Vec<SensorsArg>,
    /// What the robot may do about an obstacle the twin lacks,
    /// comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "handback,detour")]
    pub autonomy: Vec<AutonomyArg>,
    /// An unknown obstacle on the route, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "none,box")]
    pub obstacle: Vec<ObstacleArg>,
    /// Localization against the plan's map, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "on,off")]
    pub localization: Vec<OnOff>,
    /// Seeds per cell (the kinematic error's signs, the site's noise, the
    /// link's draws).
    #[arg(long, default_value_t = 1, value_parser = usage::count)]
    pub seeds: u64,
    /// The link profile (lan, wifi, satellite-lossy, lunar, mars-relay) with
    /// optional `key=value` overrides, e.g. `lunar,loss=0.1`.
    #[arg(long, default_value = "lunar")]
    pub profile: String,
    /// Give a run up after this long, seconds of mission time.
    #[arg(long, value_name = "SECONDS", default_value_t = 1_800.0, value_parser = usage::seconds)]
    pub max_duration: f64,
}

#[derive(Debug, clap::Args)]
pub struct FleetExperimentArgs {
    /// Output directory (results.json; runs/ holds each run's processes'
    /// files).
    #[arg(long, default_value = "twindrive-out/experiment-fleet")]
    pub out: PathBuf,
    /// Fleet sizes to run, comma-separated (at most 200).
    #[arg(long, value_delimiter = ',', default_value = "1,5,20,50", value_parser = usage::fleet_size)]
    pub robots: Vec<usize>,
    /// Run each robot's simulated site this many times faster than real time.
    #[arg(long, default_value_t = 1.0, value_parser = usage::time_scale)]
    pub time_scale: f64,
    /// Bytes per second each robot may send (its logs, ~1.8 MB for the
    /// case study, come back at 0.7 of it).
    #[arg(long, value_name = "BYTES_PER_S", default_value_t = 32000.0, value_parser = usage::telemetry_budget)]
    pub telemetry_budget: f64,
    /// Give a run up after this many seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 600.0, value_parser = usage::seconds)]
    pub timeout: f64,
    /// Emulate this link at the master on every robot's traffic (default:
    /// none, loopback as it is).
    #[arg(long, value_name = "PROFILE")]
    pub link: Option<String>,
    /// Also measure the master's protocol cost in virtual time for these
    /// fleet sizes, comma-separated (e.g. 1,10,100,1000).
    #[arg(long, value_delimiter = ',')]
    pub cost: Vec<usize>,
}

#[derive(Debug, clap::Args)]
pub struct LatencyExperimentArgs {
    /// Output directory.
    #[arg(long, default_value = "twindrive-out/experiment-latency")]
    pub out: PathBuf,
    /// The twin's scenario (its controller must be a wall follower).
    #[arg(long, value_name = "S.toml")]
    pub scenario: Option<PathBuf>,
    /// The robot's site (default: the twin with other true kinematics).
    #[arg(long, value_name = "SITE.toml")]
    pub site: Option<PathBuf>,
    /// The twin's calibration (from `twindrive calibrate`; default: the
    /// built-in calibration drive with the twin's robot, calibrated).
    #[arg(long, value_name = "CALIB.json")]
    pub calibration: Option<PathBuf>,
    /// One-way latencies, seconds, comma-separated.
    #[arg(long, default_value = "0,0.25,0.5,1,2,5")]
    pub latencies: String,
    /// Loss rates (fractions), comma-separated.
    #[arg(long, default_value = "0,0.1")]
    pub losses: String,
    /// Seeds per cell (the site's noise and the link's draws).
    #[arg(long, default_value_t = 3, value_parser = usage::count)]
    pub seeds: u64,
    /// The link's rate, bit/s, both ways.
    #[arg(long, value_name = "BIT_PER_S", default_value_t = 256_000.0, value_parser = usage::positive)]
    pub bandwidth: f64,
    /// Direct (b): wheels zeroed after this long without a command, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 0.5, value_parser = usage::seconds)]
    pub watchdog_timeout: f64,
    /// Direct (c): the length of one move, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 0.5, value_parser = usage::seconds)]
    pub move_s: f64,
    /// The route counts as covered within this distance of the robot, metres.
    #[arg(long, value_name = "METRES", default_value_t = 0.15, value_parser = usage::metres)]
    pub coverage_radius: f64,
    /// A direct run is complete once this share of the route is covered.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.9, value_parser = usage::fraction)]
    pub complete_at: f64,
    /// Give a run up after this long, seconds of mission time.
    #[arg(long, value_name = "SECONDS", default_value_t = 3_600.0, value_parser = usage::seconds)]
    pub max_duration: f64,
}

#[derive(Debug, clap::Args)]
pub struct UploadExperimentArgs {
    /// Also write results.csv and results.md here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seeds per row.
    #[arg(long, default_value_t = 5, value_parser = usage::count)]
    pub seeds: u64,
    /// A quick run (one 20 kB file, loss up to 10 %) that only checks it works.
    #[arg(long)]
    pub smoke: bool,
}

/// Where and how to reach the other side over zenoh.
#[derive(Debug, Clone, clap::Args)]
pub struct ZenohArgs {
    /// Listen on this zenoh endpoint (`tcp/0.0.0.0:7447`); repeatable.
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// Connect to this zenoh endpoint (the other process, or a router); repeatable.
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// A standard zenoh JSON5 configuration (client mode through a router,
    /// TLS with mutual authentication as `twindrive certs` writes it,
    /// timeouts; this build speaks TCP, UDP, TLS and QUIC); --listen and
    /// --connect replace its endpoints when given; certificate paths in
    /// it are relative to the file.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// While nothing answers at the endpoints to connect to (a router not
    /// up yet), try again every second for this long, then exit 1 with
    /// what was tried.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0, value_parser = usage::seconds)]
    pub connect_timeout: f64,
}

#[derive(Debug, clap::Args)]
pub struct RobotArgs {
    /// This robot's id (the key expressions are twindrive/ID/up and /down).
    #[arg(long, value_name = "ID", value_parser = usage::robot_id)]
    pub id: String,
    /// The site: the scenario the robot's simulator backend runs (its true
    /// kinematics, noise and world, which the master never sees); with a
    /// `[ros]` section, the robot is a ROS 2 robot driven through its own
    /// drivers over rmw_zenoh, and the scenario describes it.
    #[arg(long, value_name = "SITE.toml")]
    pub site: PathBuf,
    /// A master's public key (from `twindrive keygen`) whose plans this
    /// robot accepts; repeatable.
    #[arg(long, value_name = "master.pub", required = true)]
    pub trust: Vec<PathBuf>,
    /// This robot's private key (`twindrive keygen --robot ID`): every
    /// message to and from a trusted master is sealed with it; its public
    /// half goes to the master's --trust-robot.
    #[arg(long, value_name = "ID.key")]
    pub key: PathBuf,
    /// The robot's durable state (journal, plans, uploads, logs, the
    /// link's epochs).
    #[arg(long, value_name = "DIR")]
    pub state_dir: PathBuf,
    #[command(flatten)]
    pub zenoh: ZenohArgs,
    /// Bytes per second the robot may send (status, hand-back, log back-fill).
    #[arg(long, value_name = "BYTES_PER_S", default_value_t = 8000.0, value_parser = usage::telemetry_budget)]
    pub telemetry_budget: f64,
    /// Run the simulated site this many times faster than real time (1 for
    /// a ROS 2 robot).
    #[arg(long, default_value_t = 1.0, value_parser = usage::time_scale)]
    pub time_scale: f64,
    /// Exit after this many seconds (default: run until stopped).
    #[arg(long, value_name = "SECONDS", value_parser = usage::seconds)]
    pub run_for: Option<f64>,
    /// Localize against the map each plan carries (`on`), or drive by
    /// odometry and any tracker alone (`off`: how robots drove before plans
    /// carried maps; the fleet experiment's robots, whose hand-backs it
    /// times).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = ["on", "off"])]
    pub localization: String,
}

#[derive(Debug, clap::Args)]
pub struct MasterArgs {
    /// The plan JSON to sign and send (with --key).
    #[arg(long, value_name = "PLAN.json", conflicts_with = "signed")]
    pub plan: Option<PathBuf>,
    /// The master's private key: signs --plan and every continuation, and
    /// seals every message to and from the robots.
    #[arg(long, value_name = "master.key")]
    pub key: PathBuf,
    /// A robot's public key (`twindrive keygen --robot ID` wrote ID.pub:
    /// the file's name is the robot's id), or a directory of them (every
    /// ID.pub in it but master.pub); repeatable. Every --robot needs one;
    /// messages from any other key are refused.
    #[arg(long, value_name = "ID.pub|DIR", required = true)]
    pub trust_robot: Vec<PathBuf>,
    /// Where the master keeps each robot link's epochs (what makes a
    /// replay refused across restarts); default: link-state/ beside --key.
    #[arg(long, value_name = "DIR")]
    pub link_state: Option<PathBuf>,
    /// A plan signed beforehand (`twindrive sign`).
    #[arg(long, value_name = "PLAN.signed", required_unless_present = "plan")]
    pub signed: Option<PathBuf>,
    /// The robot to send it to; repeat for a fleet (one master, one
    /// session, each robot its own operator and twin and its files in
    /// --out/ID/, with --out/fleet.json; needs --plan and --key).
    #[arg(long, value_name = "ID", required = true, value_parser = usage::robot_id)]
    pub robot: Vec<String>,
    /// Output directory (report.json, plans, the robot's logs).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub zenoh: ZenohArgs,
    /// Emulate this link on all traffic with the robot, both ways: a
    /// profile (lan, wifi, satellite-lossy, lunar, mars-relay) with optional
    /// `key=value` overrides, e.g. `lunar,loss=0.1,outage=20..80`.
    #[arg(long, value_name = "PROFILE")]
    pub link: Option<String>,
    /// Seed of the link emulator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Plans this master signs are valid for this long, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 86_400)]
    pub expires_in: u64,
    /// Plans this master signs stop the robot when it has heard nothing
    /// for this long, seconds (default: unsupervised).
    #[arg(long, value_name = "SECONDS", value_parser = usage::seconds)]
    pub supervise: Option<f64>,
    /// What to do when the robot hands control back.
    #[arg(long, value_enum, default_value_t = OnHandbackArg::Stop)]
    pub on_handback: OnHandbackArg,
    /// The twin's scenario (default: the built-in one the plan names).
    #[arg(long, value_name = "S.toml")]
    pub scenario: Option<PathBuf>,
    /// Keep the twin's map of its site here across missions: the twin runs
    /// on the latest version kept (DIR/<site>/NNNN/site.toml), and after
    /// the mission the robot's logs (their lidar scans) extend the map into
    /// the next version. The site is --scenario's, on a map_server map (as
    /// `twindrive map` writes it).
    #[arg(long, value_name = "DIR", requires = "scenario")]
    pub site_maps: Option<PathBuf>,
    /// Give up (outcome `failed`) after this many seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 3_600.0, value_parser = usage::seconds)]
    pub timeout: f64,
    /// Bytes per second the robot may send this master (status, hand-back,
    /// log back-fill); the robot keeps to the lower of this and its own
    /// --telemetry-budget.
    #[arg(long, value_name = "BYTES_PER_S", default_value_t = 8000.0, value_parser = usage::telemetry_budget)]
    pub telemetry_budget: f64,
    /// Once the mission is decided, wait this long for the robot's next log
    /// (the wait starts again with each log received), seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 120.0, value_parser = usage::seconds_or_zero)]
    pub log_wait: f64,
    /// Once the digests of the robot's logs are in, ask it for every
    /// executed plan's full-rate log too (the whole MCAP it keeps in its
    /// --state-dir, every range sweep; written as robot_logs/NN_SHA_full/)
    /// and wait for them. They cost the link far more than the digests.
    #[arg(long)]
    pub full_logs: bool,
    /// Send the plan even if it fails verification on the twin (its open-
    /// or closed-loop replay touches something or departs from the plan's
    /// path by more than the robot's deviation tolerance). Said and logged.
    #[arg(long)]
    pub allow_failed_verification: bool,
    /// Say only the outcome (and errors): no event lines, no status line.
    #[arg(short, long, conflicts_with = "verbose")]
    pub quiet: bool,
    /// Also say every status summary the robot sends.
    #[arg(short, long)]
    pub verbose: bool,
}

#[derive(Debug, clap::Args)]
pub struct ConsoleArgs {
    /// The twin's scenario (default: the built-in wall-following case study).
    #[arg(long, value_name = "S.toml")]
    pub scenario: Option<PathBuf>,
    /// Address of the web page. The default is loopback only: the page can
    /// sign and upload plans.
    #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:8080")]
    pub listen: std::net::SocketAddr,
    /// Another origin allowed to open the page's WebSocket
    /// (`https://ops.example`, behind a reverse proxy); repeatable.
    #[arg(long, value_name = "ORIGIN")]
    pub allow_origin: Vec<String>,
    /// The master's private key (from `twindrive keygen`); without it the
    /// console plans but does not sign, upload or talk to robots.
    #[arg(long, value_name = "master.key")]
    pub key: Option<PathBuf>,
    /// A robot's public key (ID.pub from `twindrive keygen --robot ID`) or
    /// a directory of them; repeatable. Every --robot needs one.
    #[arg(long, value_name = "ID.pub|DIR")]
    pub trust_robot: Vec<PathBuf>,
    /// Where the console keeps each robot link's epochs; default:
    /// link-state/ beside --key.
    #[arg(long, value_name = "DIR")]
    pub link_state: Option<PathBuf>,
    /// The robot's calibrated parameters (`twindrive calibrate`'s JSON):
    /// plans are made with them and the twin rehearses with them. Without
    /// it the console does not plan.
    #[arg(long, value_name = "calib.json")]
    pub calibration: Option<PathBuf>,
    /// A robot this console supervises; repeatable (a fleet).
    #[arg(long, value_name = "ID", value_parser = usage::robot_id)]
    pub robot: Vec<String>,
    /// Connect to this zenoh endpoint (a robot, or a router); repeatable.
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Listen on this zenoh endpoint (`tcp/0.0.0.0:7447`) for robots;
    /// repeatable.
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh_listen: Vec<String>,
    /// A standard zenoh JSON5 configuration; --connect and --zenoh-listen
    /// are added to it.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// Emulate this link on all traffic with the robots, both ways (as
    /// `twindrive master --link`).
    #[arg(long, value_name = "PROFILE")]
    pub link: Option<String>,
    /// Seed of the link emulator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Bytes per second each robot may send this console.
    #[arg(long, value_name = "BYTES_PER_S", default_value_t = 8000.0, value_parser = usage::telemetry_budget)]
    pub telemetry_budget: f64,
    /// Plans signed here stop the robot when it has heard nothing for this
    /// long, seconds (default: unsupervised).
    #[arg(long, value_name = "SECONDS", value_parser = usage::seconds)]
    pub supervise: Option<f64>,
    /// Plans signed here are valid for this long, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 86_400)]
    pub expires_in: u64,
    /// A rehearsal to start with: a mission log made in this twin (a
    /// simulate output directory or its log.mcap).
    #[arg(long, value_name = "LOG")]
    pub rehearsal: Option<PathBuf>,
    /// Also serve the live streams (map, twin pose and scans, each robot's
    /// reported and predicted pose) to Foxglove or Lichtblick: a Foxglove
    /// WebSocket server at this address (`127.0.0.1:8765`).
    #[arg(long, value_name = "ADDR:PORT")]
    pub foxglove: Option<std::net::SocketAddr>,
    /// Output directory: plans, rehearsals, robot logs, reports and the
    /// access token (console.token, kept so a restarted console accepts the
    /// open pages).
    #[arg(long, default_value = "twindrive-console")]
    pub out: PathBuf,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnHandbackArg {
    Stop,
    Replan,
}

#[derive(Debug, clap::Args)]
pub struct SignArgs {
    /// The plan JSON (from `twindrive plan`).
    pub plan: PathBuf,
    /// The master's private key (from `twindrive keygen`).
    #[arg(long, value_name = "master.key")]
    pub key: PathBuf,
    /// The robot the plan is for.
    #[arg(long, value_name = "ID", value_parser = usage::robot_id)]
    pub robot: String,
    /// Plan counter, above every earlier plan's for this robot (default:
    /// the current Unix time in milliseconds).
    #[arg(long)]
    pub counter: Option<u64>,
    /// Valid for this long from now, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 86_400)]
    pub expires_in: u64,
    /// Stop the robot if it hears nothing from the master for this long,
    /// seconds (default: unsupervised).
    #[arg(long, value_name = "SECONDS", value_parser = usage::seconds)]
    pub supervise: Option<f64>,
    /// The twin's scenario the plan was rehearsed in, for the world hash
    /// (default: the built-in scenario the plan names).
    #[arg(long, value_name = "S.toml")]
    pub scenario: Option<PathBuf>,
    /// Send the plan even if it fails verification on the twin (its open-
    /// or closed-loop replay touches something or departs from the plan's
    /// path by more than the robot's deviation tolerance). Said and logged.
    #[arg(long)]
    pub allow_failed_verification: bool,
    /// Output file.
    #[arg(long, value_name = "PLAN.signed")]
    pub out: PathBuf,
}

/// The redundancy flags `plan` and `prune` share (for `plan` they
/// override the --redundancy file).
#[derive(Debug, clap::Args)]
pub struct RedundancyFlags {
    /// Shortest loop worth cutting, metres of path (default: 3 pinch
    /// distances).
    #[arg(long, value_name = "METRES", value_parser = usage::metres_or_zero)]
    pub min_loop_length: Option<f64>,
    /// Shortest loop worth cutting, seconds (default: 0).
    #[arg(long, value_name = "SECONDS", value_parser = usage::seconds_or_zero)]
    pub min_loop_duration: Option<f64>,
    /// Keep reversing stretches (bump and back up) instead of cutting them
    /// (a file's reversing_is_redundant = false stays).
    #[arg(long)]
    pub keep_reversals: bool,
    /// A cut may delete only samples within this distance (metres) of the
    /// path that remains (default: the pinch distance).
    #[arg(long, value_name = "METRES", value_parser = usage::metres)]
    pub coverage_radius: Option<f64>,
    /// Let the path reach its final pose along the recorded route (default:
    /// it ends once the rest only passes ground it covers, after the last
    /// new ground). Sets keep_end; a file's keep_end = true stays.
    #[arg(long)]
    pub keep_end: bool,
}

impl RedundancyFlags {
    /// Sets the fields these flags give.
    pub fn apply(&self, cfg: &mut twindrive_mission::redundancy::RedundancyConfig) {
        if let Some(l) = self.min_loop_length {
            cfg.min_loop_length_m = Some(l);
        }
        if let Some(d) = self.min_loop_duration {
            cfg.min_loop_duration_s = d;
        }
        if self.keep_reversals {
            cfg.reversing_is_redundant = false;
        }
        if let Some(r) = self.coverage_radius {
            cfg.coverage_radius_m = Some(r);
        }
        if self.keep_end {
            cfg.keep_end = true;
        }
    }
}

#[derive(Debug, clap::Args)]
pub struct RelationsArgs {
    /// The trajectory: a TUM file stamped with the scans' own times.
    pub trajectory: PathBuf,
    /// The relations file (`t1 t2 x y z roll pitch yaw` per line).
    #[arg(long, value_name = "FILE")]
    pub relations: PathBuf,
    /// Print the score as JSON (mean, std and max of each error).
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct PruneArgs {
    /// The path file (CSV `t,x,y,theta` or TUM).
    pub path: PathBuf,
    /// Samples closer than this (metres) pinch the path.
    #[arg(long, value_name = "METRES", value_parser = usage::metres)]
    pub pinch_distance: f64,
    #[command(flatten)]
    pub redundancy: RedundancyFlags,
    /// Output CSV (`t,x,y,theta`).
    #[arg(long)]
    pub out: PathBuf,
    /// Also print every cut made and every cut refused, one line each.
    #[arg(short, long)]
    pub verbose: bool,
    /// Write every cut made and every cut refused, one line each, to this
    /// file.
    #[arg(long, value_name = "FILE")]
    pub details: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// Simulator output directory of the mission (log.csv + log.meta.json).
    pub log_dir: PathBuf,
    /// calib.json from `twindrive calibrate` (its three parameters are used).
    #[arg(long)]
    pub calibration: PathBuf,
    /// Redundancy definition (TOML: pinch_distance_m, min_loop_length_m,
    /// min_loop_duration_s, reversing_is_redundant, keep_regions,
    /// keep_windows, coverage_radius_m, keep_end).
    #[arg(long, value_name = "R.toml")]
    pub redundancy: Option<PathBuf>,
    /// Pinch distance in metres (overrides the file; default: the robot's
    /// footprint radius from the log).
    #[arg(long, value_name = "METRES", value_parser = usage::metres)]
    pub pinch_distance: Option<f64>,
    #[command(flatten)]
    pub flags: RedundancyFlags,
    /// The twin's scenario TOML whose world becomes the plan's site map
    /// (default: the built-in scenario named in the log).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Drive the plan as fast as the wheel limits allow (time-optimal
    /// re-timing of the filtered path) instead of at the mission's own pace.
    #[arg(long)]
    pub time_optimal: bool,
    /// The robot's freedom on the plan (TOML): `max_half_width_m` (the
    /// default corridor's widest half width, 1.5), `stretch_m` (0.5),
    /// `max_extra_time_s` (60, the detours together) and
    /// `max_extra_distance_m` (5, each detour) the robot's detours may
    /// cost, `[[corridor]]` regions (`region = [[x, y], ...]`,
    /// `half_width_m`; the footprint radius holds the robot to its path)
    /// and `[[keep_out]]` zones (`name`, `polygon = [[x, y], ...]`). Without
    /// it the corridor follows the twin's clearance and there are no zones.
    #[arg(long, value_name = "FREEDOM.toml")]
    pub freedom: Option<PathBuf>,
    /// Output plan JSON; exports and figures go beside it.
    #[arg(long, default_value = "plan.json")]
    pub out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub struct RosbagArgs {
    /// Mission log: a directory `simulate` wrote, or a log MCAP (robot logs,
    /// rehearsals).
    pub log: PathBuf,
    /// Output bag directory.
    #[arg(long)]
    pub out: PathBuf,
    /// A plan JSON to add as /plan (nav_msgs/msg/Path).
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Scenario TOML whose world becomes /map (default: the built-in
    /// scenario the log names; none for other scenarios).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Message definitions of this ROS 2 distribution (they differ in
    /// sensor_msgs/msg/Range).
    #[arg(long, value_enum, default_value_t = DistroArg::Jazzy)]
    pub distro: DistroArg,
    /// Storage of the bag: MCAP (`NAME_0.mcap`, zstd chunks; rosbag2's
    /// default from Iron), or sqlite3 (`NAME_0.db3`, laid out as the
    /// distribution's rosbag2 writes it: with --distro humble, Humble plays
    /// it without the MCAP plugin).
    #[arg(long, value_enum, default_value_t = StorageArg::Mcap)]
    pub storage: StorageArg,
    /// Unix time (seconds) of the log's t = 0; by default the bag starts at
    /// the epoch.
    #[arg(long, default_value_t = 0.0, value_parser = usage::unix_time)]
    pub start_time: f64,
}

#[derive(Debug, clap::Subcommand)]
pub enum BagCommand {
    /// What `ros2 bag info` prints (storage, files, duration, start and end,
    /// message count, each topic with type, count and serialization
    /// format), any damage (a recording cut short is read up to it), the
    /// topics calibration can use (wheel joints, tick fields, pose
    /// references, wheel odometry, scans, IMU) and a suggested
    /// `calibrate --bag` command line.
    ///
    /// Reads MCAP (zstd, lz4 or plain chunks) and sqlite3 (.db3) storage,
    /// split or not, files or messages compressed with zstd, with or
    /// without metadata.yaml (versions 1 to 9).
    Info {
        /// A bag directory or one storage file (.mcap, .db3, either with .zstd).
        bag: PathBuf,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StorageArg {
    Mcap,
    Sqlite3,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DistroArg {
    Humble,
    Jazzy,
}

/// Which JointState field carries the wheels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum JointSignalArg {
    /// Position when every message has it, else velocity.
    Auto,
    Position,
    Velocity,
}

/// The unit a robot publishes its wheel speeds in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SpeedUnitArg {
    /// Radians per second (ROS's unit for a joint's velocity).
    RadPerS,
    /// Revolutions (turns) per second, as ODrive's controllers report.
    RevPerS,
}

/// Wheel speeds published as plain numbers (a bag's motion source).
#[derive(Debug, Clone, clap::Args)]
pub struct WheelSpeedArgs {
    /// The left wheel's speed topic: std_msgs/msg/Float64 (field `data`),
    /// or an array topic with --left-speed-field `data[0]`; integrated
    /// into the wheel's angle.
    #[arg(long, value_name = "TOPIC", requires_all = ["bag", "right_speed_topic"], conflicts_with_all = ["left_joint", "right_joint"])]
    pub left_speed_topic: Option<String>,
    /// The right wheel's speed topic (may be the left's, with another field).
    #[arg(long, value_name = "TOPIC", requires_all = ["bag", "left_speed_topic"])]
    pub right_speed_topic: Option<String>,
    /// The number field of the left speed topic (`data`, or `data[0]` in an array).
    #[arg(
        long,
        value_name = "FIELD",
        default_value = "data",
        requires = "left_speed_topic"
    )]
    pub left_speed_field: String,
    /// The number field of the right speed topic (`data`, or `data[1]` in an array).
    #[arg(
        long,
        value_name = "FIELD",
        default_value = "data",
        requires = "right_speed_topic"
    )]
    pub right_speed_field: String,
    /// The speed topics' unit.
    #[arg(long, value_enum, default_value_t = SpeedUnitArg::RadPerS, requires = "left_speed_topic")]
    pub speed_unit: SpeedUnitArg,
}

/// Where message times come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StampsArg {
    /// header.stamp (the recording time for types without a header).
    Header,
    /// The time the recorder received each message.
    Log,
}

/// Which estimate `calibrate` reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// The augmented EKF's final estimate.
    Ekf,
    /// The EKF followed by a Rauch-Tung-Striebel smoother (same final
    /// parameters, better history).
    Smoother,
    /// Levenberg-Marquardt over relative motions between pose samples.
    Batch,
}

/// What `calibrate` measures the robot's motion against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ReferenceArg {
    /// Scans when a simulator log has a lidar and no tracker sample, the
    /// pose reference otherwise.
    Auto,
    /// An absolute pose reference (a tracker, motion capture, a localizer).
    Poses,
    /// No pose reference: the lidar's scans matched to each other
    /// (self-calibration: the wheels and the lidar's mount, and a gyro's
    /// bias and scale when the log has one).
    Scans,
}

#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Simulator output directory (instead of --encoders/--poses or --bag).
    pub log_dir: Option<PathBuf>,
    /// A rosbag2 recording (a bag directory or one .mcap/.db3 file; MCAP or
    /// sqlite3, split, zstd-compressed or cut short): wheels from
    /// --left-joint/--right-joint (or --ticks-topic, or
    /// --left-speed-topic/--right-speed-topic), reference from
    /// --pose-topic (`twindrive bag info` suggests them). Times count from
    /// the first reference pose's whole second (`data.time_origin_s` in the
    /// output).
    #[arg(long, value_name = "BAG", conflicts_with_all = ["log_dir", "encoders", "poses"], requires = "bag_reference")]
    pub bag: Option<PathBuf>,
    /// sensor_msgs/msg/JointState topic with the wheel joints.
    #[arg(long, default_value = "/joint_states", requires = "bag")]
    pub joint_topic: String,
    /// Name of the left wheel's joint.
    #[arg(long, requires_all = ["bag", "right_joint"])]
    pub left_joint: Option<String>,
    /// Name of the right wheel's joint.
    #[arg(long, requires_all = ["bag", "left_joint"])]
    pub right_joint: Option<String>,
    /// Joint position (rad) or velocity (rad/s, integrated).
    #[arg(long, value_enum, default_value_t = JointSignalArg::Auto)]
    pub joint_signal: JointSignalArg,
    #[command(flatten)]
    pub speeds: WheelSpeedArgs,
    /// A topic with cumulative tick counts instead of joints (needs
    /// --left-field, --right-field and --ticks-per-rev).
    #[arg(long, requires_all = ["bag", "left_field", "right_field", "ticks_per_rev"], conflicts_with_all = ["left_joint", "left_speed_topic"])]
    pub ticks_topic: Option<String>,
    /// Field of the left count, e.g. `left_ticks` or `data[0]`.
    #[arg(long, requires = "ticks_topic")]
    pub left_field: Option<String>,
    /// Field of the right count, e.g. `right_ticks` or `data[1]`.
    #[arg(long, requires = "ticks_topic")]
    pub right_field: Option<String>,
    /// Reference pose topic: geometry_msgs PoseStamped or
    /// PoseWithCovarianceStamped, nav_msgs Odometry, or tf2_msgs TFMessage.
    #[arg(long, requires = "bag", group = "bag_reference")]
    pub pose_topic: Option<String>,
    /// No pose reference: self-calibrate from this sensor_msgs/msg/LaserScan
    /// topic (the wheels, the lidar's mount; its frame's mount in
    /// /tf_static is the matcher's first guess).
    #[arg(
        long,
        requires = "bag",
        group = "bag_reference",
        conflicts_with = "pose_topic"
    )]
    pub scan_topic: Option<String>,
    /// With --scan-topic: a sensor_msgs/msg/Imu topic whose angular
    /// velocity z is the gyro (its bias and scale are estimated too).
    #[arg(long, requires = "scan_topic")]
    pub imu_topic: Option<String>,
    /// With --scan-topic: the robot's frame in the TF tree (default
    /// base_link, else base_footprint).
    #[arg(long, requires = "scan_topic")]
    pub base_frame: Option<String>,
    /// The robot's child frame on a TF topic (checked against
    /// child_frame_id for Odometry).
    #[arg(long, requires = "pose_topic")]
    pub pose_frame: Option<String>,
    /// The parent frame on a TF topic, when several publish the child.
    #[arg(long, requires = "pose_frame")]
    pub pose_parent: Option<String>,
    /// Message times: header stamps, or the recorder's receive times.
    #[arg(long, value_enum, default_value_t = StampsArg::Header)]
    pub stamps: StampsArg,
    /// Encoder CSV: `t,left_ticks,right_ticks` or `t,left_rad_s,right_rad_s`.
    #[arg(long, requires = "poses")]
    pub encoders: Option<PathBuf>,
    /// Pose CSV: `t,x,y,theta` (theta may be empty).
    #[arg(long, requires = "encoders")]
    pub poses: Option<PathBuf>,
    /// Encoder ticks per wheel revolution (for tick counts).
    #[arg(long, value_parser = usage::ticks_per_rev)]
    pub ticks_per_rev: Option<u32>,
    /// Initial guess DL,DR,B in metres (default for logs: their nominal
    /// values; for a bag: the wheels of its /robot_description, said so).
    #[arg(long, value_name = "DL,DR,B")]
    pub initial: Option<String>,
    /// -1 for a left counter that runs backwards when driving forward.
    #[arg(long, default_value_t = 1, value_parser = usage::wheel_sign)]
    pub left_sign: i8,
    /// -1 for a right counter that runs backwards when driving forward.
    #[arg(long, default_value_t = 1, value_parser = usage::wheel_sign)]
    pub right_sign: i8,
    /// Offset added to encoder times to put them on the pose clock: seconds, or `auto`.
    #[arg(long, default_value = "0", value_name = "auto|SECONDS")]
    pub time_offset: String,
    /// Which estimate to report.
    #[arg(long, value_enum, default_value_t = MethodArg::Smoother)]
    pub method: MethodArg,
    /// Output JSON; figures and trajectories go beside it.
    #[arg(long, default_value = "calib.json")]
    pub out: PathBuf,
    /// Use poses from this time on (pose clock, seconds).
    #[arg(long, value_parser = usage::time)]
    pub start_s: Option<f64>,
    /// Use poses up to this time (pose clock, seconds).
    #[arg(long, value_parser = usage::time)]
    pub end_s: Option<f64>,
    /// Standard deviation of the reference position.
    #[arg(long, default_value_t = 0.002, value_parser = usage::positive)]
    pub position_std_m: f64,
    /// Standard deviation of the reference heading.
    #[arg(long, default_value_t = 0.005, value_parser = usage::positive)]
    pub heading_std_rad: f64,
    /// Wheel rotation noise: variance per radian of rotation (rad²/rad).
    #[arg(long, default_value_t = 1e-4, value_parser = usage::positive)]
    pub wheel_noise: f64,
    /// Random walk of each parameter (m²/s); off unless given.
    #[arg(long, value_parser = usage::positive)]
    pub param_random_walk: Option<f64>,
    /// Length of the batch estimator's relative-motion windows.
    #[arg(long, default_value_t = 1.0, value_parser = usage::seconds)]
    pub batch_window_s: f64,
    /// What the motion is measured against (simulator logs; CSV and bag
    /// inputs give poses).
    #[arg(long, value_enum, default_value_t = ReferenceArg::Auto)]
    pub reference: ReferenceArg,
    /// The lidar whose scans self-calibrate (default: the log's first
    /// sensor of kind lidar with at least 30 beams).
    #[arg(long, value_name = "NAME")]
    pub scan_sensor: Option<String>,
    /// The lidar's mount X,Y,HEADING (m, m, rad) as believed, for the scan
    /// matcher's priors (default: the log's). The estimate does not start
    /// from it: Censi's closed form needs no guess.
    #[arg(long, value_name = "X,Y,HEADING", allow_hyphen_values = true)]
    pub mount: Option<String>,
    /// Length of a self-calibration's intervals (scans this far apart are
    /// matched directly).
    #[arg(long, default_value_t = 1.0, value_parser = usage::seconds)]
    pub interval_s: f64,
}

#[derive(Debug, clap::Args)]
pub struct MapArgs {
    /// Simulator output directory with a lidar's scans (instead of --bag
    /// or --carmen).
    #[arg(required_unless_present_any = ["bag", "carmen"])]
    pub log_dir: Option<PathBuf>,
    /// A CARMEN log (`.clf`, or gzip-compressed `.clf.gz`), read directly:
    /// the scans of its FLASER or ROBOTLASER1 lines and the robot's own
    /// odometry (its ODOM lines, else the robot pose in the laser lines),
    /// stamped with their ipc_timestamp; the laser's mount from the laser
    /// lines. As the 2D SLAM benchmark (Kümmerle et al. 2009) publishes
    /// its logs; no calibration needed.
    #[arg(long, value_name = "LOG", conflicts_with_all = ["log_dir", "bag"])]
    pub carmen: Option<PathBuf>,
    /// Map only the first T seconds of the recording, counted from its
    /// first scan.
    #[arg(long, value_name = "T", value_parser = usage::positive)]
    pub until_s: Option<f64>,
    /// A rosbag2 recording (MCAP or sqlite3): scans from --scan-topic, the
    /// robot's motion from its odometry (--odom-topic), its wheel joints
    /// (--left-joint/--right-joint) or its wheel speeds
    /// (--left-speed-topic/--right-speed-topic); wheels need --calibration,
    /// or the nominal --wheel-diameter-m and --wheelbase-m, else the
    /// recording's robot description (/robot_description, a URDF) gives
    /// them, and says so.
    #[arg(
        long,
        value_name = "BAG",
        conflicts_with = "log_dir",
        requires = "scan_topic"
    )]
    pub bag: Option<PathBuf>,
    /// sensor_msgs/msg/LaserScan topic.
    #[arg(long, requires = "bag")]
    pub scan_topic: Option<String>,
    /// The robot's own odometry: a nav_msgs/msg/Odometry topic (`/odom`),
    /// or a TF topic (`/tf`: odom -> the base frame). Already in metres: no
    /// calibration needed to map.
    #[arg(long, value_name = "TOPIC", requires = "bag", conflicts_with_all = ["left_joint", "right_joint", "left_speed_topic"])]
    pub odom_topic: Option<String>,
    /// sensor_msgs/msg/JointState topic with the wheel joints.
    #[arg(long, default_value = "/joint_states", requires = "bag")]
    pub joint_topic: String,
    /// Name of the left wheel's joint.
    #[arg(long, requires = "bag")]
    pub left_joint: Option<String>,
    /// Name of the right wheel's joint.
    #[arg(long, requires = "bag")]
    pub right_joint: Option<String>,
    /// Joint position (rad) or velocity (rad/s, integrated).
    #[arg(long, value_enum, default_value_t = JointSignalArg::Auto)]
    pub joint_signal: JointSignalArg,
    #[command(flatten)]
    pub speeds: WheelSpeedArgs,
    /// The robot's frame in the TF tree (default base_link, else base_footprint).
    #[arg(long, requires = "bag")]
    pub base_frame: Option<String>,
    /// Message times: header stamps, or the recorder's receive times.
    #[arg(long, value_enum, default_value_t = StampsArg::Header)]
    pub stamps: StampsArg,
    /// -1 for a left counter that runs backwards when driving forward.
    #[arg(long, default_value_t = 1, value_parser = usage::wheel_sign)]
    pub left_sign: i8,
    /// -1 for a right counter that runs backwards when driving forward.
    #[arg(long, default_value_t = 1, value_parser = usage::wheel_sign)]
    pub right_sign: i8,
    /// The lidar (simulator logs; default: the first sensor of kind lidar
    /// with at least 30 beams).
    #[arg(long, value_name = "NAME")]
    pub scan_sensor: Option<String>,
    /// calib.json from `twindrive calibrate`: its wheels, and its
    /// lidar_mount when it has one (a self-calibration; else the log's or
    /// /tf_static's mount). Maps from wheels (without it, the nominal
    /// --wheel-diameter-m and --wheelbase-m do); with --odom-topic it gives
    /// site.toml's robot its wheels.
    #[arg(long, value_name = "calib.json")]
    pub calibration: Option<PathBuf>,
    /// The nominal wheel diameter when neither --calibration nor --mission
    /// gives the wheels: site.toml's robot's, and the dead reckoning's when
    /// mapping from wheel joints or speeds. A bag without it (or without
    /// --wheelbase-m) takes what is missing from its /robot_description.
    #[arg(long, value_parser = usage::positive)]
    pub wheel_diameter_m: Option<f64>,
    /// The nominal wheelbase when neither --calibration nor --mission gives
    /// the wheels (as --wheel-diameter-m).
    #[arg(long, value_parser = usage::positive)]
    pub wheelbase_m: Option<f64>,
    /// A mission scenario whose robot, sensors and controller site.toml
    /// puts on the map (with the calibrated wheels and mount); without it
    /// the robot stands where the drive started and holds still.
    #[arg(long, value_name = "SCENARIO")]
    pub mission: Option<PathBuf>,
    /// The grid's cell size.
    #[arg(long, default_value_t = 0.05, value_parser = usage::positive)]
    pub resolution_m: f64,
    /// The robot's footprint radius for site.toml (bags; a log gives its own).
    #[arg(long, default_value_t = 0.2, value_parser = usage::positive)]
    pub footprint_radius_m: f64,
    /// The wheels' speed limit for site.toml (bags; a log gives its own).
    #[arg(long, default_value_t = 10.0, value_parser = usage::positive)]
    pub max_wheel_speed_rad_s: f64,
    /// The wheels' acceleration limit for site.toml (bags; a log gives its own).
    #[arg(long, default_value_t = 20.0, value_parser = usage::positive)]
    pub max_wheel_accel_rad_s2: f64,
    /// Output directory (map.pgm, map.yaml, map.png: a picture of the map
    /// with the drive on it, site.toml, poses.tum, map_report.json).
    #[arg(long)]
    pub out: PathBuf,
}
