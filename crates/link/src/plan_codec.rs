//! A compact, lossless encoding of a plan document for the link.
//!
//! The robot must store exactly the `plan.json` the master signed, so the
//! encoding carries every number's exact bits and the robot rebuilds the
//! document byte for byte (`serde_json`'s pretty form of the decoded plan);
//! the envelope's SHA-256 of the document is checked on the rebuilt bytes.
//! A document that does not rebuild to itself (written by another tool)
//! travels as compressed JSON instead.
//!
//! Samples travel as columns. Each number is predicted from what came
//! before (the previous value, a straight-line extrapolation, or for
//! poses an arc step with the previous sample's speeds; wheel speeds from
//! the body speeds through the calibrated parameters), and only the XOR of
//! its bits with the prediction's is kept: an exact prediction is eight
//! zero bytes, a close one has zero high bytes. The residuals are split
//! into byte planes (all the most significant bytes first) and the whole is
//! compressed with zstd, which then finds the long runs of zeros.

use serde::{Deserialize, Serialize};
use twindrive_kinematics::{Pose, arc_step, wheel_speeds};
use twindrive_plan::{MissionPlan, PlanHeader, PlanSample};

/// First bytes of an encoded plan.
pub const MAGIC: &[u8; 8] = b"TWDPLAN2";

/// Why bytes are not an encoded plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CodecError {
    #[error("not an encoded plan: {0}")]
    Malformed(String),
    #[error("the plan does not rebuild to its own bytes")]
    NotCanonical,
}

/// What travels besides the columns.
#[derive(Serialize, Deserialize)]
struct Head {
    format: String,
    version: u32,
    sha256: String,
    header_json: String,
    samples: u32,
    /// The document ends with a newline after the JSON.
    newline: bool,
    /// Predictor chosen per column.
    predictors: Vec<u8>,
}

const COLUMNS: usize = 8;

fn pose_of(s: &PlanSample) -> Pose {
    s.pose()
}

/// Predictions of column `c` at sample `i` by predictor `p`.
fn predict(
    samples: &[PlanSample],
    header: &PlanHeader,
    i: usize,
    c: usize,
    p: u8,
    value: impl Fn(&PlanSample, usize) -> f64,
) -> f64 {
    if i == 0 {
        return 0.0;
    }
    let prev = value(&samples[i - 1], c);
    match p {
        0 => prev,
        1 => {
            if i == 1 {
                prev
            } else {
                2.0 * prev - value(&samples[i - 2], c)
            }
        }
        // Arc step with the previous sample's speeds (poses) or wheel speeds
        // from this sample's body speeds (wheels).
        _ => match c {
            1..=3 => {
                let a = &samples[i - 1];
                let dt = samples[i].t_s - a.t_s;
                let next = arc_step(&pose_of(a), a.v_m_s * dt, a.omega_rad_s * dt);
                [next.x_m, next.y_m, next.heading_rad][c - 1]
            }
            6 | 7 => {
                let s = &samples[i];
                let (l, r) = wheel_speeds(&header.calibrated, s.v_m_s, s.omega_rad_s);
                if c == 6 { l } else { r }
            }
            _ => prev,
        },
    }
}

fn column(s: &PlanSample, c: usize) -> f64 {
    match c {
        0 => s.t_s,
        1 => s.x_m,
        2 => s.y_m,
        3 => s.heading_rad,
        4 => s.v_m_s,
        5 => s.omega_rad_s,
        6 => s.left_rad_s,
        _ => s.right_rad_s,
    }
}

fn set_column(s: &mut PlanSample, c: usize, v: f64) {
    match c {
        0 => s.t_s = v,
        1 => s.x_m = v,
        2 => s.y_m = v,
        3 => s.heading_rad = v,
        4 => s.v_m_s = v,
        5 => s.omega_rad_s = v,
        6 => s.left_rad_s = v,
        _ => s.right_rad_s = v,
    }
}

fn candidates(c: usize) -> &'static [u8] {
    match c {
        1..=3 | 6 | 7 => &[0, 1, 2],
        _ => &[0, 1],
    }
}

/// Appends `residuals` as eight byte planes, most significant first.
fn push_planes(out: &mut Vec<u8>, residuals: &[u64]) {
    for shift in (0..8).rev() {
        out.extend(residuals.iter().map(|r| (r >> (8 * shift)) as u8));
    }
}

fn cost(residuals: &[u64]) -> u64 {
    // Bytes that are not leading zeros.
    residuals
        .iter()
        .map(|r| u64::from(8 - r.leading_zeros() / 8))
        .sum()
}

