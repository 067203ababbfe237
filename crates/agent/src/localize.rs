//! The robot's localization against the map its plan carries: range
//! endpoints in, pose measurements for the filter out. No I/O, no clock:
//! time comes with each reading.
//!
//! Two ways, by what the robot carries:
//! - a **scan** (a robot with a lidar, [`SensorKind::Lidar`]): every
//!   fresh scan is matched on its own, Gauss-Newton from the filter's
//!   estimate;
//! - **rangers** (side IR sensors, [`SensorKind::Ranger`]): one reading
//!   says almost nothing, so
//!   endpoints are gathered over [`LocalizeSettings::window_s`] of driving,
//!   carried into the robot's frame by odometry, and matched together with
//!   a grid search around the estimate before Gauss-Newton. Each reading is
//!   used in one match only, so the filter is not told the same thing twice.
//!
//! Readings at the sensor's maximum (nothing in reach) or minimum (too
//! close to trust) give no endpoint. What the points do not constrain (a
//! single wall says nothing of where along it the robot is) is left to
//! odometry. A robot whose readings give no match for
//! [`LocalizeSettings::lost_after_s`] is *not localized*: it goes on by
//! odometry, as it did before it had a map, and says so.

use twindrive_estimation::localize::{MatchSettings, ScanMatch, SegmentMap, match_points, search};
use twindrive_kinematics::{DiffDriveParams, Pose, WheelOdometry};
use twindrive_log::{RangeSensorInfo, SensorKind};
use twindrive_mission::plan::MissionPlan;

/// How the robot localizes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalizeSettings {
    pub matching: MatchSettings,
    /// The map's lookup resolution (m).
    pub resolution_m: f64,
    /// Few-beam robots gather endpoints over this long before a match (s).
    pub window_s: f64,
    /// Grid search half-widths around the estimate, at least (x, y m;
    /// heading rad), and poses a side; widened to 3 sigma of the estimate.
    pub search_half_width: [f64; 3],
    pub search_steps: usize,
    /// No match for this long: not localized (s).
    pub lost_after_s: f64,
    /// Off: odometry only (how the robot drove before it had a map; the
    /// experiments' baseline).
    pub enabled: bool,
}

impl LocalizeSettings {
    /// No localization: the robot goes by odometry (and any tracker) alone.
    pub fn odometry_only() -> Self {
        Self {
            enabled: false,
            ..Self::default()
        }
    }
}

impl Default for LocalizeSettings {
    fn default() -> Self {
        Self {
            matching: MatchSettings::default(),
            resolution_m: 0.05,
            window_s: 1.0,
            search_half_width: [0.03, 0.03, 0.03],
            search_steps: 5,
            lost_after_s: 5.0,
            enabled: true,
        }
    }
}

/// How the robot localizes, as said in its journal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Scan by scan (a lidar).
    Scan,
    /// Endpoints gathered over a window (a few beams).
    Window,
    /// No range sensor: odometry only.
    None,
}

/// One beam: its origin and direction in the robot frame and its limits.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Beam {
    /// Which of the robot's sensors it belongs to.
    pub sensor: usize,
    pub origin: [f64; 2],
    pub dir: [f64; 2],
    pub min_m: f64,
    pub max_m: f64,
}

impl Beam {
    /// Where a reading of `range_m` ends, in the robot's frame.
    pub fn endpoint(&self, range_m: f64) -> (f64, f64) {
        (
            self.origin[0] + range_m * self.dir[0],
            self.origin[1] + range_m * self.dir[1],
        )
    }
}

/// A match the filter should fuse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fix {
    pub matched: ScanMatch,
    pub t_s: f64,
}

/// The localizer of one plan.
pub struct Localizer {
    map: SegmentMap,
    beams: Vec<Beam>,
    mode: Mode,
    settings: LocalizeSettings,
    /// Odometry: the window's frame.
    odom: WheelOdometry,
    /// Endpoints in the odometry frame.
    window: Vec<[f64; 2]>,
    window_start_s: Option<f64>,
    /// Scratch: endpoints in the robot frame.
    points: Vec<[f64; 2]>,
    last_fix_s: Option<f64>,
    pub fixes: u64,
    pub failures: u64,
}

