//! Generic calibration inputs as CSV: encoder logs (`t,left_ticks,right_ticks`
//! with cumulative counts, or `t,left_rad_s,right_rad_s` wheel speeds) and
//! pose references (`t,x,y,theta`, `theta` may be empty for position-only).
//! Times in seconds, strictly increasing. Extra columns are ignored.

use std::path::Path;

use crate::LogError;

/// What the two wheel columns hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WheelColumns {
    /// Cumulative encoder counts.
    Ticks,
    /// Wheel angular speeds in rad/s.
    RadPerSecond,
}

/// An encoder log, column by column.
#[derive(Debug, Clone, PartialEq)]
pub struct EncoderCsv {
    pub columns: WheelColumns,
    pub t_s: Vec<f64>,
    pub left: Vec<f64>,
    pub right: Vec<f64>,
}

/// A pose reference, column by column; `theta` is NaN where empty.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseCsv {
    pub t_s: Vec<f64>,
    pub x_m: Vec<f64>,
    pub y_m: Vec<f64>,
    pub theta_rad: Vec<f64>,
}

struct Table<'a> {
    path: &'a Path,
    names: Vec<String>,
}

impl Table<'_> {
    fn column(&self, name: &str, expected: &str) -> Result<usize, LogError> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| LogError::Line {
                path: self.path.into(),
                line: 1,
                message: format!(
                    "missing column `{name}`: expected a header {expected}, found `{}`",
                    self.names.join(",")
                ),
            })
    }

    fn error(&self, line: u64, col: usize, message: String) -> LogError {
        LogError::Field {
            path: self.path.into(),
            line,
            column: self.names[col].clone(),
            message,
        }
    }
}

fn field(record: &csv::ByteRecord, col: usize) -> &str {
    std::str::from_utf8(record.get(col).unwrap_or(b""))
        .unwrap_or("\u{fffd}")
        .trim()
}

fn number(table: &Table, record: &csv::ByteRecord, line: u64, col: usize) -> Result<f64, LogError> {
    let text = field(record, col);
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(table.error(
            line,
            col,
            format!("expected a finite number, found `{text}`"),
        )),
    }
}

fn integer(
    table: &Table,
    record: &csv::ByteRecord,
    line: u64,
    col: usize,
) -> Result<f64, LogError> {
    let text = field(record, col);
    match text.parse::<i64>() {
        Ok(v) if v.unsigned_abs() < (1 << 53) => Ok(v as f64),
        _ => Err(table.error(
            line,
            col,
            format!("expected an integer tick count, found `{text}`"),
        )),
    }
}

/// Opens a CSV and reads its header; errors for empty files.
fn open<'a>(
    path: &'a Path,
    expected: &str,
) -> Result<(csv::Reader<std::fs::File>, Table<'a>), LogError> {
    let file = std::fs::File::open(path).map_err(|e| LogError::io(path, e))?;
    let meta = file.metadata().map_err(|e| LogError::io(path, e))?;
    if meta.len() == 0 {
        return Err(LogError::format(
            path,
            format!("is empty: expected a header {expected} and data rows"),
        ));
    }
    // Cells are trimmed where they are read; trimming whole records in the
    // reader costs more.
    let mut reader = csv::ReaderBuilder::new().flexible(false).from_reader(file);
    let names = reader
        .headers()
        .map_err(|e| LogError::format(path, format!("cannot read the header: {e}")))?
        .iter()
        .map(|n| n.trim().to_owned())
        .collect();
    Ok((reader, Table { path, names }))
}

/// Reads every row, checking that times strictly increase.
fn rows(
    reader: &mut csv::Reader<std::fs::File>,
    table: &Table,
    t_col: usize,
    mut row: impl FnMut(&csv::ByteRecord, u64) -> Result<(), LogError>,
) -> Result<Vec<f64>, LogError> {
    let mut record = csv::ByteRecord::new();
    let mut times = Vec::new();
    let mut prev_line = 0;
    loop {
        match reader.read_byte_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                return Err(LogError::Line {
                    path: table.path.into(),
                    line: e.position().map_or(0, |p| p.line()),
                    message: e.to_string(),
                });
            }
        }
        let line = record.position().map_or(0, |p| p.line());
        let t = number(table, &record, line, t_col)?;
        if let Some(&prev) = times.last() {
            if t == prev {
                return Err(table.error(
                    line,
                    t_col,
                    format!("duplicate timestamp {t} (also on line {prev_line})"),
                ));
            }
            if t < prev {
                return Err(table.error(
                    line,
                    t_col,
                    format!(
                        "time {t} goes back from {prev} on line {prev_line}; times must increase"
                    ),
                ));
            }
        }
        row(&record, line)?;
        times.push(t);
        prev_line = line;
    }
    if times.is_empty() {
        return Err(LogError::format(
            table.path,
            "has a header but no data rows",
        ));
    }
    Ok(times)
}

