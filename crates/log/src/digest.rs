//! A mission log for the link: what the master needs of a robot's log,
//! within a byte budget per second of mission.
//!
//! The robot keeps its full log (MCAP and CSV, every value as measured);
//! this is what comes home over a slow link. Each column is quantized
//! (below), delta-coded against its previous value, written as zigzag
//! varints column by column, and the whole compressed with zstd. Time and
//! encoder counts are exact; the rest is rounded:
//!
//! | column | step |
//! |---|---|
//! | wheel speeds commanded and reached | 1 mrad/s |
//! | tracker and best-estimate positions | 0.1 mm |
//! | headings | 10 µrad |
//! | gyro | 10 µrad/s |
//! | ranges | 1 mm |
//!
//! When the result exceeds the budget, range sweeps are thinned (every
//! second sampled sweep of each sensor dropped, then every second of what
//! is left, ...) until it fits; the header says how many were kept.

use std::io::Read;

use twindrive_kinematics::Pose;

use crate::{LogHeader, MissionLog, StepRecord};

/// What a digest costs at most by default: bytes per second of mission.
pub const DEFAULT_BUDGET_BYTES_PER_S: f64 = 4000.0;

const MAGIC: &[u8; 8] = b"TDLOGDG1";
const SPEED_STEP: f64 = 1e-3;
const POSITION_STEP: f64 = 1e-4;
const ANGLE_STEP: f64 = 1e-5;
const RANGE_STEP: f64 = 1e-3;
/// A range the sensor did not sample (NaN), in range steps.
const NO_RANGE: i64 = -1;
const ZSTD_LEVEL: i32 = 19;
/// zstd's level for the size of a thinning that may be far over the
/// budget: about fifty times faster than [`ZSTD_LEVEL`] on these columns.
const QUICK_LEVEL: i32 = 3;
/// [`ZSTD_LEVEL`] makes these columns smaller than [`QUICK_LEVEL`] does,
/// but by far less than this: 1.4 to 4 % on a 361-beam lidar's 90 s (the
/// demo's mapped site). A thinning whose quick size is over the budget by
/// more than this factor is not compressed at [`ZSTD_LEVEL`] at all.
const QUICK_OVER_AT_MOST: f64 = 1.0 / 0.85;

/// Why bytes are not a digest.
#[derive(Debug, thiserror::Error)]
#[error("not a twindrive log digest: {0}")]
pub struct DigestError(String);

/// A digest of `log` in at most `budget_bytes_per_s` per second of mission
/// (its range sweeps thinned if need be), and the fraction of sampled
/// sweeps it kept.
pub fn encode(log: &MissionLog, budget_bytes_per_s: f64) -> (Vec<u8>, f64) {
    let mission_s = match (log.steps.first(), log.steps.last()) {
        (Some(a), Some(b)) => (b.t_s() - a.t_s()).max(1.0),
        _ => 1.0,
    };
    let budget = (budget_bytes_per_s * mission_s) as usize;
    let sweeps = log.ranges.iter().any(|r| !r.is_nan());
    let mut keep_every = 1usize;
    loop {
        let plain = columns_thinned(log, keep_every);
        let last = !sweeps || keep_every > log.steps.len();
        // Each compression at the digest's level costs seconds for a
        // lidar's log: a thinning that cannot fit is told quickly.
        let hopeless = || {
            let quick =
                zstd::bulk::compress(&plain, QUICK_LEVEL).expect("zstd compresses a buffer");
            quick.len() as f64 > QUICK_OVER_AT_MOST * budget as f64
        };
        if !last && hopeless() {
            keep_every *= 2;
            continue;
        }
        let bytes = zstd::bulk::compress(&plain, ZSTD_LEVEL).expect("zstd compresses a buffer");
        if bytes.len() <= budget || last {
            return (bytes, 1.0 / keep_every as f64);
        }
        keep_every *= 2;
    }
}

