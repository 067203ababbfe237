//! Wheel speeds published as plain numbers, integrated into cumulative
//! wheel angles: a `std_msgs/msg/Float64` topic per wheel (as motor
//! controllers such as ODrive's ROS nodes publish them), or two elements
//! of one array topic (`std_msgs/msg/Float64MultiArray`, as ros2_control's
//! forward controllers take them).
//!
//! Two topics are sampled at different times: each wheel's speed is
//! interpolated linearly at every time either topic has (inside the span
//! both cover), and the pairs are integrated by the trapezoid rule.

use super::{
    Extracted, Stamps, WheelTrack, check_stamped, element_path, header_stamp, message_time,
    number_at, ordered, topic_error,
};
use crate::bag::{Bag, BagError};

/// A number field of a topic: `data`, or `data[1]` for an array element.
#[derive(Debug, Clone, PartialEq)]
pub struct NumberField {
    pub topic: String,
    pub field: String,
}

/// `(t_s, value)` of every message of `topic`, reading `fields` (each
/// scaled by `scale`), time-ordered with repeated times dropped.
fn series<const N: usize>(
    bag: &Bag,
    topic: &str,
    fields: [&str; N],
    scale: f64,
    stamps: Stamps,
) -> Result<Vec<(f64, [f64; N])>, BagError> {
    let schema = bag.schema(topic)?;
    let mut paths = Vec::with_capacity(N);
    for f in fields {
        paths.push(element_path(&schema, f).map_err(|e| topic_error(bag, topic, e))?);
    }
    let header = header_stamp(&schema, 0);
    let mut raw = Vec::new();
    bag.for_each(topic, |m| {
        let t = message_time(m.value, m.log_time_ns, stamps, header.as_ref())?;
        let mut v = [0.0; N];
        for ((x, p), f) in v.iter_mut().zip(&paths).zip(fields) {
            *x = number_at(m.value, p, f)? * scale;
        }
        raw.push((t, v));
        Ok(())
    })?;
    check_stamped(bag, topic, raw.iter().map(|s| s.0), stamps)?;
    let raw = ordered(raw);
    if raw.len() < 2 {
        return Err(topic_error(
            bag,
            topic,
            format!(
                "{} message(s): wheel speeds need at least two to integrate",
                raw.len()
            ),
        ));
    }
    Ok(raw)
}

/// `(t_s, value)` of a number field over its topic's messages, in time
/// order, one per time.
pub fn number_track(
    bag: &Bag,
    field: &NumberField,
    stamps: Stamps,
) -> Result<Vec<(f64, f64)>, BagError> {
    Ok(series(bag, &field.topic, [&field.field], 1.0, stamps)?
        .into_iter()
        .map(|(t, [v])| (t, v))
        .collect())
}

/// The value of a time-ordered series at `t` inside its span, linearly
/// interpolated; `cursor` only moves forward (calls come in time order).
fn at(series: &[(f64, [f64; 1])], cursor: &mut usize, t: f64) -> f64 {
    while *cursor + 2 < series.len() && series[*cursor + 1].0 <= t {
        *cursor += 1;
    }
    let (t0, [v0]) = series[*cursor];
    let (t1, [v1]) = series[(*cursor + 1).min(series.len() - 1)];
    if t1 > t0 {
        v0 + (v1 - v0) * ((t - t0) / (t1 - t0)).clamp(0.0, 1.0)
    } else {
        v0
    }
}

/// Cumulative wheel angles from wheel speeds (`rad_per_unit` radians per
/// published unit).
pub(super) fn speeds(
    bag: &Bag,
    left: &NumberField,
    right: &NumberField,
    rad_per_unit: f64,
    stamps: Stamps,
) -> Result<Extracted<WheelTrack>, BagError> {
    if !(rad_per_unit.is_finite() && rad_per_unit > 0.0) {
        return Err(topic_error(
            bag,
            &left.topic,
            format!("the speed unit must be a positive number of radians, not {rad_per_unit}"),
        ));
    }
    let pairs: Vec<(f64, [f64; 2])> = if left.topic == right.topic {
        series(
            bag,
            &left.topic,
            [&left.field, &right.field],
            rad_per_unit,
            stamps,
        )?
    } else {
        let l = series(bag, &left.topic, [&left.field], rad_per_unit, stamps)?;
        let r = series(bag, &right.topic, [&right.field], rad_per_unit, stamps)?;
        let from = l[0].0.max(r[0].0);
        let to = l[l.len() - 1].0.min(r[r.len() - 1].0);
        if from >= to {
            return Err(topic_error(
                bag,
                &right.topic,
                format!(
                    "its messages ({:.3} s to {:.3} s) and {}'s ({:.3} s to {:.3} s) do not overlap in time",
                    r[0].0,
                    r[r.len() - 1].0,
                    left.topic,
                    l[0].0,
                    l[l.len() - 1].0
                ),
            ));
        }
        let mut times: Vec<f64> = l
            .iter()
            .chain(&r)
            .map(|s| s.0)
            .filter(|t| (from..=to).contains(t))
            .collect();
        times.sort_by(f64::total_cmp);
        times.dedup();
        let (mut cl, mut cr) = (0, 0);
        times
            .into_iter()
            .map(|t| (t, [at(&l, &mut cl, t), at(&r, &mut cr, t)]))
            .collect()
    };
    let samples = twindrive_kinematics::wheel_angles_from_speeds(pairs)
        .into_iter()
        .map(|(t, [l, r])| (t, l, r))
        .collect();
    Ok(Extracted {
        samples,
        skipped: 0,
        used: "speed".into(),
    })
}