/// The plan document in its compact form, or `None` when `plan_json` is not
/// the canonical (pretty) form of its plan, which the robot could not rebuild.
pub fn encode(plan_json: &[u8]) -> Option<Vec<u8>> {
    let plan: MissionPlan = serde_json::from_slice(plan_json).ok()?;
    let pretty = serde_json::to_vec_pretty(&plan).ok()?;
    let newline = match plan_json.strip_prefix(pretty.as_slice()) {
        Some(b"") => false,
        Some(b"\n") => true,
        _ => return None,
    };
    let n = plan.samples.len();
    let mut body = Vec::with_capacity(n * COLUMNS * 8 + n / 8 + 1);
    let mut predictors = Vec::with_capacity(COLUMNS);
    for c in 0..COLUMNS {
        let residuals_for = |p: u8| -> Vec<u64> {
            (0..n)
                .map(|i| {
                    let pred = predict(&plan.samples, &plan.header, i, c, p, column);
                    column(&plan.samples[i], c).to_bits() ^ pred.to_bits()
                })
                .collect()
        };
        let (p, residuals) = candidates(c)
            .iter()
            .map(|&p| (p, residuals_for(p)))
            .min_by_key(|(_, r)| cost(r))
            .expect("a predictor");
        predictors.push(p);
        push_planes(&mut body, &residuals);
    }
    let mut bits = vec![0u8; n.div_ceil(8)];
    for (i, s) in plan.samples.iter().enumerate() {
        if s.expected_bump {
            bits[i / 8] |= 1 << (i % 8);
        }
    }
    body.extend_from_slice(&bits);
    let head = Head {
        format: plan.format.clone(),
        version: plan.version,
        sha256: plan.sha256.clone(),
        header_json: serde_json::to_string(&plan.header).ok()?,
        samples: n as u32,
        newline,
        predictors,
    };
    let head = postcard::to_allocvec(&head).ok()?;
    let mut raw = Vec::with_capacity(head.len() + body.len() + 4);
    raw.extend_from_slice(&(head.len() as u32).to_le_bytes());
    raw.extend_from_slice(&head);
    raw.extend_from_slice(&body);
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(&(raw.len() as u64).to_le_bytes());
    out.extend(zstd::bulk::compress(&raw, 19).ok()?);
    // What the robot will rebuild must be these bytes.
    (decode(&out, raw.len() as u64 + 16).ok()? == plan_json).then_some(out)
}

/// Rebuilds the plan document from its compact form; nothing longer than
/// `max_raw_bytes` is decompressed.
pub fn decode(bytes: &[u8], max_raw_bytes: u64) -> Result<Vec<u8>, CodecError> {
    let bad = |m: &str| CodecError::Malformed(m.into());
    let rest = bytes
        .strip_prefix(MAGIC.as_slice())
        .ok_or_else(|| bad("no TWDPLAN2"))?;
    let (len, rest) = rest
        .split_first_chunk::<8>()
        .ok_or_else(|| bad("no length"))?;
    let raw_len = u64::from_le_bytes(*len);
    if raw_len > max_raw_bytes {
        return Err(bad("longer than allowed"));
    }
    let raw = zstd::bulk::decompress(rest, raw_len as usize)
        .map_err(|e| CodecError::Malformed(format!("zstd: {e}")))?;
    let (hl, raw) = raw
        .split_first_chunk::<4>()
        .ok_or_else(|| bad("no head length"))?;
    let hl = u32::from_le_bytes(*hl) as usize;
    if raw.len() < hl {
        return Err(bad("short head"));
    }
    let head: Head = postcard::from_bytes(&raw[..hl])
        .map_err(|e| CodecError::Malformed(format!("head: {e}")))?;
    let body = &raw[hl..];
    let n = head.samples as usize;
    let need = COLUMNS
        .checked_mul(n)
        .and_then(|x| x.checked_mul(8))
        .and_then(|x| x.checked_add(n.div_ceil(8)))
        .ok_or_else(|| bad("sizes overflow"))?;
    if body.len() != need || head.predictors.len() != COLUMNS {
        return Err(bad("body size does not match its head"));
    }
    let header: PlanHeader = serde_json::from_str(&head.header_json)
        .map_err(|e| CodecError::Malformed(format!("header: {e}")))?;
    let read = |col: usize, i: usize| -> u64 {
        (0..8).fold(0u64, |acc, plane| {
            (acc << 8) | u64::from(body[(col * 8 + plane) * n + i])
        })
    };
    let blank = PlanSample {
        t_s: 0.0,
        x_m: 0.0,
        y_m: 0.0,
        heading_rad: 0.0,
        v_m_s: 0.0,
        omega_rad_s: 0.0,
        left_rad_s: 0.0,
        right_rad_s: 0.0,
        expected_bump: false,
    };
    let mut samples = vec![blank; n];
    // Columns in order, so every prediction uses only decoded values (the
    // wheel speeds' come from this sample's body speeds, decoded before).
    for i in 0..n {
        for c in 0..COLUMNS {
            let pred = predict(&samples, &header, i, c, head.predictors[c], column);
            let v = f64::from_bits(read(c, i) ^ pred.to_bits());
            set_column(&mut samples[i], c, v);
        }
        samples[i].expected_bump = body[COLUMNS * 8 * n + i / 8] & (1 << (i % 8)) != 0;
    }
    let plan = MissionPlan {
        format: head.format,
        version: head.version,
        header,
        samples,
        sha256: head.sha256,
    };
    let mut json = serde_json::to_vec_pretty(&plan).map_err(|_| CodecError::NotCanonical)?;
    if head.newline {
        json.push(b'\n');
    }
    Ok(json)
}