/// The log a digest holds (values rounded to the digest's steps).
pub fn decode(bytes: &[u8]) -> Result<MissionLog, DigestError> {
    let mut plain = Vec::new();
    zstd::stream::read::Decoder::new(bytes)
        .and_then(|mut d| d.read_to_end(&mut plain))
        .map_err(|e| DigestError(format!("zstd: {e}")))?;
    let mut r = Reader {
        bytes: &plain,
        at: 0,
    };
    if r.take(MAGIC.len())? != MAGIC {
        return Err(DigestError("wrong magic".into()));
    }
    let header_len = r.unsigned()? as usize;
    let header: LogHeader = serde_json::from_slice(r.take(header_len)?)
        .map_err(|e| DigestError(format!("header: {e}")))?;
    let _keep_every = r.unsigned()?;
    let n = r.unsigned()? as usize;
    if n > plain.len() {
        return Err(DigestError(format!("{n} steps in {} bytes", plain.len())));
    }
    let t_ns = r.column(n)?;
    let cmd = [r.column(n)?, r.column(n)?];
    let wheel = [r.column(n)?, r.column(n)?];
    let flags = r.column(n)?;
    let ticks = [r.column(n)?, r.column(n)?];
    let tracker = [r.column(n)?, r.column(n)?, r.column(n)?];
    let truth = [r.column(n)?, r.column(n)?, r.column(n)?];
    let gyro = r.column(n)?;
    let beams = header.beams_per_step();
    let mut ranges = vec![f64::NAN; n * beams];
    for b in 0..beams {
        let column = r.column(n)?;
        for (k, v) in column.into_iter().enumerate() {
            if v != NO_RANGE {
                ranges[k * beams + b] = v as f64 * RANGE_STEP;
            }
        }
    }
    if r.at != plain.len() {
        return Err(DigestError("bytes after the last column".into()));
    }
    let pose = |p: &[Vec<i64>; 3], k: usize| {
        Pose::new(
            p[0][k] as f64 * POSITION_STEP,
            p[1][k] as f64 * POSITION_STEP,
            p[2][k] as f64 * ANGLE_STEP,
        )
    };
    let steps = (0..n)
        .map(|k| {
            let f = flags[k];
            StepRecord {
                t_ns: t_ns[k] as u64,
                cmd_wheel_rad_s: [cmd[0][k], cmd[1][k]].map(|v| v as f64 * SPEED_STEP),
                wheel_rad_s: [wheel[0][k], wheel[1][k]].map(|v| v as f64 * SPEED_STEP),
                encoder_ticks: (f & HAS_TICKS != 0).then(|| [ticks[0][k], ticks[1][k]]),
                bump: f & BUMP != 0,
                tracker: (f & HAS_TRACKER != 0).then(|| pose(&tracker, k)),
                ground_truth: pose(&truth, k),
                gyro_z_rad_s: (f & HAS_GYRO != 0).then(|| gyro[k] as f64 * ANGLE_STEP),
            }
        })
        .collect();
    Ok(MissionLog {
        header,
        steps,
        ranges,
    })
}

const BUMP: i64 = 1;
const HAS_TICKS: i64 = 2;
const HAS_TRACKER: i64 = 4;
const HAS_GYRO: i64 = 8;

fn q(v: f64, step: f64) -> i64 {
    (v / step).round() as i64
}