/// Reads an encoder log.
pub fn read_encoder_csv(path: &Path) -> Result<EncoderCsv, LogError> {
    const EXPECTED: &str = "`t,left_ticks,right_ticks` or `t,left_rad_s,right_rad_s`";
    let (mut reader, table) = open(path, EXPECTED)?;
    let columns = if table.names.iter().any(|n| n == "left_ticks") {
        WheelColumns::Ticks
    } else if table.names.iter().any(|n| n == "left_rad_s") {
        WheelColumns::RadPerSecond
    } else {
        return Err(LogError::Line {
            path: path.into(),
            line: 1,
            message: format!(
                "expected a header {EXPECTED}, found `{}`",
                table.names.join(",")
            ),
        });
    };
    let (l_name, r_name) = match columns {
        WheelColumns::Ticks => ("left_ticks", "right_ticks"),
        WheelColumns::RadPerSecond => ("left_rad_s", "right_rad_s"),
    };
    let t_col = table.column("t", EXPECTED)?;
    let (l_col, r_col) = (
        table.column(l_name, EXPECTED)?,
        table.column(r_name, EXPECTED)?,
    );
    let (mut left, mut right) = (Vec::new(), Vec::new());
    let t_s = rows(&mut reader, &table, t_col, |rec, line| {
        let parse = match columns {
            WheelColumns::Ticks => integer,
            WheelColumns::RadPerSecond => number,
        };
        left.push(parse(&table, rec, line, l_col)?);
        right.push(parse(&table, rec, line, r_col)?);
        Ok(())
    })?;
    Ok(EncoderCsv {
        columns,
        t_s,
        left,
        right,
    })
}

/// Reads a pose reference.
pub fn read_pose_csv(path: &Path) -> Result<PoseCsv, LogError> {
    const EXPECTED: &str = "`t,x,y,theta`";
    let (mut reader, table) = open(path, EXPECTED)?;
    let t_col = table.column("t", EXPECTED)?;
    let (x_col, y_col, th_col) = (
        table.column("x", EXPECTED)?,
        table.column("y", EXPECTED)?,
        table.column("theta", EXPECTED)?,
    );
    let (mut x_m, mut y_m, mut theta_rad) = (Vec::new(), Vec::new(), Vec::new());
    let t_s = rows(&mut reader, &table, t_col, |rec, line| {
        x_m.push(number(&table, rec, line, x_col)?);
        y_m.push(number(&table, rec, line, y_col)?);
        theta_rad.push(if field(rec, th_col).is_empty() {
            f64::NAN
        } else {
            number(&table, rec, line, th_col)?
        });
        Ok(())
    })?;
    Ok(PoseCsv {
        t_s,
        x_m,
        y_m,
        theta_rad,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("in.csv");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    fn enc_err(text: &str) -> String {
        let (_d, p) = write(text);
        read_encoder_csv(&p).unwrap_err().to_string()
    }

    fn pose_err(text: &str) -> String {
        let (_d, p) = write(text);
        read_pose_csv(&p).unwrap_err().to_string()
    }

    #[test]
    fn reads_both_encoder_kinds_and_position_only_poses() {
        let (_d, p) = write("t,left_ticks,right_ticks\n0.0,0,0\n0.02,5,-7\n");
        let e = read_encoder_csv(&p).unwrap();
        assert_eq!(e.columns, WheelColumns::Ticks);
        assert_eq!((e.left[1], e.right[1]), (5.0, -7.0));
        let (_d, p) = write("t,left_rad_s,right_rad_s,extra\n1,0.5,0.25,x\n2,0.5,0.5,y\n");
        assert_eq!(
            read_encoder_csv(&p).unwrap().columns,
            WheelColumns::RadPerSecond
        );
        let (_d, p) = write("t,x,y,theta\n0,1,2,\n0.5,1.5,2,0.1\n");
        let poses = read_pose_csv(&p).unwrap();
        assert!(poses.theta_rad[0].is_nan() && poses.theta_rad[1] == 0.1);
    }

    #[test]
    fn bad_input_names_file_line_and_column() {
        assert!(enc_err("").contains("in.csv: is empty"));
        assert!(enc_err("t,left_ticks,right_ticks\n").contains("has a header but no data rows"));
        assert!(enc_err("t,left,right\n0,1,2\n").contains("in.csv, line 1: expected a header"));
        let e = enc_err("t,left_ticks\n0,1\n");
        assert!(e.contains("line 1: missing column `right_ticks`"), "{e}");
        let e = enc_err("t,left_ticks,right_ticks\n0,0,0\n0.02,abc,1\n");
        assert!(
            e.contains(
                "in.csv, line 3, column `left_ticks`: expected an integer tick count, found `abc`"
            ),
            "{e}"
        );
        let e = enc_err("t,left_rad_s,right_rad_s\n0,0,0\n0.02,NaN,1\n");
        assert!(
            e.contains("line 3, column `left_rad_s`: expected a finite number, found `NaN`"),
            "{e}"
        );
        let e = enc_err("t,left_ticks,right_ticks\n0,0,0\n0,1,1\n");
        assert!(
            e.contains("line 3, column `t`: duplicate timestamp 0 (also on line 2)"),
            "{e}"
        );
        let e = pose_err("t,x,y,theta\n1,0,0,0\n0.5,0,0,0\n");
        assert!(
            e.contains("line 3, column `t`: time 0.5 goes back from 1 on line 2"),
            "{e}"
        );
        let e = pose_err("t,x,theta\n1,0,0\n");
        assert!(e.contains("missing column `y`"), "{e}");
        let e = pose_err("t,x,y,theta\n1,0,inf,0\n");
        assert!(
            e.contains("column `y`: expected a finite number, found `inf`"),
            "{e}"
        );
        let e = pose_err("t,x,y,theta\n1,0,0\n");
        assert!(e.contains("line 2"), "{e}");
    }
}
