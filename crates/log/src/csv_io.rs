//! The mission log as CSV: one row per simulation step.
//!
//! Columns, in order: `t` (seconds), `cmd_left_rad_s`, `cmd_right_rad_s`,
//! `left_rad_s`, `right_rad_s`, `left_ticks`, `right_ticks`, `bump` (0/1),
//! `tracker_x`, `tracker_y`, `tracker_theta`, `gt_x`, `gt_y`, `gt_theta`, then
//! `gyro_z_rad_s` when the header has a gyro, then one column per range beam: `range_<name>` for a single-beam sensor,
//! `range_<name>_<beam>` otherwise. Empty cells mean "did not sample".
//! Floats are written in their shortest exact form, so a read-back is bit-identical.

use std::io::{Read, Write};
use std::path::Path;

use twindrive_kinematics::Pose;

use crate::{LogError, LogHeader, MissionLog, StepRecord, format_seconds, ns_from_seconds};

const FIXED_COLUMNS: [&str; 14] = [
    "t",
    "cmd_left_rad_s",
    "cmd_right_rad_s",
    "left_rad_s",
    "right_rad_s",
    "left_ticks",
    "right_ticks",
    "bump",
    "tracker_x",
    "tracker_y",
    "tracker_theta",
    "gt_x",
    "gt_y",
    "gt_theta",
];

/// The gyro's column, present only in logs of a robot with a gyro.
const GYRO_COLUMN: &str = "gyro_z_rad_s";

/// The columns after the fixed ones: the gyro's, if any, then the range beams.
fn sensor_columns(header: &LogHeader) -> Vec<String> {
    let mut cols = Vec::new();
    if header.gyro.is_some() {
        cols.push(GYRO_COLUMN.to_string());
    }
    for s in &header.range_sensors {
        if s.beams == 1 {
            cols.push(format!("range_{}", s.name));
        } else {
            cols.extend((0..s.beams).map(|b| format!("range_{}_{b}", s.name)));
        }
    }
    cols
}

/// Writes the log's rows (the header belongs in its JSON sidecar).
pub fn write_csv<W: Write>(log: &MissionLog, out: W) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    let sensors = sensor_columns(&log.header);
    w.write_record(
        FIXED_COLUMNS
            .iter()
            .copied()
            .chain(sensors.iter().map(String::as_str)),
    )?;
    let gyro = log.header.gyro.is_some();
    let per_step = log.beams_per_step();
    let mut fields: Vec<String> = Vec::with_capacity(FIXED_COLUMNS.len() + 1 + per_step);
    let opt = |v: Option<String>| v.unwrap_or_default();
    for (k, s) in log.steps.iter().enumerate() {
        fields.clear();
        fields.push(format_seconds(s.t_ns));
        fields.extend(
            s.cmd_wheel_rad_s
                .iter()
                .chain(&s.wheel_rad_s)
                .map(f64::to_string),
        );
        fields.push(opt(s.encoder_ticks.map(|t| t[0].to_string())));
        fields.push(opt(s.encoder_ticks.map(|t| t[1].to_string())));
        fields.push(if s.bump { "1" } else { "0" }.to_string());
        fields.push(opt(s.tracker.map(|p| p.x_m.to_string())));
        fields.push(opt(s.tracker.map(|p| p.y_m.to_string())));
        fields.push(opt(s.tracker.map(|p| p.heading_rad.to_string())));
        let gt = &s.ground_truth;
        fields.extend([gt.x_m, gt.y_m, gt.heading_rad].iter().map(f64::to_string));
        if gyro {
            fields.push(opt(s.gyro_z_rad_s.map(|w| w.to_string())));
        }
        for r in &log.ranges[k * per_step..(k + 1) * per_step] {
            fields.push(if r.is_nan() {
                String::new()
            } else {
                r.to_string()
            });
        }
        w.write_record(&fields)?;
    }
    w.flush()?;
    Ok(())
}

/// Reads rows written by [`write_csv`], checking them against `header`.
pub fn read_csv(path: &Path, header: &LogHeader) -> Result<MissionLog, LogError> {
    let file = std::fs::File::open(path).map_err(|e| LogError::io(path, e))?;
    read_csv_from(std::io::BufReader::new(file), path, header)
}