#[cfg(test)]
mod tests {
    use super::super::{WheelSource, wheel_track};
    use super::*;
    use crate::bag::BagWriter;
    use crate::msgs::{Distro, Float64, Float64MultiArray};
    use crate::qos::Qos;

    /// Left at 2 rad/s sampled every 0.1 s, right at -1 rad/s sampled
    /// every 0.15 s and 0.02 s late; an array topic with both.
    fn bag(dir: &std::path::Path) -> Bag {
        let path = dir.join("s.mcap");
        let f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = BagWriter::mcap(f, "s.mcap", Distro::Jazzy).unwrap();
        let l = w.topic::<Float64>("/left_speed", Qos::DEFAULT).unwrap();
        let r = w.topic::<Float64>("/right_speed", Qos::DEFAULT).unwrap();
        let both = w
            .topic::<Float64MultiArray>("/wheel_speeds", Qos::DEFAULT)
            .unwrap();
        let ns = |t: f64| (t * 1e9).round() as u64;
        for k in 0..=30 {
            let t = 1.0 + 0.1 * f64::from(k);
            w.write(l, ns(t), &Float64 { data: 2.0 }).unwrap();
            let both_msg = Float64MultiArray {
                data: vec![2.0, -1.0],
                ..Default::default()
            };
            w.write(both, ns(t), &both_msg).unwrap();
        }
        for k in 0..=20 {
            let t = 1.02 + 0.15 * f64::from(k);
            w.write(r, ns(t), &Float64 { data: -1.0 }).unwrap();
        }
        w.finish().unwrap();
        Bag::open(&path).unwrap()
    }

    fn field(topic: &str, field: &str) -> NumberField {
        NumberField {
            topic: topic.into(),
            field: field.into(),
        }
    }

    #[test]
    fn two_topics_and_one_array_integrate_to_the_same_angles() {
        let dir = tempfile::tempdir().unwrap();
        let b = bag(dir.path());
        let two = WheelSource::Speeds {
            left: field("/left_speed", "data"),
            right: field("/right_speed", "data"),
            rad_per_unit: std::f64::consts::TAU,
        };
        let w = wheel_track(&b, &two, Stamps::Header).unwrap();
        assert_eq!(w.used, "speed");
        // Inside the span both cover: 1.02 s to 4.0 s, every time of either.
        let (t0, t1) = (w.samples[0].0, w.samples.last().unwrap().0);
        assert!(
            (t0 - 1.02).abs() < 1e-9 && (t1 - 4.0).abs() < 1e-9,
            "{t0} {t1}"
        );
        assert!(w.samples.len() > 30);
        for &(t, a_l, a_r) in &w.samples {
            let tau = std::f64::consts::TAU;
            assert!((a_l - 2.0 * tau * (t - t0)).abs() < 1e-9, "{t}: {a_l}");
            assert!((a_r + tau * (t - t0)).abs() < 1e-9, "{t}: {a_r}");
        }
        let one = WheelSource::Speeds {
            left: field("/wheel_speeds", "data[0]"),
            right: field("/wheel_speeds", "data[1]"),
            rad_per_unit: 1.0,
        };
        let w = wheel_track(&b, &one, Stamps::Header).unwrap();
        assert_eq!(w.samples.len(), 31);
        let (t, a_l, a_r) = w.samples[30];
        assert!((t - 4.0).abs() < 1e-9 && (a_l - 6.0).abs() < 1e-9 && (a_r + 3.0).abs() < 1e-9);
    }

    #[test]
    fn wrong_fields_and_units_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let b = bag(dir.path());
        let err = |left: NumberField, right: NumberField, unit: f64| {
            let s = WheelSource::Speeds {
                left,
                right,
                rad_per_unit: unit,
            };
            wheel_track(&b, &s, Stamps::Header).unwrap_err().to_string()
        };
        let e = err(
            field("/wheel_speeds", "data"),
            field("/wheel_speeds", "data[1]"),
            1.0,
        );
        assert!(
            e.contains("`data` is not a number field") && e.contains("[0]"),
            "{e}"
        );
        let e = err(
            field("/wheel_speeds", "data[0]"),
            field("/wheel_speeds", "data[5]"),
            1.0,
        );
        assert!(e.contains("data[5]") && e.contains("message 0"), "{e}");
        let e = err(
            field("/left_speed", "x"),
            field("/right_speed", "data"),
            1.0,
        );
        assert!(e.contains("/left_speed") && e.contains("x"), "{e}");
        let e = err(field("/nope", "data"), field("/right_speed", "data"), 1.0);
        assert!(e.contains("/nope"), "{e}");
        let e = err(
            field("/left_speed", "data"),
            field("/right_speed", "data"),
            0.0,
        );
        assert!(e.contains("positive"), "{e}");
    }
}