/// The digest's columns before compression, a sensor's sweeps thinned to
/// every `keep_every`-th.
fn columns_thinned(log: &MissionLog, keep_every: usize) -> Vec<u8> {
    let n = log.steps.len();
    let mut w = Vec::with_capacity(64 + 40 * n);
    w.extend_from_slice(MAGIC);
    let header = serde_json::to_vec(&log.header).expect("a header serializes");
    unsigned(&mut w, header.len() as u64);
    w.extend_from_slice(&header);
    unsigned(&mut w, keep_every as u64);
    unsigned(&mut w, n as u64);
    let s = &log.steps;
    column(&mut w, s.iter().map(|r| r.t_ns as i64));
    for i in 0..2 {
        column(
            &mut w,
            s.iter().map(|r| q(r.cmd_wheel_rad_s[i], SPEED_STEP)),
        );
    }
    for i in 0..2 {
        column(&mut w, s.iter().map(|r| q(r.wheel_rad_s[i], SPEED_STEP)));
    }
    column(
        &mut w,
        s.iter().map(|r| {
            [
                (r.bump, BUMP),
                (r.encoder_ticks.is_some(), HAS_TICKS),
                (r.tracker.is_some(), HAS_TRACKER),
                (r.gyro_z_rad_s.is_some(), HAS_GYRO),
            ]
            .iter()
            .filter(|(on, _)| *on)
            .fold(0, |flags, (_, bit)| flags | bit)
        }),
    );
    // An absent value repeats the one before, which deltas to nothing.
    for i in 0..2 {
        let mut last = 0;
        column(
            &mut w,
            s.iter().map(|r| {
                if let Some(t) = r.encoder_ticks {
                    last = t[i];
                }
                last
            }),
        );
    }
    let pose_columns = |w: &mut Vec<u8>, get: &dyn Fn(&StepRecord) -> Option<Pose>| {
        for i in 0..3 {
            let mut last = 0;
            column(
                w,
                s.iter().map(|r| {
                    if let Some(p) = get(r) {
                        last = match i {
                            0 => q(p.x_m, POSITION_STEP),
                            1 => q(p.y_m, POSITION_STEP),
                            _ => q(p.heading_rad, ANGLE_STEP),
                        };
                    }
                    last
                }),
            );
        }
    };
    pose_columns(&mut w, &|r| r.tracker);
    pose_columns(&mut w, &|r| Some(r.ground_truth));
    let mut last = 0;
    column(
        &mut w,
        s.iter().map(|r| {
            if let Some(g) = r.gyro_z_rad_s {
                last = q(g, ANGLE_STEP);
            }
            last
        }),
    );
    // Ranges beam by beam; a sensor's k-th sampled sweep is kept when k is
    // a multiple of `keep_every`.
    let beams = log.beams_per_step();
    let offsets = log.header.beam_offsets();
    for (sensor, info) in log.header.range_sensors.iter().enumerate() {
        let first = offsets[sensor];
        let width = info.beams as usize;
        let mut sampled = 0usize;
        let kept: Vec<bool> = (0..n)
            .map(|k| {
                let row = &log.ranges[k * beams + first..k * beams + first + width];
                if row.iter().all(|v| v.is_nan()) {
                    return false;
                }
                sampled += 1;
                (sampled - 1).is_multiple_of(keep_every)
            })
            .collect();
        for b in first..first + width {
            column(
                &mut w,
                (0..n).map(|k| {
                    let v = log.ranges[k * beams + b];
                    if kept[k] && !v.is_nan() {
                        q(v, RANGE_STEP).max(0)
                    } else {
                        NO_RANGE
                    }
                }),
            );
        }
    }
    w
}

/// A column: each value's difference from the one before, as a zigzag varint.
fn column(w: &mut Vec<u8>, values: impl Iterator<Item = i64>) {
    let mut last = 0i64;
    for v in values {
        let d = v.wrapping_sub(last);
        unsigned(w, ((d << 1) ^ (d >> 63)) as u64);
        last = v;
    }
}

