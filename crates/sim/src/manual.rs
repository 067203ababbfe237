//! Manual drives: timed (v, ω) commands, and the CSV file they are read from.

use std::path::Path;

use crate::SimError;

/// One timed command of a manual drive, held until the next one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ManualCommand {
    pub t_ns: u64,
    pub v_m_s: f64,
    pub omega_rad_s: f64,
}

/// Reads a manual command file: CSV with header `t_s,v_m_s,omega_rad_s`,
/// times strictly increasing.
pub fn read_manual_commands(path: &Path) -> Result<Vec<ManualCommand>, SimError> {
    let text = std::fs::read_to_string(path).map_err(|e| SimError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let bad = |line: usize, message: String| SimError::Commands {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == "t_s,v_m_s,omega_rad_s" => {}
        _ => return Err(bad(1, "expected the header `t_s,v_m_s,omega_rad_s`".into())),
    }
    let mut out: Vec<ManualCommand> = Vec::new();
    for (i, line) in lines {
        let line_no = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != 3 {
            return Err(bad(
                line_no,
                format!("expected 3 columns, found {}", cells.len()),
            ));
        }
        let mut values = [0.0; 3];
        for (k, (cell, name)) in cells
            .iter()
            .zip(["t_s", "v_m_s", "omega_rad_s"])
            .enumerate()
        {
            values[k] = cell
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(
                        line_no,
                        format!("column `{name}`: expected a finite number, found `{cell}`"),
                    )
                })?;
        }
        let t_ns = twindrive_log::ns_from_seconds(values[0]).ok_or_else(|| {
            bad(
                line_no,
                format!("column `t_s`: must be >= 0, found {}", values[0]),
            )
        })?;
        if out.last().is_some_and(|c| c.t_ns >= t_ns) {
            return Err(bad(line_no, "column `t_s`: times must increase".into()));
        }
        out.push(ManualCommand {
            t_ns,
            v_m_s: values[1],
            omega_rad_s: values[2],
        });
    }
    if out.is_empty() {
        return Err(bad(1, "no commands after the header".into()));
    }
    Ok(out)
}
