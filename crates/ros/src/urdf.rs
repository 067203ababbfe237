//! A differential-drive robot's wheels from its URDF, as
//! `robot_state_publisher` publishes it on `/robot_description` (expanded:
//! no `xacro`).
//!
//! The wheels are found by what they are, not by their names: a
//! `continuous` (or `revolute`) joint whose child link, with the links
//! fixed to it, has a `<cylinder>` geometry (under `<collision>`, else
//! under `<visual>`) turning about the robot's left-right axis, about the
//! same axis as the joint. Every joint's origin (`xyz`, `rpy`) is composed
//! from the base link down (joints at their zero position), so wheels
//! hung below other links (fixed joints, a suspension's prismatic joint)
//! are placed where they are. When more than two joints qualify, those
//! whose joint or link name says `left` or `right` are preferred (casters
//! are passed over). The wheel on +y (REP-103: y to the left) is the left
//! one; a wheel's diameter is twice its cylinder's radius, the wheelbase
//! the two joints' distance across the robot (along the base link's y).

use std::collections::HashMap;
use std::fmt;

/// One wheel found in a URDF.
#[derive(Debug, Clone, PartialEq)]
pub struct Wheel {
    /// The joint the wheel turns on.
    pub joint: String,
    /// The joint's child link.
    pub link: String,
    /// The cylinder's radius (m).
    pub radius_m: f64,
    /// The joint's origin in the base link's frame (m; x forward, y left,
    /// z up).
    pub position_m: [f64; 3],
}

/// The two drive wheels of a URDF.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelGeometry {
    /// `<robot name=...>`.
    pub robot: String,
    /// The link the wheels are placed from: `base_link`, else
    /// `base_footprint`, else the tree's root.
    pub base_link: String,
    /// The wheel on +y.
    pub left: Wheel,
    /// The wheel on −y.
    pub right: Wheel,
}

impl WheelGeometry {
    pub fn left_diameter_m(&self) -> f64 {
        2.0 * self.left.radius_m
    }

    pub fn right_diameter_m(&self) -> f64 {
        2.0 * self.right.radius_m
    }

    /// The joints' distance across the robot (along the base link's y).
    pub fn wheelbase_m(&self) -> f64 {
        (self.left.position_m[1] - self.right.position_m[1]).abs()
    }
}

/// A URDF of a differential-drive robot as twindrive knows it (what
/// `robot_state_publisher` would publish for it): `base_link` with the
/// footprint as a vertical cylinder, the two wheels on continuous joints
/// `left_joint` and `right_joint` (links `<joint>_link`) at ±wheelbase/2 on
/// the axle under `base_link`, their axles at their radius above the
/// floor, and each sensor frame (`name`, mount in `base_link`) on a fixed
/// joint. [`wheels`] reads the wheels back.
pub fn describe(
    robot: &str,
    params: &twindrive_kinematics::DiffDriveParams,
    footprint_radius_m: f64,
    joints: [&str; 2],
    frames: &[(String, twindrive_kinematics::Pose)],
) -> String {
    let esc = |s: &str| {
        s.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
            .replace('"', "&quot;")
    };
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<robot name=\"{}\">\n  <link name=\"base_link\">\n    \
         <collision><geometry><cylinder radius=\"{}\" length=\"0.1\"/></geometry></collision>\n  </link>\n",
        esc(robot),
        footprint_radius_m
    );
    for (joint, diameter_m, side) in [
        (joints[0], params.left_diameter_m, 1.0),
        (joints[1], params.right_diameter_m, -1.0),
    ] {
        let (joint, r) = (esc(joint), diameter_m / 2.0);
        out += &format!(
            "  <joint name=\"{joint}\" type=\"continuous\">\n    <parent link=\"base_link\"/>\n    \
             <child link=\"{joint}_link\"/>\n    <origin xyz=\"0 {} {r}\" rpy=\"{} 0 0\"/>\n    \
             <axis xyz=\"0 0 1\"/>\n  </joint>\n  <link name=\"{joint}_link\">\n    \
             <collision><geometry><cylinder radius=\"{r}\" length=\"0.02\"/></geometry></collision>\n    \
             <visual><geometry><cylinder radius=\"{r}\" length=\"0.02\"/></geometry></visual>\n  </link>\n",
            side * params.wheelbase_m / 2.0,
            -std::f64::consts::FRAC_PI_2,
        );
    }
    for (name, mount) in frames {
        let name = esc(name);
        out += &format!(
            "  <joint name=\"{name}_joint\" type=\"fixed\">\n    <parent link=\"base_link\"/>\n    \
             <child link=\"{name}\"/>\n    <origin xyz=\"{} {} 0\" rpy=\"0 0 {}\"/>\n  </joint>\n  \
             <link name=\"{name}\"/>\n",
            mount.x_m, mount.y_m, mount.heading_rad
        );
    }
    out + "</robot>\n"
}

