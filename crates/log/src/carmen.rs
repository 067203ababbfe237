//! CARMEN logs (`.clf`, and gzip-compressed `.clf.gz`): the robot's
//! odometry (`ODOM`) and its laser scans (`FLASER`, `ROBOTLASER1`), as the
//! public 2D SLAM benchmark logs (Kümmerle et al. 2009) carry them.
//!
//! Line formats (space separated; times are the `ipc_timestamp`, the clock
//! the benchmark's relations use):
//! - `ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp`
//! - `FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ipc_timestamp
//!   hostname logger_timestamp`: `x y theta` is the laser's pose,
//!   `odom_*` the robot's, both in the odometry's frame. The `n` beams
//!   run counter-clockwise from -90° over the front half-plane: π/(n-1)
//!   apart for an odd count (181, 361: -90° to +90° inclusive), π/n for an
//!   even one (180, 360: -90° up to +89°, +89.5°), as GMapping and CARMEN
//!   read them.
//! - `ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy
//!   remission_mode n r_1 .. r_n n_rem rem_1 .. rem_n_rem laser_x laser_y
//!   laser_theta robot_x robot_y robot_theta tv rv forward_safety_dist
//!   side_safety_dist turn_axis ipc_timestamp hostname logger_timestamp`.
//!
//! `#` lines, `PARAM` lines and lines of other kinds are skipped.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use twindrive_kinematics::{Pose, wrap_angle};

use crate::LogError;

/// Which line a scan came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaserLine {
    Flaser,
    RobotLaser1,
}

/// One `ODOM` line: the robot's odometry pose at `t_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarmenOdometry {
    pub t_s: f64,
    pub pose: Pose,
}

/// One laser line.
#[derive(Debug, Clone, PartialEq)]
pub struct CarmenLaser {
    pub line_kind: LaserLine,
    /// The line's `ipc_timestamp` (s).
    pub t_s: f64,
    /// Bearing of the first beam in the laser's frame (rad).
    pub angle_min_rad: f64,
    /// Bearing step between beams (rad, counter-clockwise).
    pub increment_rad: f64,
    /// `ROBOTLASER1`'s `max_range` field (FLASER has none).
    pub max_range_m: Option<f64>,
    pub ranges_m: Vec<f32>,
    /// The laser's pose in the odometry's frame.
    pub laser_pose: Pose,
    /// The robot's odometry pose.
    pub robot_pose: Pose,
    /// Line number in the file (1-based).
    pub line: u64,
}

impl CarmenLaser {
    /// The laser's pose on the robot: robot⁻¹ ⊕ laser.
    pub fn mount(&self) -> Pose {
        let r = self.robot_pose;
        let (s, c) = r.heading_rad.sin_cos();
        let (dx, dy) = (self.laser_pose.x_m - r.x_m, self.laser_pose.y_m - r.y_m);
        Pose::new(
            c * dx + s * dy,
            -s * dx + c * dy,
            wrap_angle(self.laser_pose.heading_rad - r.heading_rad),
        )
    }
}

/// A CARMEN log's odometry and laser scans, each in time order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CarmenLog {
    pub path: PathBuf,
    /// The `ODOM` lines (empty when the log has none: the robot's pose in
    /// the laser lines is then its odometry).
    pub odometry: Vec<CarmenOdometry>,
    pub lasers: Vec<CarmenLaser>,
    /// Lines not read, by kind (`PARAM`, `SYNC`, `RAWLASER1`, ...).
    pub skipped: BTreeMap<String, usize>,
}

/// Share of all readings, and count, a value must reach to be taken as the
/// scanner's "no return" reading (it repeats as a plateau at the top of
/// the range).
const PLATEAU_SHARE: f64 = 1e-3;
const PLATEAU_MIN_COUNT: usize = 10;

impl CarmenLog {
    /// Reads `path`; gzip when it starts with gzip's magic bytes.
    pub fn read(path: &Path) -> Result<Self, LogError> {
        let mut file = std::fs::File::open(path).map_err(|e| LogError::io(path, e))?;
        let mut magic = [0u8; 2];
        let gz = file.read_exact(&mut magic).is_ok() && magic == [0x1f, 0x8b];
        drop(file);
        let file = std::fs::File::open(path).map_err(|e| LogError::io(path, e))?;
        if gz {
            Self::parse(
                BufReader::new(flate2::read::MultiGzDecoder::new(BufReader::new(file))),
                path,
            )
        } else {
            Self::parse(BufReader::new(file), path)
        }
    }

