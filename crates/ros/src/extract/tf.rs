//! Sensor mounts from a recording's TF tree: `/tf_static`, with `/tf`
//! filling in what it lacks, composed in 3D and projected onto the ground
//! plane.

use std::collections::{BTreeMap, BTreeSet};

use crate::bag::{Bag, BagError};
use crate::schema::Base;
use crate::value::Value;

pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
const TF_STATIC: &str = "/tf_static";
const TF: &str = "/tf";

/// Where a child frame sits in a parent frame, seen from above.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarMount {
    /// The child's origin in the parent frame (m).
    pub x_m: f64,
    pub y_m: f64,
    /// Height of the child's origin above the parent's (m).
    pub z_m: f64,
    /// Direction of the child's x axis in the parent's x-y plane (rad,
    /// counter-clockwise, in (−π, π]): the yaw of roll-pitch-yaw.
    pub heading_rad: f64,
    /// Roll and pitch of the child in the parent (rad; fixed axes x then
    /// y, then yaw about z, as ROS composes `rpy`; pitch in [−π/2, π/2]).
    pub roll_rad: f64,
    pub pitch_rad: f64,
    /// |roll| > π/2: the child's z axis points down. A lidar mounted so
    /// scans mirrored: its beam at angle `a` points at `heading_rad − a`
    /// (not `+ a`), and a gyro's z rate is the robot's yaw rate negated.
    pub upside_down: bool,
    /// The frames from the parent to the child (both included, without
    /// leading `/`).
    pub chain: Vec<String>,
    /// Some link of the chain came from `/tf` (absent from `/tf_static`):
    /// its first value in the recording was used.
    pub from_tf: bool,
}

/// A rigid transform: translation, then the unit quaternion `[x, y, z, w]`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rigid {
    t: [f64; 3],
    q: [f64; 4],
}

impl Rigid {
    const IDENTITY: Rigid = Rigid {
        t: [0.0; 3],
        q: [0.0, 0.0, 0.0, 1.0],
    };

    /// From a message's numbers (the quaternion normalized); `None` when a
    /// number is not finite or the quaternion is zero.
    fn new(t: [f64; 3], q: [f64; 4]) -> Option<Self> {
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        let finite = t.iter().chain(&q).all(|c| c.is_finite());
        (finite && n > 1e-9).then(|| Rigid {
            t,
            q: q.map(|c| c / n),
        })
    }

    /// `self ∘ b`: `b` expressed in `self`'s parent.
    fn then(&self, b: &Rigid) -> Rigid {
        let r = rotate(self.q, b.t);
        let q = mul(self.q, b.q);
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        Rigid {
            t: [self.t[0] + r[0], self.t[1] + r[1], self.t[2] + r[2]],
            q: q.map(|c| c / n),
        }
    }

    fn inverse(&self) -> Rigid {
        let c = conjugate(self.q);
        let r = rotate(c, self.t);
        Rigid {
            t: [-r[0], -r[1], -r[2]],
            q: c,
        }
    }

    /// `(roll, pitch, yaw)` with `R = Rz(yaw) Ry(pitch) Rx(roll)`.
    fn rpy(&self) -> (f64, f64, f64) {
        let [x, y, z, w] = self.q;
        let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
        let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
        let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
        (roll, pitch, yaw)
    }
}

/// The Hamilton product `a b`.
fn mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]
}

fn conjugate(q: [f64; 4]) -> [f64; 4] {
    [-q[0], -q[1], -q[2], q[3]]
}