fn unsigned(w: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        w.push((v as u8) | 0x80);
        v >>= 7;
    }
    w.push(v as u8);
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], DigestError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| DigestError("cut short".into()))?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn unsigned(&mut self) -> Result<u64, DigestError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.take(1)?[0];
            v |= u64::from(b & 0x7f) << shift;
            if b < 0x80 {
                return Ok(v);
            }
        }
        Err(DigestError("a varint longer than 64 bits".into()))
    }

    fn column(&mut self, n: usize) -> Result<Vec<i64>, DigestError> {
        let mut last = 0i64;
        (0..n)
            .map(|_| {
                let z = self.unsigned()?;
                let d = ((z >> 1) as i64) ^ -((z & 1) as i64);
                last = last.wrapping_add(d);
                Ok(last)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RangeSensorInfo;

    /// A random drive with a tracker, a gyro, an IR beam and a lidar.
    fn log(seed: u64, lidar_beams: u32, seconds: f64) -> MissionLog {
        let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let sensor =
            |name: &str, mount: Pose, beams: u32, fov_rad: f64, max_range_m: f64| RangeSensorInfo {
                name: name.into(),
                kind: crate::SensorKind::of_unlabelled(beams),
                mount,
                beams,
                fov_rad,
                min_range_m: 0.1,
                max_range_m,
            };
        let header = LogHeader {
            format: "twindrive-log".into(),
            version: 1,
            scenario: "digest".into(),
            seed,
            dt_s: 0.01,
            ticks_per_rev: 512,
            nominal: twindrive_kinematics::DiffDriveParams {
                left_diameter_m: 0.066,
                right_diameter_m: 0.066,
                wheelbase_m: 0.26,
            },
            footprint_radius_m: 0.15,
            max_wheel_speed_rad_s: 12.0,
            max_wheel_accel_rad_s2: 30.0,
            start: Pose::default(),
            range_sensors: vec![
                sensor("ir", Pose::new(0.05, -0.12, -1.0), 1, 0.0, 0.8),
                sensor(
                    "lidar",
                    Pose::default(),
                    lidar_beams,
                    std::f64::consts::TAU,
                    8.0,
                ),
            ],
            gyro: None,
            goals: Default::default(),
        };
        let beams = header.beams_per_step();
        let mut l = MissionLog::new(header);
        let (mut x, mut y, mut h, mut tl, mut tr) = (0.0, 0.0, 0.0, 0i64, 0i64);
        let n = (seconds / 0.01) as usize;
        for k in 0..n {
            let (wl, wr) = (6.0 + rnd(), 6.0 + 2.0 * rnd());
            tl += (wl * 0.01 * 512.0 / std::f64::consts::TAU) as i64;
            tr += (wr * 0.01 * 512.0 / std::f64::consts::TAU) as i64;
            h += (wr - wl) * 0.033 / 0.26 * 0.01;
            x += 0.033 * (wl + wr) / 2.0 * 0.01 * h.cos();
            y += 0.033 * (wl + wr) / 2.0 * 0.01 * h.sin();
            l.steps.push(StepRecord {
                t_ns: k as u64 * 10_000_000,
                cmd_wheel_rad_s: [6.0, 7.0],
                wheel_rad_s: [wl, wr],
                encoder_ticks: (k % 2 == 0).then_some([tl, tr]),
                bump: k % 500 == 0,
                tracker: (k % 3 == 0).then(|| Pose::new(x + 0.001 * rnd(), y, h)),
                ground_truth: Pose::new(x, y, h),
                gyro_z_rad_s: Some((wr - wl) * 0.127 + 0.01 * rnd()),
            });
            for b in 0..beams {
                let sampled = if b == 0 { k % 2 == 0 } else { k % 10 == 0 };
                l.ranges
                    .push(if sampled { 0.3 + 5.0 * rnd() } else { f64::NAN });
            }
        }
        l
    }

    #[test]
    fn a_digest_holds_the_log_to_its_steps_and_keeps_to_its_budget() {
        for (seed, beams) in [(1, 8), (2, 90), (3, 360)] {
            let log = log(seed, beams, 20.0);
            let (bytes, kept) = encode(&log, DEFAULT_BUDGET_BYTES_PER_S);
            let mission_s = log.steps.last().unwrap().t_s();
            assert!(
                bytes.len() as f64 <= DEFAULT_BUDGET_BYTES_PER_S * mission_s,
                "{beams} beams: {} bytes for {mission_s} s",
                bytes.len()
            );
            let back = decode(&bytes).unwrap();
            assert_eq!(back.header, log.header);
            assert_eq!(back.steps.len(), log.steps.len());
            for (a, b) in log.steps.iter().zip(&back.steps) {
                assert_eq!(a.t_ns, b.t_ns);
                assert_eq!(a.encoder_ticks, b.encoder_ticks);
                assert_eq!(a.bump, b.bump);
                assert_eq!(a.tracker.is_some(), b.tracker.is_some());
                assert!((a.wheel_rad_s[0] - b.wheel_rad_s[0]).abs() <= SPEED_STEP / 2.0 + 1e-12);
                assert!(
                    (a.ground_truth.x_m - b.ground_truth.x_m).abs() <= POSITION_STEP / 2.0 + 1e-12
                );
                assert!(
                    (a.ground_truth.heading_rad - b.ground_truth.heading_rad).abs()
                        <= ANGLE_STEP / 2.0 + 1e-12
                );
                assert!(
                    (a.gyro_z_rad_s.unwrap() - b.gyro_z_rad_s.unwrap()).abs()
                        <= ANGLE_STEP / 2.0 + 1e-12
                );
            }
            // Every range kept is within half a millimetre; a thinned
            // digest kept that fraction of each sensor's sweeps.
            let mut kept_values = 0usize;
            for (a, b) in log.ranges.iter().zip(&back.ranges) {
                if !b.is_nan() {
                    assert!((a - b).abs() <= RANGE_STEP / 2.0 + 1e-12, "{a} {b}");
                    kept_values += 1;
                }
            }
            let sampled = log.ranges.iter().filter(|v| !v.is_nan()).count();
            assert!(
                kept_values as f64 >= 0.9 * kept * sampled as f64,
                "{beams}: {kept}"
            );
            eprintln!(
                "{beams} beams: {:.0} B/s, {kept} of the sweeps",
                bytes.len() as f64 / mission_s
            );
            if beams <= 8 {
                assert_eq!(kept, 1.0, "{beams} beams fit whole");
            }
            if beams >= 360 {
                assert!(kept < 1.0, "{beams} beams at 10 Hz do not fit whole");
            }
        }
    }

    /// The digest the search before the quick sizes chose: every thinning
    /// compressed at the digest's level until one fits.
    fn thinned_at_full_level(log: &MissionLog, budget_bytes_per_s: f64) -> (Vec<u8>, f64) {
        let mission_s = (log.steps.last().unwrap().t_s() - log.steps[0].t_s()).max(1.0);
        let budget = (budget_bytes_per_s * mission_s) as usize;
        let mut keep_every = 1;
        loop {
            let bytes =
                zstd::bulk::compress(&columns_thinned(log, keep_every), ZSTD_LEVEL).unwrap();
            if bytes.len() <= budget || keep_every > log.steps.len() {
                return (bytes, 1.0 / keep_every as f64);
            }
            keep_every *= 2;
        }
    }

    #[test]
    fn quick_sizes_choose_the_thinning_the_full_search_chooses() {
        for (seed, beams) in [(5, 360), (6, 180), (7, 90)] {
            let log = log(seed, beams, 8.0);
            let mission_s = log.steps.last().unwrap().t_s();
            // Budgets at each thinning's size at the digest's level, and a
            // byte under it (the quick size is larger: it must not rule
            // out a thinning that fits).
            for keep_every in [1, 2, 4] {
                let size =
                    zstd::bulk::compress(&columns_thinned(&log, keep_every), ZSTD_LEVEL).unwrap();
                for bytes in [size.len(), size.len() - 1] {
                    let budget = (bytes as f64 + 0.5) / mission_s;
                    let (digest, kept) = encode(&log, budget);
                    let (reference, reference_kept) = thinned_at_full_level(&log, budget);
                    assert_eq!(kept, reference_kept, "{beams} beams in {bytes} bytes");
                    assert!(digest == reference, "{beams} beams in {bytes} bytes");
                    if bytes == size.len() {
                        assert_eq!(kept, 1.0 / keep_every as f64);
                    }
                }
            }
        }
    }

    #[test]
    fn damaged_digests_are_refused() {
        let (bytes, _) = encode(&log(4, 4, 2.0), DEFAULT_BUDGET_BYTES_PER_S);
        assert!(decode(&bytes[..bytes.len() / 2]).is_err());
        assert!(decode(b"not a digest").is_err());
        let mut plain = zstd::bulk::decompress(&bytes, 1 << 24).unwrap();
        plain.truncate(plain.len() - 3);
        let recompressed = zstd::bulk::compress(&plain, 1).unwrap();
        assert!(decode(&recompressed).is_err());
    }
}