/// Why a URDF gives no wheels: what is missing or malformed, with the
/// line where there is one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UrdfError(pub String);

impl fmt::Display for UrdfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UrdfError {}

/// How far (30°) a wheel's axis may lean from the robot's left-right axis.
const LATERAL_COS: f64 = 0.866;
/// A wheel closer than this to the robot's centre line (m) is on neither side.
const SIDE_M: f64 = 1e-3;

/// A rigid transform: rotation `r` (rows), then translation `t`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Transform {
    r: [[f64; 3]; 3],
    t: [f64; 3],
}

impl Transform {
    const IDENTITY: Self = Self {
        r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        t: [0.0; 3],
    };

    /// URDF's `<origin xyz rpy>`: fixed-axis roll about x, then pitch
    /// about y, then yaw about z (R = Rz·Ry·Rx).
    fn from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Self {
        let (sr, cr) = rpy[0].sin_cos();
        let (sp, cp) = rpy[1].sin_cos();
        let (sy, cy) = rpy[2].sin_cos();
        Self {
            r: [
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                [-sp, cp * sr, cp * cr],
            ],
            t: xyz,
        }
    }

    fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.r;
        [
            r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
            r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
            r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2],
        ]
    }

    /// `self` then `next` (next's frame given in self's).
    fn then(&self, next: &Self) -> Self {
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = (0..3).map(|k| self.r[i][k] * next.r[k][j]).sum();
            }
        }
        let moved = self.rotate(next.t);
        Self {
            r,
            t: [
                moved[0] + self.t[0],
                moved[1] + self.t[1],
                moved[2] + self.t[2],
            ],
        }
    }

    fn inverse(&self) -> Self {
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = self.r[j][i];
            }
        }
        let back = Self { r, t: [0.0; 3] }.rotate(self.t);
        Self {
            r,
            t: [-back[0], -back[1], -back[2]],
        }
    }
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > 0.0 {
        [v[0] / n, v[1] / n, v[2] / n]
    } else {
        v
    }
}

/// A `<cylinder>` of a link: its radius and its axis (z) in the link's frame.
#[derive(Debug, Clone, Copy)]
struct Cylinder {
    radius_m: f64,
    axis: [f64; 3],
    collision: bool,
}

#[derive(Debug)]
struct Joint {
    name: String,
    kind: String,
    parent: String,
    child: String,
    origin: Transform,
    axis: [f64; 3],
}

/// The line of `node` in `doc`.
fn line(doc: &roxmltree::Document, node: roxmltree::Node) -> u32 {
    doc.text_pos_at(node.range().start).row
}

fn err<T>(message: impl Into<String>) -> Result<T, UrdfError> {
    Err(UrdfError(message.into()))
}