    /// Parses a log's text; `path` names it in errors.
    pub fn parse(reader: impl BufRead, path: &Path) -> Result<Self, LogError> {
        let mut log = CarmenLog {
            path: path.to_path_buf(),
            ..Self::default()
        };
        for (i, line) in reader.lines().enumerate() {
            let line_no = i as u64 + 1;
            let line = line.map_err(|e| LogError::io(path, e))?;
            let mut fields = Fields {
                words: line.split_ascii_whitespace(),
                path,
                line: line_no,
            };
            let Some(kind) = fields.words.next() else {
                continue;
            };
            match kind {
                "ODOM" => log.odometry.push(fields.odom()?),
                "FLASER" => log.lasers.push(fields.flaser()?),
                "ROBOTLASER1" => log.lasers.push(fields.robotlaser1()?),
                k if k.starts_with('#') => {}
                k => *log.skipped.entry(k.to_string()).or_default() += 1,
            }
        }
        // Each stream in time order (a stable sort: equal stamps keep
        // their lines' order).
        log.odometry.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        log.lasers.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        Ok(log)
    }

    /// Readings at or above this are no return (m). The scanner's maximum
    /// is the lowest value, within 10 % of the largest reading, that
    /// repeats as a plateau (at least 10 times and 0.1 % of all readings: a SICK's
    /// 81.83 and 81.91 m codes, ACES's 50.00 m), less 1 cm; capped by
    /// `ROBOTLASER1`'s `max_range` field when it is smaller. Without a
    /// plateau, every reading is a return.
    pub fn no_return_from_m(&self) -> f64 {
        let mut counts: BTreeMap<u32, usize> = BTreeMap::new();
        let mut total = 0usize;
        for l in &self.lasers {
            for r in &l.ranges_m {
                *counts.entry(r.to_bits()).or_default() += 1;
            }
            total += l.ranges_m.len();
        }
        let top = counts
            .keys()
            .map(|b| f64::from(f32::from_bits(*b)))
            .fold(0.0, f64::max);
        let plateau = counts
            .iter()
            .map(|(b, n)| (f64::from(f32::from_bits(*b)), *n))
            .filter(|(r, n)| {
                *r >= 0.9 * top
                    && *n >= PLATEAU_MIN_COUNT
                    && *n as f64 >= PLATEAU_SHARE * total as f64
            })
            .map(|(r, _)| r)
            .fold(f64::INFINITY, f64::min);
        let from_plateau = if plateau.is_finite() {
            // f32 readings: 49.99 as f32 is above 49.99 as f64; compare on f32.
            f64::from((plateau - 0.01) as f32)
        } else {
            f64::from((top + 0.01) as f32)
        };
        self.lasers
            .iter()
            .filter_map(|l| l.max_range_m)
            .fold(from_plateau, f64::min)
    }

    /// The robot's odometry: the `ODOM` lines, else the robot's pose in
    /// each laser line.
    pub fn robot_odometry(&self) -> Vec<(f64, Pose)> {
        if self.odometry.is_empty() {
            self.lasers.iter().map(|l| (l.t_s, l.robot_pose)).collect()
        } else {
            self.odometry.iter().map(|o| (o.t_s, o.pose)).collect()
        }
    }

    /// The raw odometry at each laser stamp: the `ODOM` poses linearly
    /// interpolated (heading along the shorter arc; clamped to the first
    /// or last outside their span), else the laser line's robot pose.
    pub fn odometry_at_lasers(&self) -> Vec<(f64, Pose)> {
        if self.odometry.is_empty() {
            return self.robot_odometry();
        }
        let odom = &self.odometry;
        self.lasers
            .iter()
            .map(|l| {
                let k = odom.partition_point(|o| o.t_s <= l.t_s);
                let pose = if k == 0 {
                    odom[0].pose
                } else if k == odom.len() {
                    odom[k - 1].pose
                } else {
                    let (a, b) = (&odom[k - 1], &odom[k]);
                    let dt = b.t_s - a.t_s;
                    let f = if dt > 0.0 { (l.t_s - a.t_s) / dt } else { 0.0 };
                    let (p, q) = (a.pose, b.pose);
                    Pose::new(
                        p.x_m + f * (q.x_m - p.x_m),
                        p.y_m + f * (q.y_m - p.y_m),
                        wrap_angle(p.heading_rad + f * wrap_angle(q.heading_rad - p.heading_rad)),
                    )
                };
                (l.t_s, pose)
            })
            .collect()
    }
}