/// As [`read_csv`], from any reader; `path` only labels errors.
pub fn read_csv_from<R: Read>(
    input: R,
    path: &Path,
    header: &LogHeader,
) -> Result<MissionLog, LogError> {
    let mut r = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(input);
    let names: Vec<String> = r
        .headers()
        .map_err(|e| LogError::format(path, format!("cannot read the header row: {e}")))?
        .iter()
        .map(str::to_owned)
        .collect();
    let expected: Vec<String> = FIXED_COLUMNS
        .iter()
        .map(|c| c.to_string())
        .chain(sensor_columns(header))
        .collect();
    let gyro_column = header.gyro.as_ref().map(|_| FIXED_COLUMNS.len());
    let first_range = FIXED_COLUMNS.len() + usize::from(gyro_column.is_some());
    for (i, want) in expected.iter().enumerate() {
        match names.get(i) {
            Some(got) if got == want => {}
            Some(got) => {
                return Err(LogError::Line {
                    path: path.into(),
                    line: 1,
                    message: format!("column {} is `{got}`, expected `{want}`", i + 1),
                });
            }
            None => {
                return Err(LogError::Line {
                    path: path.into(),
                    line: 1,
                    message: format!("missing column `{want}`"),
                });
            }
        }
    }
    if names.len() > expected.len() {
        return Err(LogError::Line {
            path: path.into(),
            line: 1,
            message: format!("unexpected extra column `{}`", names[expected.len()]),
        });
    }

    let mut log = MissionLog::new(header.clone());
    let mut record = csv::StringRecord::new();
    loop {
        match r.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map_or(0, |p| p.line());
                return Err(LogError::Line {
                    path: path.into(),
                    line,
                    message: e.to_string(),
                });
            }
        }
        let line = record.position().map_or(0, |p| p.line());
        let cell = Cell {
            path,
            line,
            names: &names,
            record: &record,
        };
        let t_s: f64 = cell.parse(0)?;
        let t_ns = ns_from_seconds(t_s).ok_or_else(|| cell.error(0, "expected a time >= 0 s"))?;
        if let Some(prev) = log.steps.last()
            && t_ns <= prev.t_ns
        {
            return Err(cell.error(0, "time must increase from row to row"));
        }
        let ticks = match (cell.optional::<i64>(5)?, cell.optional::<i64>(6)?) {
            (Some(l), Some(r)) => Some([l, r]),
            (None, None) => None,
            _ => {
                return Err(cell.error(
                    6,
                    "left_ticks and right_ticks must both be set or both empty",
                ));
            }
        };
        let bump = match cell.text(7) {
            "0" => false,
            "1" => true,
            _ => return Err(cell.error(7, "expected 0 or 1")),
        };
        let tracker = match (cell.optional(8)?, cell.optional(9)?, cell.optional(10)?) {
            (Some(x), Some(y), Some(th)) => Some(Pose::new(x, y, th)),
            (None, None, None) => None,
            _ => {
                return Err(cell.error(
                    8,
                    "tracker_x, tracker_y and tracker_theta must all be set or all empty",
                ));
            }
        };
        log.steps.push(StepRecord {
            t_ns,
            cmd_wheel_rad_s: [cell.parse(1)?, cell.parse(2)?],
            wheel_rad_s: [cell.parse(3)?, cell.parse(4)?],
            encoder_ticks: ticks,
            bump,
            tracker,
            ground_truth: Pose::new(cell.parse(11)?, cell.parse(12)?, cell.parse(13)?),
            gyro_z_rad_s: match gyro_column {
                Some(c) => cell.optional(c)?,
                None => None,
            },
        });
        for c in first_range..names.len() {
            log.ranges.push(cell.optional(c)?.unwrap_or(f64::NAN));
        }
    }
    Ok(log)
}

/// One row being parsed, for errors that name line and column.
struct Cell<'a> {
    path: &'a Path,
    line: u64,
    names: &'a [String],
    record: &'a csv::StringRecord,
}

impl Cell<'_> {
    fn text(&self, col: usize) -> &str {
        self.record.get(col).unwrap_or("").trim()
    }

    fn error(&self, col: usize, message: &str) -> LogError {
        LogError::Field {
            path: self.path.into(),
            line: self.line,
            column: self.names[col].clone(),
            message: format!("{message} (found `{}`)", self.text(col)),
        }
    }

    fn optional<T: std::str::FromStr + Finite>(&self, col: usize) -> Result<Option<T>, LogError> {
        let text = self.text(col);
        if text.is_empty() {
            return Ok(None);
        }
        match text.parse::<T>() {
            Ok(v) if v.is_finite_value() => Ok(Some(v)),
            _ => Err(self.error(col, T::EXPECTED)),
        }
    }

    fn parse<T: std::str::FromStr + Finite>(&self, col: usize) -> Result<T, LogError> {
        self.optional(col)?
            .ok_or_else(|| self.error(col, T::EXPECTED))
    }
}