/// Three numbers of attribute `attr` of `node` (`default` when absent).
fn triple(
    doc: &roxmltree::Document,
    node: roxmltree::Node,
    attr: &str,
    default: [f64; 3],
    owner: &str,
) -> Result<[f64; 3], UrdfError> {
    let Some(text) = node.attribute(attr) else {
        return Ok(default);
    };
    let parts: Vec<Option<f64>> = text
        .split_whitespace()
        .map(|p| p.parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect();
    match parts[..] {
        [Some(a), Some(b), Some(c)] => Ok([a, b, c]),
        _ => err(format!(
            "line {}: {owner}'s <{} {attr}=\"{text}\">: expected three numbers",
            line(doc, node),
            node.tag_name().name()
        )),
    }
}

/// `<origin>` under `node`, the identity when absent.
fn origin_of(
    doc: &roxmltree::Document,
    node: roxmltree::Node,
    owner: &str,
) -> Result<Transform, UrdfError> {
    match child(node, "origin") {
        Some(o) => Ok(Transform::from_xyz_rpy(
            triple(doc, o, "xyz", [0.0; 3], owner)?,
            triple(doc, o, "rpy", [0.0; 3], owner)?,
        )),
        None => Ok(Transform::IDENTITY),
    }
}

fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, name: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children()
        .find(|c| c.is_element() && c.tag_name().name() == name)
}

fn children<'a, 'i>(
    node: roxmltree::Node<'a, 'i>,
    name: &'static str,
) -> impl Iterator<Item = roxmltree::Node<'a, 'i>> {
    node.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == name)
}

/// The cylinders of a `<link>`: those under `<collision>` and `<visual>`,
/// with their axes in the link's frame.
fn cylinders(
    doc: &roxmltree::Document,
    link: roxmltree::Node,
    name: &str,
) -> Result<Vec<Cylinder>, UrdfError> {
    let mut out = Vec::new();
    for (kind, collision) in [("collision", true), ("visual", false)] {
        for shape in children(link, kind) {
            let Some(cylinder) = child(shape, "geometry").and_then(|g| child(g, "cylinder")) else {
                continue;
            };
            let owner = format!("link `{name}`");
            let radius = cylinder.attribute("radius").ok_or_else(|| {
                UrdfError(format!(
                    "line {}: {owner}'s <cylinder> has no radius",
                    line(doc, cylinder)
                ))
            })?;
            let radius_m = radius
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|r| r.is_finite() && *r > 0.0)
                .ok_or_else(|| {
                    UrdfError(format!(
                        "line {}: {owner}'s <cylinder radius=\"{radius}\">: expected a number > 0 (metres)",
                        line(doc, cylinder)
                    ))
                })?;
            let origin = origin_of(doc, shape, &owner)?;
            out.push(Cylinder {
                radius_m,
                axis: origin.rotate([0.0, 0.0, 1.0]),
                collision,
            });
        }
    }
    Ok(out)
}

