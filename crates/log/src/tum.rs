//! TUM trajectory format (`t x y z qx qy qz qw`), as read by `evo`.

use std::io::{BufRead, Write};
use std::path::Path;

use twindrive_kinematics::Pose;

use crate::{LogError, ns_from_seconds, push_seconds};

/// Writes planar poses as TUM lines (z = 0, rotation about +z).
/// Bytes gathered before each write.
const BLOCK_BYTES: usize = 1 << 16;

pub fn write_tum<W: Write>(
    poses: impl IntoIterator<Item = (u64, Pose)>,
    mut out: W,
) -> std::io::Result<()> {
    // ryu: shortest round-trip decimals, several times faster than `{}`;
    // lines are built in one reused buffer and written in blocks.
    let mut buf = ryu::Buffer::new();
    let mut block: Vec<u8> = Vec::with_capacity(BLOCK_BYTES + 256);
    for (t_ns, p) in poses {
        let (qz, qw) = (0.5 * p.heading_rad).sin_cos();
        push_seconds(&mut block, t_ns);
        for (sep, v) in [(" ", p.x_m), (" ", p.y_m), (" 0 0 0 ", qz), (" ", qw)] {
            block.extend_from_slice(sep.as_bytes());
            block.extend_from_slice(buf.format(v).as_bytes());
        }
        block.push(b'\n');
        if block.len() >= BLOCK_BYTES {
            out.write_all(&block)?;
            block.clear();
        }
    }
    out.write_all(&block)?;
    out.flush()
}

/// Reads a TUM file into (t_ns, planar pose); `#` lines are comments.
/// Headings are the yaw of each quaternion, in (-π, π].
pub fn read_tum(path: &Path) -> Result<Vec<(u64, Pose)>, LogError> {
    let file = std::fs::File::open(path).map_err(|e| LogError::io(path, e))?;
    let mut out = Vec::new();
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let line_no = i as u64 + 1;
        let line = line.map_err(|e| LogError::io(path, e))?;
        let text = line.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let bad = |message: String| LogError::Line {
            path: path.into(),
            line: line_no,
            message,
        };
        let values: Vec<f64> = text
            .split_whitespace()
            .map(|v| v.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| bad(format!("expected 8 finite numbers, found `{text}`")))?;
        let [t, x, y, _z, qx, qy, qz, qw] = values[..] else {
            return Err(bad(format!(
                "expected 8 numbers `t x y z qx qy qz qw`, found {}",
                values.len()
            )));
        };
        let t_ns = ns_from_seconds(t).ok_or_else(|| bad(format!("time {t} is negative")))?;
        if out.last().is_some_and(|(prev, _)| *prev >= t_ns) {
            return Err(bad("time must increase from line to line".into()));
        }
        let yaw = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
        out.push((t_ns, Pose::new(x, y, yaw)));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        let poses = vec![
            (0, Pose::new(0.0, 0.0, 0.0)),
            (10_000_000, Pose::new(1.5, -2.25, 1.0)),
            (20_000_000, Pose::new(3.0, 4.0, -3.0)),
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.tum");
        write_tum(poses.clone(), std::fs::File::create(&path).unwrap()).unwrap();
        let back = read_tum(&path).unwrap();
        for ((t0, p0), (t1, p1)) in poses.iter().zip(&back) {
            assert_eq!(t0, t1);
            assert_eq!((p0.x_m, p0.y_m), (p1.x_m, p1.y_m));
            assert!((p0.heading_rad - p1.heading_rad).abs() < 1e-12);
        }
    }
}
