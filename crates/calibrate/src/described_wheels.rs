//! The nominal wheels a rosbag2 recording describes: the robot's URDF on
//! `/robot_description` (as `robot_state_publisher` publishes it), read by
//! [`twindrive_ros::urdf::wheels`]. What `map` and `calibrate` take when
//! no flag, calibration or scenario gives the wheels.

use std::path::Path;

use anyhow::Context;
use twindrive_kinematics::DiffDriveParams;
use twindrive_ros::urdf::WheelGeometry;

/// The wheels a recording's robot description gives.
#[derive(Debug, Clone, PartialEq)]
pub struct DescribedWheels {
    /// The topic the URDF came from.
    pub topic: String,
    pub geometry: WheelGeometry,
}

impl DescribedWheels {
    pub fn params(&self) -> DiffDriveParams {
        DiffDriveParams {
            left_diameter_m: self.geometry.left_diameter_m(),
            right_diameter_m: self.geometry.right_diameter_m(),
            wheelbase_m: self.geometry.wheelbase_m(),
        }
    }

    /// What the terminal is told: where the wheels came from and what they are.
    pub fn summary(&self) -> String {
        let g = &self.geometry;
        format!(
            "wheels from {} (robot `{}`): diameter {:.4} m / {:.4} m, wheelbase {:.4} m (joints {}, {})",
            self.topic,
            g.robot,
            g.left_diameter_m(),
            g.right_diameter_m(),
            g.wheelbase_m(),
            g.left.joint,
            g.right.joint
        )
    }
}

/// Why a recording gives no wheels (the caller adds the flags that do).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NoWheels(pub String);

impl std::fmt::Display for NoWheels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// The wheels the bag at `path` describes. The outer error is a bag that
/// does not open; the inner one says what the recording lacks: no
/// description, one that cannot be read, or a URDF without two wheels.
pub fn described_wheels(path: &Path) -> anyhow::Result<Result<DescribedWheels, NoWheels>> {
    let bag = twindrive_ros::Bag::open(path).context("--bag")?;
    Ok(of_bag(&bag))
}

/// The wheels `bag` describes, or what it lacks.
pub fn of_bag(bag: &twindrive_ros::Bag) -> Result<DescribedWheels, NoWheels> {
    let (topic, text) = match twindrive_ros::extract::robot_description(bag) {
        Ok(Some(found)) => found,
        Ok(None) => {
            return Err(NoWheels(format!(
                "the bag records no {} (the robot's URDF) to read them from",
                twindrive_ros::extract::ROBOT_DESCRIPTION
            )));
        }
        Err(e) => return Err(NoWheels(format!("the robot's description: {e}"))),
    };
    match twindrive_ros::urdf::wheels(&text) {
        Ok(geometry) => Ok(DescribedWheels { topic, geometry }),
        Err(e) => Err(NoWheels(format!("the bag's {topic} gives no wheels: {e}"))),
    }
}