impl Localizer {
    /// For `plan`'s map and the robot's range sensors.
    pub fn new(plan: &MissionPlan, settings: LocalizeSettings) -> Self {
        let sensors = &plan.header.robot.range_sensors;
        let reach = settings.matching.outlier_m + settings.resolution_m;
        // The walls only: a learnt block's extent is partly a guess, no
        // landmark.
        let walls = plan.header.site_map.walls_without_boxes();
        let map = SegmentMap::new(&walls, settings.resolution_m, reach);
        let beams = beams(sensors);
        let mode =
            if !settings.enabled || beams.is_empty() || plan.header.site_map.segments.is_empty() {
                Mode::None
            } else if sensors.iter().any(|s| s.kind == SensorKind::Lidar) {
                Mode::Scan
            } else {
                Mode::Window
            };
        Self {
            map,
            beams,
            mode,
            settings,
            odom: WheelOdometry::new(Pose::default()),
            window: Vec::new(),
            window_start_s: None,
            points: Vec::new(),
            last_fix_s: None,
            fixes: 0,
            failures: 0,
        }
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Beams the robot localizes with.
    pub fn beams(&self) -> usize {
        self.beams.len()
    }

    /// Whether a match was fused within [`LocalizeSettings::lost_after_s`]
    /// of `t_s`.
    pub fn localized(&self, t_s: f64) -> bool {
        self.mode != Mode::None
            && self
                .last_fix_s
                .is_some_and(|fix| t_s - fix <= self.settings.lost_after_s)
    }

    /// A fix was fused (the filter took it).
    pub fn fused(&mut self, t_s: f64) {
        self.last_fix_s = Some(t_s);
        self.fixes += 1;
    }

    /// One control period: the wheel angles (rad, cumulative) when the
    /// encoders sampled, the wheel parameters in use, the readings taken this
    /// period (NaN where a beam did not sample), and the filter's estimate
    /// (pose and its 3 x 3 covariance). A match to fuse, when there is one.
    pub fn observe(
        &mut self,
        t_s: f64,
        wheels_rad: Option<[f64; 2]>,
        params: &DiffDriveParams,
        fresh_ranges_m: &[f64],
        estimate: [f64; 3],
        covariance: &[[f64; 3]; 3],
    ) -> Option<Fix> {
        if self.mode == Mode::None {
            return None;
        }
        if let Some(w) = wheels_rad {
            self.odom.advance(params, w);
        }
        let odom = self.odom.pose;
        let fresh = fresh_ranges_m.iter().any(|r| r.is_finite());
        if !fresh {
            return None;
        }
        // Endpoints of this period's readings, into the odometry frame.
        for (beam, &r) in self.beams.iter().zip(fresh_ranges_m) {
            if !(r.is_finite() && r > beam.min_m && r < beam.max_m) {
                continue;
            }
            let (bx, by) = beam.endpoint(r);
            let (x, y) = odom.transform_point(bx, by);
            self.window.push([x, y]);
        }
        let start = *self.window_start_s.get_or_insert(t_s);
        if self.mode == Mode::Window && t_s - start < self.settings.window_s {
            return None;
        }
        // Into the robot frame now.
        let (s, c) = odom.heading_rad.sin_cos();
        self.points.clear();
        self.points.extend(self.window.iter().map(|p| {
            let (dx, dy) = (p[0] - odom.x_m, p[1] - odom.y_m);
            [c * dx + s * dy, -s * dx + c * dy]
        }));
        self.window.clear();
        self.window_start_s = None;
        let matched = match self.mode {
            Mode::Scan => match_points(&self.map, &self.points, estimate, &self.settings.matching),
            _ => {
                let w = self.settings.search_half_width;
                let half =
                    [0, 1, 2].map(|i| w[i].max(3.0 * covariance[i][i].max(0.0).sqrt()).min(0.3));
                search(
                    &self.map,
                    &self.points,
                    estimate,
                    half,
                    self.settings.search_steps,
                    &self.settings.matching,
                )
            }
        };
        match matched {
            Some(m) => Some(Fix { matched: m, t_s }),
            None => {
                self.failures += 1;
                None
            }
        }
    }
}

/// Every beam of `sensors`, in reading order.
pub(crate) fn beams(sensors: &[RangeSensorInfo]) -> Vec<Beam> {
    sensors
        .iter()
        .enumerate()
        .flat_map(|(sensor, s)| {
            (0..s.beams).map(move |b| {
                let a = s.mount.heading_rad + s.beam_angle_rad(b);
                Beam {
                    sensor,
                    origin: [s.mount.x_m, s.mount.y_m],
                    dir: [a.cos(), a.sin()],
                    min_m: s.min_range_m,
                    max_m: s.max_range_m,
                }
            })
        })
        .collect()
}