/// The robot's two drive wheels from URDF text (see the module's doc).
pub fn wheels(text: &str) -> Result<WheelGeometry, UrdfError> {
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..roxmltree::ParsingOptions::default()
    };
    let doc = roxmltree::Document::parse_with_options(text, options)
        .map_err(|e| UrdfError(format!("not well-formed XML: {e}")))?;
    let robot = doc.root_element();
    if robot.tag_name().name() != "robot" {
        return err(format!(
            "the root element is <{}>, expected <robot> (a URDF)",
            robot.tag_name().name()
        ));
    }
    if let Some(x) = robot.descendants().find(|n| {
        n.is_element()
            && n.tag_name()
                .namespace()
                .is_some_and(|ns| ns.contains("xacro"))
    }) {
        return err(format!(
            "line {}: <xacro:{}>: the URDF is not expanded (robot_state_publisher publishes it run through xacro)",
            line(&doc, x),
            x.tag_name().name()
        ));
    }
    let robot_name = robot.attribute("name").unwrap_or("").to_string();
    // Links and their cylinders.
    let mut links: HashMap<String, Vec<Cylinder>> = HashMap::new();
    for link in children(robot, "link") {
        let Some(name) = link.attribute("name") else {
            return err(format!("line {}: a <link> has no name", line(&doc, link)));
        };
        let found = cylinders(&doc, link, name)?;
        if links.insert(name.to_string(), found).is_some() {
            return err(format!(
                "line {}: a second <link name=\"{name}\">",
                line(&doc, link)
            ));
        }
    }
    if links.is_empty() {
        return err("the URDF has no <link>");
    }
    // Joints, and each link's joint from its parent.
    let mut joints: Vec<Joint> = Vec::new();
    let mut parent_joint: HashMap<String, usize> = HashMap::new();
    for j in children(robot, "joint") {
        let at = line(&doc, j);
        let Some(name) = j.attribute("name") else {
            return err(format!("line {at}: a <joint> has no name"));
        };
        let owner = format!("joint `{name}`");
        let Some(kind) = j.attribute("type") else {
            return err(format!("line {at}: {owner} has no type"));
        };
        let link_of = |tag: &str| -> Result<String, UrdfError> {
            let link = child(j, tag)
                .and_then(|n| n.attribute("link"))
                .ok_or_else(|| UrdfError(format!("line {at}: {owner} has no <{tag} link=...>")))?;
            if !links.contains_key(link) {
                return err(format!(
                    "line {at}: {owner}'s {tag} link `{link}` is not a <link> of the URDF"
                ));
            }
            Ok(link.to_string())
        };
        let (parent, child_link) = (link_of("parent")?, link_of("child")?);
        let axis = match child(j, "axis") {
            Some(a) => unit(triple(&doc, a, "xyz", [1.0, 0.0, 0.0], &owner)?),
            None => [1.0, 0.0, 0.0],
        };
        if let Some(k) = parent_joint.get(&child_link) {
            return err(format!(
                "line {at}: {owner} gives link `{child_link}` a second parent (joint `{}` is its first): a URDF is a tree",
                joints[*k].name
            ));
        }
        parent_joint.insert(child_link.clone(), joints.len());
        joints.push(Joint {
            name: name.to_string(),
            kind: kind.to_string(),
            parent,
            child: child_link,
            origin: origin_of(&doc, j, &owner)?,
            axis,
        });
    }
    // Each link's pose from its tree's root (joints at zero).
    let mut pose: HashMap<&str, (Transform, &str)> = HashMap::new();
    fn place<'a>(
        link: &'a str,
        joints: &'a [Joint],
        parent_joint: &HashMap<String, usize>,
        pose: &mut HashMap<&'a str, (Transform, &'a str)>,
        depth: usize,
    ) -> Result<(Transform, &'a str), UrdfError> {
        if let Some(p) = pose.get(link) {
            return Ok(*p);
        }
        if depth > joints.len() {
            return err(format!(
                "the joints from link `{link}` up form a loop: a URDF is a tree"
            ));
        }
        let placed = match parent_joint.get(link) {
            None => (Transform::IDENTITY, link),
            Some(&k) => {
                let j = &joints[k];
                let (above, root) = place(&j.parent, joints, parent_joint, pose, depth + 1)?;
                (above.then(&j.origin), root)
            }
        };
        pose.insert(link, placed);
        Ok(placed)
    }
    let mut names: Vec<&str> = links.keys().map(String::as_str).collect();
    names.sort_unstable();
    for name in &names {
        place(name, &joints, &parent_joint, &mut pose, 0)?;
    }
    let base = ["base_link", "base_footprint"]
        .into_iter()
        .find(|b| links.contains_key(*b))
        .or_else(|| {
            let roots: Vec<&str> = names
                .iter()
                .copied()
                .filter(|n| !parent_joint.contains_key(*n))
                .collect();
            (roots.len() == 1).then(|| roots[0])
        })
        .ok_or_else(|| {
            UrdfError(
                "no base link: no `base_link` or `base_footprint`, and more than one root link"
                    .into(),
            )
        })?;
    let (base_pose, base_root) = pose[base];
    let from_base = base_pose.inverse();
    // The links fixed to each link (a wheel's rigid body).
    let mut fixed_children: HashMap<&str, Vec<&str>> = HashMap::new();
    for j in &joints {
        if j.kind == "fixed" {
            fixed_children
                .entry(j.parent.as_str())
                .or_default()
                .push(j.child.as_str());
        }
    }
    let lateral = |v: [f64; 3]| unit(v)[1].abs() >= LATERAL_COS;
    let turning: Vec<&Joint> = joints
        .iter()
        .filter(|j| j.kind == "continuous" || j.kind == "revolute")
        .collect();
    if turning.is_empty() {
        return err(format!(
            "robot `{robot_name}` has no continuous or revolute joint: no wheel to read"
        ));
    }
    let mut candidates: Vec<Wheel> = Vec::new();
    let mut rejected: Vec<String> = Vec::new();
    for j in &turning {
        let (link_pose, root) = pose[j.child.as_str()];
        if root != base_root {
            rejected.push(format!("{} (not attached to `{base}`)", j.name));
            continue;
        }
        let in_base = from_base.then(&link_pose);
        if !lateral(in_base.rotate(j.axis)) {
            rejected.push(format!("{} (turns about no left-right axis)", j.name));
            continue;
        }
        // The child link and the links fixed to it: their cylinders about
        // the left-right axis, collision shapes first.
        let mut body = vec![(j.child.as_str(), Transform::IDENTITY)];
        let mut shapes: Vec<Cylinder> = Vec::new();
        while let Some((link, at)) = body.pop() {
            for c in &links[link] {
                let axis = in_base.then(&at).rotate(c.axis);
                if lateral(axis) {
                    shapes.push(*c);
                }
            }
            for k in fixed_children.get(link).into_iter().flatten() {
                let fixed = &joints[parent_joint[*k]];
                body.push((k, at.then(&fixed.origin)));
            }
        }
        let collision = shapes.iter().any(|c| c.collision);
        let radius_m = shapes
            .iter()
            .filter(|c| c.collision == collision)
            .map(|c| c.radius_m)
            .fold(None, |m: Option<f64>, r| Some(m.map_or(r, |m| m.max(r))));
        let Some(radius_m) = radius_m else {
            rejected.push(format!(
                "{} (link `{}` has no <cylinder> about its axis)",
                j.name, j.child
            ));
            continue;
        };
        candidates.push(Wheel {
            joint: j.name.clone(),
            link: j.child.clone(),
            radius_m,
            position_m: in_base.t,
        });
    }
    if candidates.len() > 2 {
        let named = |w: &Wheel, side: &str| {
            w.joint.to_lowercase().contains(side) || w.link.to_lowercase().contains(side)
        };
        let sided: Vec<Wheel> = candidates
            .iter()
            .filter(|w| named(w, "left") || named(w, "right"))
            .cloned()
            .collect();
        if sided.iter().any(|w| named(w, "left")) && sided.iter().any(|w| named(w, "right")) {
            candidates = sided;
        }
    }
    let side = |left: bool| -> Vec<&Wheel> {
        candidates
            .iter()
            .filter(|w| {
                if left {
                    w.position_m[1] > SIDE_M
                } else {
                    w.position_m[1] < -SIDE_M
                }
            })
            .collect()
    };
    let list = |ws: &[&Wheel]| match ws.len() {
        0 => "none".to_string(),
        n => format!(
            "{n} ({})",
            ws.iter()
                .map(|w| format!("{} at y {:.4} m", w.joint, w.position_m[1]))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let (left, right) = (side(true), side(false));
    match (&left[..], &right[..]) {
        ([l], [r]) => Ok(WheelGeometry {
            robot: robot_name,
            base_link: base.to_string(),
            left: (*l).clone(),
            right: (*r).clone(),
        }),
        _ if candidates.is_empty() => err(format!(
            "robot `{robot_name}` has no wheel joint: a continuous or revolute joint whose link has a <cylinder> about the left-right axis; its joints that turn: {}",
            rejected.join(", ")
        )),
        _ => err(format!(
            "robot `{robot_name}`: expected one wheel joint on each side of `{base}`; on the left (+y): {}; on the right: {}",
            list(&left),
            list(&right)
        )),
    }
}

#[cfg(test)]
mod tests;