/// `v` rotated by the unit quaternion `q`.
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let u = [q[0], q[1], q[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let t = cross(u, v).map(|c| 2.0 * c);
    let c = cross(u, t);
    [
        v[0] + q[3] * t[0] + c[0],
        v[1] + q[3] * t[1] + c[1],
        v[2] + q[3] * t[2] + c[2],
    ]
}

/// A frame name as tf2 compares them (ROS 1 bags write a leading `/`).
fn frame(name: &str) -> &str {
    name.trim_start_matches('/')
}

/// The link from a child frame to its parent.
struct Link {
    parent: String,
    pose: Rigid,
    /// From `/tf`.
    dynamic: bool,
}

/// Links by child frame: in tf2 each frame has one parent.
type Tree = BTreeMap<String, Link>;

/// Hands `f` every transform of `topic` in log-time order: parent, child
/// (without leading `/`) and the transform, `None` when it is not a
/// rotation and a translation (a zero quaternion, a NaN). A bag without the
/// topic has none; a topic of another type is an error.
fn read_transforms(
    bag: &Bag,
    topic: &str,
    mut f: impl FnMut(&str, &str, Option<Rigid>),
) -> Result<(), BagError> {
    if bag.topic(topic).is_none() {
        return Ok(());
    }
    let schema = super::typed_schema(bag, topic, TF_MESSAGE)?;
    let terr = |m: String| super::topic_error(bag, topic, m);
    let transforms = schema.path("transforms").map_err(terr)?;
    let Base::Message(ts) = transforms.ty.base else {
        return Err(terr("`transforms` is not a list of messages".into()));
    };
    let inner = |dotted: &str| schema.path_from(ts, dotted).map_err(terr);
    let child_path = inner("child_frame_id")?;
    let parent_path = inner("header.frame_id")?;
    let t = [
        inner("transform.translation.x")?,
        inner("transform.translation.y")?,
        inner("transform.translation.z")?,
    ];
    let q = [
        inner("transform.rotation.x")?,
        inner("transform.rotation.y")?,
        inner("transform.rotation.z")?,
        inner("transform.rotation.w")?,
    ];
    bag.for_each(topic, |m| {
        let list = m
            .value
            .at(&transforms)
            .and_then(Value::as_array)
            .ok_or("no `transforms` list")?;
        for tr in list {
            let (Some(c), Some(p)) = (
                tr.at(&child_path).and_then(Value::as_str),
                tr.at(&parent_path).and_then(Value::as_str),
            ) else {
                continue;
            };
            let num =
                |p: &crate::schema::FieldPath| tr.at(p).and_then(Value::as_f64).unwrap_or(f64::NAN);
            f(
                frame(p),
                frame(c),
                Rigid::new(t.each_ref().map(num), q.each_ref().map(num)),
            );
        }
        Ok(())
    })?;
    Ok(())
}

/// The mount of `child` in `parent` from the recording's TF tree: the
/// chain of transforms between them (up and down the tree, through their
/// nearest common ancestor) composed in 3D, then seen from above. Links
/// come from `/tf_static` (its latest transform of each child frame); only
/// when those do not connect the frames does `/tf` add the links it has and
/// `/tf_static` lacks (the first transform of each). Frames may be named
/// with or without a leading `/`. `Ok(None)` when no chain connects them;
/// an error when `/tf_static` or `/tf` is not a `tf2_msgs/msg/TFMessage`
/// topic.
pub fn static_transform(
    bag: &Bag,
    parent: &str,
    child: &str,
) -> Result<Option<PlanarMount>, BagError> {
    let (parent, child) = (frame(parent), frame(child));
    let mut tree = Tree::new();
    read_transforms(bag, TF_STATIC, |p, c, pose| {
        if let Some(pose) = pose
            && p != c
        {
            tree.insert(
                c.to_string(),
                Link {
                    parent: p.to_string(),
                    pose,
                    dynamic: false,
                },
            );
        }
    })?;
    if let Some(m) = chain(&tree, parent, child) {
        return Ok(Some(m));
    }
    let before = tree.len();
    read_transforms(bag, TF, |p, c, pose| {
        if let Some(pose) = pose
            && p != c
        {
            tree.entry(c.to_string()).or_insert_with(|| Link {
                parent: p.to_string(),
                pose,
                dynamic: true,
            });
        }
    })?;
    if tree.len() == before {
        return Ok(None);
    }
    Ok(chain(&tree, parent, child))
}

/// `child` in `parent` through `tree`, if they are connected.
fn chain(tree: &Tree, parent: &str, child: &str) -> Option<PlanarMount> {
    // A frame, its parent, its grandparent… up to the root (or a cycle).
    let up = |from: &str| {
        let mut path = vec![from.to_string()];
        while let Some(link) = tree.get(path.last().expect("not empty")) {
            if path.contains(&link.parent) {
                break;
            }
            path.push(link.parent.clone());
        }
        path
    };
    let (from_parent, from_child) = (up(parent), up(child));
    // The nearest common ancestor, at from_parent[i] = from_child[j].
    let (i, j) = from_child
        .iter()
        .enumerate()
        .find_map(|(j, f)| from_parent.iter().position(|p| p == f).map(|i| (i, j)))?;
    // The ancestor → a frame below it, along `path` (the frame first).
    let down = |path: &[String]| {
        path.iter()
            .rev()
            .fold(Rigid::IDENTITY, |acc, f| acc.then(&tree[f].pose))
    };
    let pose = down(&from_parent[..i])
        .inverse()
        .then(&down(&from_child[..j]));
    let used = from_parent[..i].iter().chain(&from_child[..j]);
    let from_tf = used.clone().any(|f| tree[f].dynamic);
    let mut names: Vec<String> = from_parent[..=i].to_vec();
    names.extend(from_child[..j].iter().rev().cloned());
    let (roll, pitch, yaw) = pose.rpy();
    Some(PlanarMount {
        x_m: pose.t[0],
        y_m: pose.t[1],
        z_m: pose.t[2],
        heading_rad: yaw,
        roll_rad: roll,
        pitch_rad: pitch,
        upside_down: roll.abs() > std::f64::consts::FRAC_PI_2,
        chain: names,
        from_tf,
    })
}

/// Every frame named in `/tf_static` and `/tf` (without leading `/`),
/// sorted.
pub fn tf_frames(bag: &Bag) -> Result<Vec<String>, BagError> {
    let mut frames = BTreeSet::new();
    for topic in [TF_STATIC, TF] {
        read_transforms(bag, topic, |p, c, _| {
            for f in [p, c] {
                if !frames.contains(f) {
                    frames.insert(f.to_string());
                }
            }
        })?;
    }
    Ok(frames.into_iter().collect())
}

/// The robot's base frame as REP-105 names it: `base_link` if the TF tree
/// has it, else `base_footprint`, else `None` (also when `/tf_static` or
/// `/tf` cannot be read).
pub fn base_frame_guess(bag: &Bag) -> Option<String> {
    let frames = tf_frames(bag).ok()?;
    ["base_link", "base_footprint"]
        .into_iter()
        .find(|f| frames.iter().any(|x| x == f))
        .map(String::from)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    /// `Rz(yaw) Ry(pitch) Rx(roll)` as a quaternion.
    fn rpy(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
        let axis = |i: usize, a: f64| {
            let mut q = [0.0, 0.0, 0.0, (0.5 * a).cos()];
            q[i] = (0.5 * a).sin();
            q
        };
        mul(mul(axis(2, yaw), axis(1, pitch)), axis(0, roll))
    }

    #[test]
    fn quaternion_math_matches_rotation_by_hand() {
        // Rz(π/2) takes x to y.
        let r = rotate(rpy(0.0, 0.0, FRAC_PI_2), [1.0, 0.0, 0.0]);
        assert!((r[0]).abs() < 1e-15 && (r[1] - 1.0).abs() < 1e-15);
        // Rx(π) takes y to −y and z to −z.
        let r = rotate(rpy(PI, 0.0, 0.0), [0.0, 1.0, 1.0]);
        assert!((r[1] + 1.0).abs() < 1e-15 && (r[2] + 1.0).abs() < 1e-15);
        for (roll, pitch, yaw) in [(0.3, -0.2, 2.5), (PI, 0.0, 0.5), (-3.0, 1.2, -2.0)] {
            let a = Rigid::new([1.0, -2.0, 0.5], rpy(roll, pitch, yaw)).unwrap();
            let (r, p, y) = a.rpy();
            let wrap = |d: f64| (d + PI).rem_euclid(2.0 * PI) - PI;
            assert!(
                wrap(r - roll).abs() < 1e-12
                    && (p - pitch).abs() < 1e-12
                    && wrap(y - yaw).abs() < 1e-12,
                "{r} {p} {y}"
            );
            let b = Rigid::new([0.2, 0.1, -0.4], rpy(0.1, 0.2, 0.3)).unwrap();
            let back = a.inverse().then(&a.then(&b));
            for k in 0..3 {
                assert!((back.t[k] - b.t[k]).abs() < 1e-12);
            }
            let dot: f64 = (0..4).map(|k| back.q[k] * b.q[k]).sum();
            assert!((dot.abs() - 1.0).abs() < 1e-12);
        }
        assert!(Rigid::new([0.0; 3], [0.0; 4]).is_none());
        assert!(Rigid::new([f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]).is_none());
    }
}