trait Finite {
    const EXPECTED: &'static str;
    fn is_finite_value(&self) -> bool;
}

impl Finite for f64 {
    const EXPECTED: &'static str = "expected a finite number";
    fn is_finite_value(&self) -> bool {
        self.is_finite()
    }
}

impl Finite for i64 {
    const EXPECTED: &'static str = "expected an integer";
    fn is_finite_value(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{assert_same, sample_log};

    fn parse(text: &str) -> Result<MissionLog, LogError> {
        let log = sample_log();
        read_csv_from(text.as_bytes(), Path::new("x.csv"), &log.header)
    }

    #[test]
    fn round_trip_is_exact() {
        let log = sample_log();
        let mut bytes = Vec::new();
        write_csv(&log, &mut bytes).unwrap();
        let back = read_csv_from(bytes.as_slice(), Path::new("mem.csv"), &log.header).unwrap();
        assert_same(&log, &back);
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.starts_with(
            "t,cmd_left_rad_s,cmd_right_rad_s,left_rad_s,right_rad_s,left_ticks,right_ticks,bump,"
        ));
        assert!(
            text.lines()
                .next()
                .unwrap()
                .ends_with("range_side_ir,range_scan_0,range_scan_1,range_scan_2,range_scan_3")
        );
    }

    #[test]
    fn the_gyro_column_is_there_only_with_a_gyro() {
        let log = crate::testutil::sample_log_with_gyro();
        let mut bytes = Vec::new();
        write_csv(&log, &mut bytes).unwrap();
        let back = read_csv_from(bytes.as_slice(), Path::new("mem.csv"), &log.header).unwrap();
        assert_same(&log, &back);
        let text = String::from_utf8(bytes).unwrap();
        let mut lines = text.lines();
        assert!(
            lines
                .next()
                .unwrap()
                .contains(",gt_theta,gyro_z_rad_s,range_side_ir,")
        );
        let first: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(first[14], "-0.03333333333333333");
        let second: Vec<&str> = text.lines().nth(2).unwrap().split(',').collect();
        assert_eq!(second[14], "");

        // A gyro column the header does not announce, and one it misses.
        let err = parse(&text).unwrap_err().to_string();
        assert!(
            err.contains("column 15 is `gyro_z_rad_s`, expected `range_side_ir`"),
            "{err}"
        );
        let mut plain = Vec::new();
        write_csv(&sample_log(), &mut plain).unwrap();
        let err = read_csv_from(plain.as_slice(), Path::new("x.csv"), &log.header)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("column 15 is `range_side_ir`, expected `gyro_z_rad_s`"),
            "{err}"
        );
        let bad = text.replacen("-0.03333333333333333", "fast", 1);
        let err = read_csv_from(bad.as_bytes(), Path::new("x.csv"), &log.header)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("line 2, column `gyro_z_rad_s`: expected a finite number"),
            "{err}"
        );
    }

    #[test]
    fn bad_cells_name_line_and_column() {
        let log = sample_log();
        let mut bytes = Vec::new();
        write_csv(&log, &mut bytes).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        lines[3] = lines[3].replacen(",0,", ",maybe,", 1);
        let err = parse(&lines.join("\n")).unwrap_err().to_string();
        assert!(err.contains("x.csv, line 4, column `bump`"), "{err}");

        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        let mut cells: Vec<&str> = lines[2].split(',').collect();
        cells[11] = "NaN";
        lines[2] = cells.join(",");
        let err = parse(&lines.join("\n")).unwrap_err().to_string();
        assert!(
            err.contains("line 3, column `gt_x`: expected a finite number"),
            "{err}"
        );

        let err = parse("t,cmd_left_rad_s\n0,1\n").unwrap_err().to_string();
        assert!(
            err.contains("line 1: missing column `cmd_right_rad_s`"),
            "{err}"
        );
    }

    #[test]
    fn time_must_increase() {
        let log = sample_log();
        let mut bytes = Vec::new();
        write_csv(&log, &mut bytes).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        lines.swap(2, 3);
        let err = parse(&lines.join("\n")).unwrap_err().to_string();
        assert!(err.contains("column `t`: time must increase"), "{err}");
    }
}
