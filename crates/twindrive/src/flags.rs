//! Flag resolution the commands share: files named on the command line
//! read and checked (a calibration, a key; plans and the twin's world are
//! `twindrive_workflow::inputs`'), and values parsed, each error naming its
//! flag or file.

use std::path::Path;

use anyhow::Context;
use serde::Deserialize;
use twindrive_kinematics::DiffDriveParams;
use twindrive_link::LinkProfile;
use twindrive_link::envelope::read_private_key_pem;

use crate::usage::usage;

/// The three parameters of a `calib.json` (other fields are ignored).
#[derive(Debug, Deserialize)]
struct Calibration {
    left_diameter_m: f64,
    right_diameter_m: f64,
    wheelbase_m: f64,
}

/// Reads a `--freedom` file (the robot's freedom on a plan) for a robot of
/// `footprint_radius_m`; errors name the file and the line or field.
pub fn read_freedom(
    path: &Path,
    footprint_radius_m: f64,
) -> anyhow::Result<twindrive_mission::freedom::FreedomSettings> {
    use anyhow::Context;
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("--freedom: reading {}", path.display()))?;
    let settings = toml::from_str::<twindrive_mission::freedom::FreedomSettings>(&text)
        .with_context(|| format!("--freedom: {}", path.display()))?;
    settings
        .validate(footprint_radius_m)
        .map_err(|e| anyhow::anyhow!("--freedom: {}: {e}", path.display()))?;
    Ok(settings)
}

/// Reads the calibrated parameters from a `twindrive calibrate` output.
pub fn read_calibration(path: &Path) -> anyhow::Result<DiffDriveParams> {
    let c: Calibration = twindrive_files::json::read(
        path,
        "a calibration (calib.json from `twindrive calibrate`, with left_diameter_m, right_diameter_m and wheelbase_m)",
    )?;
    let params = DiffDriveParams::new(c.left_diameter_m, c.right_diameter_m, c.wheelbase_m);
    params
        .validate()
        .with_context(|| format!("{}", path.display()))?;
    Ok(params)
}

/// The robots a master or the console supervises are distinct (each id is
/// checked when parsed).
pub fn check_distinct_robots(robots: &[String]) -> anyhow::Result<()> {
    let mut seen = std::collections::HashSet::new();
    for id in robots {
        if !seen.insert(id) {
            return Err(usage(format!("--robot {id} is given twice")));
        }
    }
    Ok(())
}

/// `--link PROFILE`, parsed.
pub fn link_profile(arg: Option<&str>) -> anyhow::Result<Option<LinkProfile>> {
    arg.map(|p| p.parse().map_err(|e| usage(format!("--link {p}: {e}"))))
        .transpose()
}

/// `--key KEY`, read (the master's or a robot's private key).
pub fn signing_key(path: &Path) -> anyhow::Result<twindrive_link::envelope::SigningKey> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("--key: reading {}", path.display()))?;
    read_private_key_pem(&text).map_err(|e| anyhow::anyhow!("--key {}: {e}", path.display()))
}

/// The master's key (`--key` of `sign` and `master`), read and checked not
/// to be one of `robots`' own keys: by its name (`ID.key`, as `keygen
/// --robot ID` writes it) or by its public half (`robot_keys`, the robots'
/// `--trust-robot` keys).
pub fn master_key(
    path: &Path,
    robots: &[String],
    robot_keys: Option<&std::collections::BTreeMap<String, twindrive_link::envelope::VerifyingKey>>,
) -> anyhow::Result<twindrive_link::envelope::SigningKey> {
    let key = signing_key(path)?;
    let public = key.verifying_key();
    let by_name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|stem| robots.iter().any(|r| r == stem));
    let by_key = robot_keys
        .and_then(|keys| keys.iter().find(|(_, k)| **k == public))
        .map(|(id, _)| id.as_str());
    if let Some(id) = by_name.or(by_key) {
        return Err(usage(format!(
            "--key {}: that is robot {id}'s own key (keygen --robot {id}); plans are signed with the master's key (keygen without --robot writes master.key)",
            path.display()
        )));
    }
    Ok(key)
}

/// A public key that `flag` names, read (`--trust master.pub`,
/// `--trust-robot ID.pub`).
pub fn public_key(
    flag: &str,
    path: &Path,
) -> anyhow::Result<twindrive_link::envelope::VerifyingKey> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{flag}: reading {}", path.display()))?;
    twindrive_link::envelope::read_public_key_pem(&text)
        .map_err(|e| anyhow::anyhow!("{flag} {}: {e}", path.display()))
}