/// The words of one line after its kind, read field by field.
struct Fields<'a> {
    words: std::str::SplitAsciiWhitespace<'a>,
    path: &'a Path,
    line: u64,
}

impl<'a> Fields<'a> {
    fn error(&self, column: &str, message: String) -> LogError {
        LogError::Field {
            path: self.path.to_path_buf(),
            line: self.line,
            column: column.to_string(),
            message,
        }
    }

    fn word(&mut self, column: &str) -> Result<&'a str, LogError> {
        match self.words.next() {
            Some(w) => Ok(w),
            None => Err(self.error(column, "the line ends before this field".into())),
        }
    }

    fn number(&mut self, column: &str) -> Result<f64, LogError> {
        let w = self.word(column)?;
        match w.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.error(column, format!("`{w}` is not a finite number"))),
        }
    }

    fn count(&mut self, column: &str) -> Result<usize, LogError> {
        let w = self.word(column)?;
        w.parse::<usize>()
            .map_err(|_| self.error(column, format!("`{w}` is not a count")))
    }

    fn pose(&mut self, names: [&str; 3]) -> Result<Pose, LogError> {
        Ok(Pose::new(
            self.number(names[0])?,
            self.number(names[1])?,
            self.number(names[2])?,
        ))
    }

    fn ranges(&mut self, n: usize) -> Result<Vec<f32>, LogError> {
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let w = self.word(&format!("range {}", i + 1))?;
            match w.parse::<f32>() {
                Ok(r) if r.is_finite() && r >= 0.0 => out.push(r),
                _ => {
                    return Err(self.error(
                        &format!("range {}", i + 1),
                        format!("`{w}` is not a range in metres"),
                    ));
                }
            }
        }
        Ok(out)
    }

    fn stamp(&mut self) -> Result<f64, LogError> {
        let t = self.number("ipc_timestamp")?;
        if t < 0.0 {
            return Err(self.error("ipc_timestamp", format!("{t} is negative")));
        }
        Ok(t)
    }

    fn odom(&mut self) -> Result<CarmenOdometry, LogError> {
        let pose = self.pose(["x", "y", "theta"])?;
        for c in ["tv", "rv", "accel"] {
            self.number(c)?;
        }
        Ok(CarmenOdometry {
            t_s: self.stamp()?,
            pose,
        })
    }

    /// A laser line's `num_readings`: at least 2.
    fn beams(&mut self) -> Result<usize, LogError> {
        let n = self.count("num_readings")?;
        if n < 2 {
            return Err(self.error(
                "num_readings",
                format!("{n} beams: a scan needs at least 2"),
            ));
        }
        Ok(n)
    }

    fn flaser(&mut self) -> Result<CarmenLaser, LogError> {
        let n = self.beams()?;
        let ranges_m = self.ranges(n)?;
        let laser_pose = self.pose(["x", "y", "theta"])?;
        let robot_pose = self.pose(["odom_x", "odom_y", "odom_theta"])?;
        let t_s = self.stamp()?;
        let gaps = if n % 2 == 1 { n - 1 } else { n };
        Ok(CarmenLaser {
            line_kind: LaserLine::Flaser,
            t_s,
            angle_min_rad: -std::f64::consts::FRAC_PI_2,
            increment_rad: std::f64::consts::PI / gaps as f64,
            max_range_m: None,
            ranges_m,
            laser_pose,
            robot_pose,
            line: self.line,
        })
    }

    fn robotlaser1(&mut self) -> Result<CarmenLaser, LogError> {
        self.number("laser_type")?;
        let angle_min_rad = self.number("start_angle")?;
        self.number("fov")?;
        let increment_rad = self.number("angular_res")?;
        if increment_rad <= 0.0 {
            return Err(self.error(
                "angular_res",
                format!("{increment_rad} rad: the beams' step must be positive"),
            ));
        }
        let max_range_m = self.number("max_range")?;
        if max_range_m <= 0.0 {
            return Err(self.error("max_range", format!("{max_range_m} m is not positive")));
        }
        self.number("accuracy")?;
        self.number("remission_mode")?;
        let n = self.beams()?;
        let ranges_m = self.ranges(n)?;
        let remissions = self.count("num_remissions")?;
        for i in 0..remissions {
            self.number(&format!("remission {}", i + 1))?;
        }
        let laser_pose = self.pose(["laser_x", "laser_y", "laser_theta"])?;
        let robot_pose = self.pose(["robot_x", "robot_y", "robot_theta"])?;
        for c in [
            "tv",
            "rv",
            "forward_safety_dist",
            "side_safety_dist",
            "turn_axis",
        ] {
            self.number(c)?;
        }
        Ok(CarmenLaser {
            line_kind: LaserLine::RobotLaser1,
            t_s: self.stamp()?,
            angle_min_rad,
            increment_rad,
            max_range_m: Some(max_range_m),
            ranges_m,
            laser_pose,
            robot_pose,
            line: self.line,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<CarmenLog, LogError> {
        CarmenLog::parse(text.as_bytes(), Path::new("t.clf"))
    }

    #[test]
    fn reads_odom_flaser_and_robotlaser1() {
        let log = parse(
            "# a comment\n\
             PARAM robot_length 0.5\n\
             ODOM 1 2 0.5 0.1 0.2 0 10.25 host 10.3\n\
             SYNC whatever\n\
             FLASER 3 1.5 50 2 1 2 0.5 1 2 0.5 10.5 host 10.6\n\
             \n\
             ROBOTLASER1 0 -1.570796 3.14159 0.017453 81.9 0.01 0 2 3.5 81.91 1 7 \
             1.22 0 0 1 0 0 0 0 0 0 0 11.0 host 11.1\n\
             ODOM 2 2 0.5 0 0 0 10.75 host 10.8\n",
        )
        .unwrap();
        assert_eq!(log.odometry.len(), 2);
        assert_eq!(log.odometry[0].t_s, 10.25);
        assert_eq!(log.odometry[0].pose, Pose::new(1.0, 2.0, 0.5));
        assert_eq!(log.skipped.get("PARAM"), Some(&1));
        assert_eq!(log.skipped.get("SYNC"), Some(&1));
        let [f, r] = &log.lasers[..] else {
            panic!("{:?}", log.lasers)
        };
        assert_eq!(f.line_kind, LaserLine::Flaser);
        assert_eq!(f.ranges_m, vec![1.5, 50.0, 2.0]);
        // Three beams: -90°, 0°, +90°.
        assert!((f.increment_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert_eq!(f.t_s, 10.5);
        assert_eq!(f.line, 5);
        assert_eq!(r.line_kind, LaserLine::RobotLaser1);
        assert_eq!(r.ranges_m, vec![3.5, 81.91]);
        assert_eq!(r.max_range_m, Some(81.9));
        assert!((r.angle_min_rad + std::f64::consts::FRAC_PI_2).abs() < 1e-6);
        let m = r.mount();
        assert!((m.x_m - 0.22).abs() < 1e-12 && m.y_m.abs() < 1e-12, "{m:?}");
        // The laser lines' robot poses are not the odometry when ODOM lines exist.
        assert_eq!(log.robot_odometry().len(), 2);
        // ODOM at the laser stamps: halfway, then clamped to the last.
        let at = log.odometry_at_lasers();
        assert_eq!(at[0], (10.5, Pose::new(1.5, 2.0, 0.5)));
        assert_eq!(at[1], (11.0, Pose::new(2.0, 2.0, 0.5)));
    }

    #[test]
    fn beams_span_the_front_half_plane() {
        let line = |n: usize| {
            let ranges = vec!["1"; n].join(" ");
            format!("FLASER {n} {ranges} 0 0 0 0 0 0 1 h 1\n")
        };
        for (n, step_deg, last_deg) in [
            (180, 1.0, 89.0),
            (181, 1.0, 90.0),
            (360, 0.5, 89.5),
            (361, 0.5, 90.0),
        ] {
            let log = parse(&line(n)).unwrap();
            let l = &log.lasers[0];
            assert!(
                (l.increment_rad.to_degrees() - step_deg).abs() < 1e-12,
                "{n}"
            );
            let last = l.angle_min_rad + (n - 1) as f64 * l.increment_rad;
            assert!((last.to_degrees() - last_deg).abs() < 1e-9, "{n}");
        }
    }

    #[test]
    fn the_mount_is_the_laser_seen_from_the_robot() {
        let robot = Pose::new(3.0, -1.0, 2.0);
        let laser_on_robot = Pose::new(0.3, -0.1, 0.25);
        let (x, y) = robot.transform_point(laser_on_robot.x_m, laser_on_robot.y_m);
        let laser = CarmenLaser {
            line_kind: LaserLine::Flaser,
            t_s: 0.0,
            angle_min_rad: 0.0,
            increment_rad: 0.1,
            max_range_m: None,
            ranges_m: vec![],
            laser_pose: Pose::new(x, y, robot.heading_rad + laser_on_robot.heading_rad),
            robot_pose: robot,
            line: 1,
        };
        let m = laser.mount();
        assert!((m.x_m - 0.3).abs() < 1e-12);
        assert!((m.y_m + 0.1).abs() < 1e-12);
        assert!((m.heading_rad - 0.25).abs() < 1e-12);
    }

    #[test]
    fn no_return_is_the_plateau_at_the_top() {
        let mut text = String::new();
        for k in 0..400 {
            let far = if k == 3 { "49.81" } else { "7.5" };
            text.push_str(&format!("FLASER 4 1 2 {far} 50.00 0 0 0 0 0 0 {k} h {k}\n"));
        }
        let log = parse(&text).unwrap();
        let limit = log.no_return_from_m();
        assert!(limit > 49.98 && limit < 49.991, "{limit}");
        assert!(49.81_f32 < limit as f32 && 49.99_f32 >= limit as f32);
        // Two codes at the top (81.83 and 81.91), and the field's cap.
        let text = "ROBOTLASER1 0 -1.57 3.14 0.0175 81.9 0.01 0 3 81.83 81.91 5 0 0 0 0 0 0 0 0 0 0 0 0 1 h 1\n";
        let limit = parse(&text.repeat(10)).unwrap().no_return_from_m();
        assert!((limit - 81.82).abs() < 1e-5, "{limit}");
        // No plateau: every reading is a return.
        let text = "FLASER 2 1 2 0 0 0 0 0 0 1 h 1\n";
        assert!(parse(text).unwrap().no_return_from_m() > 2.0);
    }

    #[test]
    fn errors_name_the_file_line_and_field() {
        for (text, says) in [
            ("ODOM 1 2\n", "t.clf, line 1, column `theta`: the line ends"),
            (
                "# c\nFLASER 3 1 x 2 0 0 0 0 0 0 1 h 1\n",
                "t.clf, line 2, column `range 2`: `x` is not a range",
            ),
            (
                "FLASER 2 1 -2 0 0 0 0 0 0 1 h 1\n",
                "column `range 2`: `-2` is not a range",
            ),
            (
                "FLASER many\n",
                "column `num_readings`: `many` is not a count",
            ),
            (
                "FLASER 2 1 1 0 0 0 0 0 0 -5 h 1\n",
                "column `ipc_timestamp`: -5 is negative",
            ),
            (
                "ODOM 1 2 nan 0 0 0 1 h 1\n",
                "column `theta`: `nan` is not a finite number",
            ),
            (
                "ROBOTLASER1 0 -1.57 3.14 0.0175 81.9 0.01 0 2 1 1 1\n",
                "column `remission 1`: the line ends",
            ),
        ] {
            let err = parse(text).unwrap_err().to_string();
            assert!(err.contains(says), "{err}");
        }
    }

    #[test]
    fn a_gzip_file_is_read_as_its_text() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let text = "ODOM 1 2 0.5 0 0 0 10.25 host 10.3\nFLASER 2 1 2 0 0 0 0 0 0 10.3 h 1\n";
        let plain = dir.path().join("a.clf");
        std::fs::write(&plain, text).unwrap();
        let gz = dir.path().join("a.clf.gz");
        let mut enc = flate2::write::GzEncoder::new(
            std::fs::File::create(&gz).unwrap(),
            flate2::Compression::default(),
        );
        enc.write_all(text.as_bytes()).unwrap();
        enc.finish().unwrap();
        let a = CarmenLog::read(&plain).unwrap();
        let b = CarmenLog::read(&gz).unwrap();
        assert_eq!((a.odometry, a.lasers), (b.odometry, b.lasers));
        let err = CarmenLog::read(&dir.path().join("missing.clf"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("missing.clf"), "{err}");
    }
}
