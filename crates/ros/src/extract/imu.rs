//! A gyro's yaw rates: `angular_velocity.z` of every `sensor_msgs/msg/Imu`
//! of a topic, in time order.

use super::{Stamps, check_stamped, header_stamp, message_time, one_sensor, topic_error};
use crate::bag::{Bag, BagError};
use crate::value::Value;

pub const IMU: &str = "sensor_msgs/msg/Imu";

/// The yaw rates of an IMU topic.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuRateTrack {
    /// `(t_s, z_rad_s)`: the rate about the IMU frame's z axis,
    /// time-ordered, one per time. It is the robot's yaw rate only if the
    /// IMU's z axis points up: see [`super::static_transform`] from the
    /// base frame to `frame_id` (`upside_down` flips the sign).
    pub samples: Vec<(f64, f64)>,
    /// `header.frame_id` of the earliest sample.
    pub frame_id: String,
    /// Messages without a rate: `angular_velocity_covariance[0]` = −1 (not
    /// measured, as an orientation-only IMU says) or a z that is not finite.
    pub skipped: u64,
    /// Messages left out for another `frame_id` (another IMU).
    pub other_frame: u64,
    /// Messages left out for repeating an earlier message's time.
    pub repeated: u64,
}

/// Every `sensor_msgs/msg/Imu` on `topic` that measures angular velocity,
/// times by `stamps` (seconds, as recorded). A topic that is missing or of
/// another type is an error naming its type and the bag's Imu topics; so is
/// one without a single rate.
pub fn imu_rate_track(bag: &Bag, topic: &str, stamps: Stamps) -> Result<ImuRateTrack, BagError> {
    let schema = super::typed_schema(bag, topic, IMU)?;
    let terr = |m: String| topic_error(bag, topic, m);
    let frame = schema.path("header.frame_id").map_err(terr)?;
    let z = schema.path("angular_velocity.z").map_err(terr)?;
    let covariance = schema.path("angular_velocity_covariance").map_err(terr)?;
    let header = header_stamp(&schema, 0);
    let mut raw = Vec::new();
    let mut skipped = 0;
    bag.for_each(topic, |m| {
        let not_measured = m
            .value
            .at(&covariance)
            .and_then(Value::as_array)
            .and_then(|c| c.first())
            .and_then(Value::as_f64)
            == Some(-1.0);
        let rate = m.value.at(&z).and_then(Value::as_f64);
        match rate {
            Some(w) if w.is_finite() && !not_measured => {
                let t = message_time(m.value, m.log_time_ns, stamps, header.as_ref())?;
                let f = m.value.at(&frame).and_then(Value::as_str).unwrap_or("");
                raw.push((t, f.to_string(), w));
            }
            _ => skipped += 1,
        }
        Ok(())
    })?;
    if raw.is_empty() {
        return Err(terr(if skipped == 0 {
            "has no messages".into()
        } else {
            format!(
                "no message measures angular velocity ({skipped} with angular_velocity_covariance[0] = -1 or a z that is not a number)"
            )
        }));
    }
    check_stamped(bag, topic, raw.iter().map(|s| s.0), stamps)?;
    let one = one_sensor(raw);
    Ok(ImuRateTrack {
        samples: one.readings,
        frame_id: one.frame_id,
        skipped,
        other_frame: one.other_frame,
        repeated: one.repeated,
    })
}