/// `--trust-robot` files and directories, read: each robot's id (the
/// file's name, `ID.pub`) and public key. A directory gives every `*.pub`
/// in it but `master.pub`.
pub fn robot_keys(
    paths: &[std::path::PathBuf],
) -> anyhow::Result<std::collections::BTreeMap<String, twindrive_link::envelope::VerifyingKey>> {
    let mut files = Vec::new();
    for path in paths {
        if !path.exists() {
            return Err(usage(format!(
                "--trust-robot {}: no such file or directory (give a robot's ID.pub, or a directory of them)",
                path.display()
            )));
        }
        if path.is_dir() {
            let mut in_dir: Vec<_> = std::fs::read_dir(path)
                .with_context(|| format!("--trust-robot: reading {}", path.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension().is_some_and(|e| e == "pub")
                        && p.file_name().is_some_and(|n| n != "master.pub")
                })
                .collect();
            if in_dir.is_empty() {
                return Err(usage(format!(
                    "--trust-robot {}: no robot key (ID.pub) in the directory",
                    path.display()
                )));
            }
            in_dir.sort();
            files.extend(in_dir);
        } else {
            files.push(path.clone());
        }
    }
    let mut keys = std::collections::BTreeMap::new();
    for file in files {
        let id = file
            .file_stem()
            .and_then(|s| s.to_str())
            .filter(|_| file.extension().is_some_and(|e| e == "pub"))
            .ok_or_else(|| {
                usage(format!(
                    "--trust-robot {}: a robot's key is named ID.pub (its robot's id)",
                    file.display()
                ))
            })?;
        crate::usage::robot_id(id).map_err(|e| {
            usage(format!(
                "--trust-robot {}: the name is not a robot id: {e}",
                file.display()
            ))
        })?;
        let key = public_key("--trust-robot", &file)?;
        if keys.insert(id.to_string(), key).is_some() {
            return Err(usage(format!(
                "--trust-robot: two keys for robot {id} (the second: {})",
                file.display()
            )));
        }
    }
    Ok(keys)
}

/// Every robot of `robots` has a key in `keys` (a usage error names the
/// first that has none).
pub fn check_robot_keys(
    robots: &[String],
    keys: &std::collections::BTreeMap<String, twindrive_link::envelope::VerifyingKey>,
) -> anyhow::Result<()> {
    match robots.iter().find(|r| !keys.contains_key(*r)) {
        Some(r) => Err(usage(format!(
            "--robot {r}: no trusted key for it (give --trust-robot with its {r}.pub, from `twindrive keygen --robot {r}`)"
        ))),
        None => Ok(()),
    }
}

/// `--link-state`, or link-state/ beside the master's key.
pub fn link_state_dir(link_state: Option<&Path>, key: &Path) -> std::path::PathBuf {
    link_state.map_or_else(
        || {
            key.parent()
                .unwrap_or_else(|| Path::new("."))
                .join("link-state")
        },
        Path::to_path_buf,
    )
}

/// `--stamps`, as the bag reader takes it.
pub fn stamps(s: crate::cli::StampsArg) -> twindrive_ros::extract::Stamps {
    match s {
        crate::cli::StampsArg::Header => twindrive_ros::extract::Stamps::Header,
        crate::cli::StampsArg::Log => twindrive_ros::extract::Stamps::LogTime,
    }
}

/// `--joint-signal`, as the bag reader takes it.
pub fn joint_signal(s: crate::cli::JointSignalArg) -> twindrive_ros::extract::JointSignal {
    use twindrive_ros::extract::JointSignal;
    match s {
        crate::cli::JointSignalArg::Auto => JointSignal::Auto,
        crate::cli::JointSignalArg::Position => JointSignal::Position,
        crate::cli::JointSignalArg::Velocity => JointSignal::Velocity,
    }
}

/// The wheel speed topics the command line names, if it names them.
pub fn speed_source(a: &crate::cli::WheelSpeedArgs) -> Option<twindrive_ros::extract::WheelSource> {
    use twindrive_ros::extract::{NumberField, WheelSource};
    let (left, right) = (a.left_speed_topic.as_ref()?, a.right_speed_topic.as_ref()?);
    Some(WheelSource::Speeds {
        left: NumberField {
            topic: left.clone(),
            field: a.left_speed_field.clone(),
        },
        right: NumberField {
            topic: right.clone(),
            field: a.right_speed_field.clone(),
        },
        rad_per_unit: match a.speed_unit {
            crate::cli::SpeedUnitArg::RadPerS => 1.0,
            crate::cli::SpeedUnitArg::RevPerS => std::f64::consts::TAU,
        },
    })
}

/// The lidar's mount in a self-calibration's `calib.json`, if it has one.
#[derive(Debug, Deserialize)]
struct MountFile {
    lidar: Option<String>,
    lidar_mount: Option<twindrive_kinematics::Pose>,
}

/// The lidar named in `calib.json` and its calibrated mount; `None` for a
/// calibration against poses, which has none.
pub fn read_lidar_mount(
    path: &Path,
) -> anyhow::Result<Option<(Option<String>, twindrive_kinematics::Pose)>> {
    let m: MountFile = twindrive_files::json::read(
        path,
        "a calibration (calib.json from `twindrive calibrate`)",
    )?;
    Ok(m.lidar_mount.map(|mount| (m.lidar, mount)))
}
