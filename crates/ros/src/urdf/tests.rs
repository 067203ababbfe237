//! Synthetic URDFs with random wheels hung in the ways real robots hang
//! them, and the distractors real robots have (casters, a spinning
//! lidar, body cylinders, meshes); the geometry recovered must be the
//! one built.

use std::f64::consts::FRAC_PI_2;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;

fn f(v: f64) -> String {
    format!("{v:.17}")
}

fn origin(xyz: [f64; 3], rpy: [f64; 3]) -> String {
    format!(
        "<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
        f(xyz[0]),
        f(xyz[1]),
        f(xyz[2]),
        f(rpy[0]),
        f(rpy[1]),
        f(rpy[2])
    )
}

fn joint(name: &str, kind: &str, parent: &str, child: &str, origin: &str, axis: &str) -> String {
    format!(
        "<joint name=\"{name}\" type=\"{kind}\"><parent link=\"{parent}\"/><child link=\"{child}\"/>{origin}{axis}</joint>"
    )
}

fn cylinder(under: &str, radius: f64, shape_origin: &str) -> String {
    format!(
        "<{under}>{shape_origin}<geometry><cylinder radius=\"{}\" length=\"0.03\"/></geometry></{under}>",
        f(radius)
    )
}

fn link(name: &str, shapes: &str) -> String {
    format!("<link name=\"{name}\">{shapes}</link>")
}

/// A drive wheel at `p` (base_link's frame) of radius `r`, named `name`,
/// hung in style `style`: its elements (links and joints).
fn wheel(rng: &mut ChaCha8Rng, name: &str, p: [f64; 3], r: f64, style: u32) -> Vec<String> {
    let joint_name = format!("{name}_joint");
    let cyl_z = cylinder("collision", r, "") + &cylinder("visual", r, "");
    match style {
        // Straight from the base: rolled so that z (the cylinder's axis
        // and the joint's) points along y.
        0 => {
            let roll = if rng.random_bool(0.5) {
                -FRAC_PI_2
            } else {
                FRAC_PI_2
            };
            vec![
                joint(
                    &joint_name,
                    "continuous",
                    "base_link",
                    name,
                    &origin(p, [roll, 0.0, 0.0]),
                    "<axis xyz=\"0 0 1\"/>",
                ),
                link(name, &cyl_z),
            ]
        }
        // Through a fixed mount turned by a random yaw about z and a
        // random roll about the (lateral) wheel axis: the wheel's origin
        // is given in the mount's frame; the axis is the joint's y, the
        // cylinder rolled onto it by its own origin.
        1 => {
            let m = [
                p[0] + rng.random_range(-0.1..0.1),
                p[1] + rng.random_range(-0.1..0.1),
                p[2] + rng.random_range(-0.05..0.05),
            ];
            let yaw = rng.random_range(-0.2..0.2_f64);
            let (s, c) = yaw.sin_cos();
            // p − m in the mount's frame: rotated back by the yaw.
            let (dx, dy) = (p[0] - m[0], p[1] - m[1]);
            let local = [c * dx + s * dy, -s * dx + c * dy, p[2] - m[2]];
            let mount = format!("{name}_mount");
            vec![
                joint(
                    &format!("{name}_mount_joint"),
                    "fixed",
                    "base_link",
                    &mount,
                    &origin(m, [0.0, 0.0, yaw]),
                    "",
                ),
                link(&mount, ""),
                joint(
                    &joint_name,
                    "continuous",
                    &mount,
                    name,
                    &origin(local, [0.0, 0.0, 0.0]),
                    "<axis xyz=\"0 1 0\"/>",
                ),
                link(
                    name,
                    &cylinder("collision", r, &origin([0.0; 3], [FRAC_PI_2, 0.0, 0.0])),
                ),
            ]
        }
        // Below a suspension's prismatic joint (as the iRobot Create 3's
        // wheel drop), the cylinder only under <visual>, and a smaller hub
        // cylinder beside it.
        2 => {
            let drop = format!("{name}_drop");
            vec![
                joint(
                    &format!("{name}_drop_joint"),
                    "prismatic",
                    "base_link",
                    &drop,
                    &origin(p, [-FRAC_PI_2, 0.0, 0.0]),
                    "<axis xyz=\"0 1 0\"/><limit effort=\"0\" lower=\"0\" upper=\"0.03\" velocity=\"0\"/>",
                ),
                link(&drop, ""),
                joint(
                    &joint_name,
                    "revolute",
                    &drop,
                    name,
                    &origin([0.0; 3], [0.0; 3]),
                    "<axis xyz=\"0 0 -1\"/><limit effort=\"1\" lower=\"-1e9\" upper=\"1e9\" velocity=\"10\"/>",
                ),
                link(
                    name,
                    &(cylinder("visual", r, "") + &cylinder("visual", 0.4 * r, "")),
                ),
            ]
        }
        // The tyre on a link fixed to the wheel's link, which has only a mesh.
        _ => {
            let tyre = format!("{name}_tyre");
            vec![
                joint(
                    &joint_name,
                    "continuous",
                    "base_link",
                    name,
                    &origin(p, [-FRAC_PI_2, 0.0, 0.0]),
                    "<axis xyz=\"0 0 1\"/>",
                ),
                link(
                    name,
                    "<visual><geometry><mesh filename=\"package://r/wheel.dae\"/></geometry></visual>",
                ),
                joint(
                    &format!("{name}_tyre_joint"),
                    "fixed",
                    name,
                    &tyre,
                    &origin([0.0; 3], [0.0; 3]),
                    "",
                ),
                link(&tyre, &cyl_z),
            ]
        }
    }
}

/// A random robot: base_footprint over base_link (offset and turned, so
/// measuring from the root would be wrong), two drive wheels, and
/// distractors; elements shuffled. Returns the URDF and the truth
/// `(left radius, right radius, left y, right y)`.
fn robot(seed: u64) -> (String, [f64; 4]) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rl = rng.random_range(0.02..0.2);
    let rr = rl * rng.random_range(0.97..1.03);
    let x = rng.random_range(-0.2..0.2);
    let pl = [
        x + rng.random_range(-0.01..0.01),
        rng.random_range(0.05..0.4),
        rng.random_range(-0.05..0.1),
    ];
    let pr = [
        x + rng.random_range(-0.01..0.01),
        -rng.random_range(0.05..0.4),
        pl[2],
    ];
    let mut parts = vec![
        link("base_footprint", ""),
        joint(
            "base_joint",
            "fixed",
            "base_footprint",
            "base_link",
            &origin(
                [
                    rng.random_range(-0.1..0.1),
                    rng.random_range(-0.1..0.1),
                    0.05,
                ],
                [0.0, 0.0, rng.random_range(-3.0..3.0)],
            ),
            "",
        ),
        link(
            "base_link",
            &cylinder("collision", rng.random_range(0.1..0.3), ""),
        ),
    ];
    // Every pair of styles over 16 seeds.
    let (sl, sr) = ((seed % 4) as u32, (seed / 4 % 4) as u32);
    parts.extend(wheel(&mut rng, "left_wheel", pl, rl, sl));
    parts.extend(wheel(&mut rng, "right_wheel", pr, rr, sr));
    // A caster: a swivel about z carrying a small wheel about y.
    let caster_y = rng.random_range(-0.1..0.1);
    parts.extend([
        joint(
            "caster_swivel_joint",
            "continuous",
            "base_link",
            "caster_swivel",
            &origin([0.25, caster_y, 0.0], [0.0; 3]),
            "<axis xyz=\"0 0 1\"/>",
        ),
        link("caster_swivel", ""),
        joint(
            "caster_wheel_joint",
            "continuous",
            "caster_swivel",
            "caster_wheel",
            &origin([-0.02, 0.0, -0.03], [-FRAC_PI_2, 0.0, 0.0]),
            "<axis xyz=\"0 0 1\"/>",
        ),
        link("caster_wheel", &cylinder("collision", 0.5 * rl, "")),
    ]);
    // A spinning lidar: a cylinder about z.
    parts.extend([
        joint(
            "lidar_spin_joint",
            "continuous",
            "base_link",
            "lidar",
            &origin([0.0, 0.0, 0.2], [0.0; 3]),
            "<axis xyz=\"0 0 1\"/>",
        ),
        link("lidar", &cylinder("collision", 0.04, "")),
    ]);
    // Elements in any order.
    for i in (1..parts.len()).rev() {
        parts.swap(i, rng.random_range(0..=i));
    }
    let text = format!(
        "<?xml version=\"1.0\"?>\n<!-- generated -->\n<robot name=\"r{seed}\">\n{}\n</robot>\n",
        parts.join("\n")
    );
    (text, [rl, rr, pl[1], pr[1]])
}

#[test]
fn random_robots_give_back_their_wheels() {
    for seed in 0..200 {
        let (text, [rl, rr, yl, yr]) = robot(seed);
        let w = wheels(&text).unwrap_or_else(|e| panic!("seed {seed}: {e}\n{text}"));
        assert_eq!(w.base_link, "base_link");
        assert_eq!(
            (w.left.joint.as_str(), w.right.joint.as_str()),
            ("left_wheel_joint", "right_wheel_joint"),
            "seed {seed}"
        );
        for (got, want, what) in [
            (w.left_diameter_m(), 2.0 * rl, "left diameter"),
            (w.right_diameter_m(), 2.0 * rr, "right diameter"),
            (w.wheelbase_m(), yl - yr, "wheelbase"),
            (w.left.position_m[1], yl, "left y"),
        ] {
            assert!(
                (got - want).abs() < 1e-9,
                "seed {seed}: {what} {got}, built {want}\n{text}"
            );
        }
    }
}

/// Without left/right names the two drive wheels are told apart from a
/// third by nothing: the error lists what it found on each side.
#[test]
fn wheels_named_for_no_side_are_taken_only_when_there_are_two() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let p = |y: f64| [0.0, y, 0.0];
    let mut parts = vec![link("base_link", "")];
    parts.extend(wheel(&mut rng, "wheel_a", p(0.12), 0.05, 0));
    parts.extend(wheel(&mut rng, "wheel_b", p(-0.13), 0.06, 0));
    let two = format!("<robot name=\"t\">{}</robot>", parts.join(""));
    let w = wheels(&two).unwrap();
    assert_eq!(
        (w.left.joint.as_str(), w.right.joint.as_str()),
        ("wheel_a_joint", "wheel_b_joint")
    );
    assert!((w.wheelbase_m() - 0.25).abs() < 1e-12);
    parts.extend(wheel(&mut rng, "wheel_c", p(0.2), 0.05, 0));
    let three = format!("<robot name=\"t\">{}</robot>", parts.join(""));
    let e = wheels(&three).unwrap_err().to_string();
    assert!(
        e.contains("on the left (+y): 2 (wheel_a_joint at y 0.1200 m, wheel_c_joint at y 0.2000 m); on the right: 1 (wheel_b_joint"),
        "{e}"
    );
}

#[test]
fn urdfs_without_wheels_say_what_is_missing() {
    let base = link("base_link", "");
    let cases: Vec<(String, &str)> = vec![
        ("<robot name=\"a\"><link name=\"base_link\">".into(), "not well-formed XML"),
        ("<sdf><model/></sdf>".into(), "expected <robot>"),
        (
            format!("<robot name=\"a\">{base}</robot>"),
            "robot `a` has no continuous or revolute joint",
        ),
        (
            format!(
                "<robot name=\"a\">{base}{}{}</robot>",
                joint("w", "continuous", "base_link", "wl", &origin([0.0, 0.1, 0.0], [-FRAC_PI_2, 0.0, 0.0]), "<axis xyz=\"0 0 1\"/>"),
                link("wl", "<collision><geometry><mesh filename=\"w.stl\"/></geometry></collision>")
            ),
            "has no wheel joint: a continuous or revolute joint whose link has a <cylinder> about the left-right axis; its joints that turn: w (link `wl` has no <cylinder> about its axis)",
        ),
        (
            format!(
                "<robot name=\"a\">{base}{}{}</robot>",
                joint("w", "continuous", "base_link", "wl", &origin([0.0, 0.1, 0.0], [-FRAC_PI_2, 0.0, 0.0]), "<axis xyz=\"0 0 1\"/>"),
                link("wl", &cylinder("collision", 0.05, ""))
            ),
            "on the left (+y): 1 (w at y 0.1000 m); on the right: none",
        ),
        (
            format!(
                "<robot name=\"a\">{base}\n{}</robot>",
                joint("w", "continuous", "base_link", "nowhere", "", "")
            ),
            "line 2: joint `w`'s child link `nowhere` is not a <link> of the URDF",
        ),
        (
            format!(
                "<robot name=\"a\">{base}\n<link name=\"wl\"><collision><geometry><cylinder length=\"0.1\"/></geometry></collision></link></robot>"
            ),
            "line 2: link `wl`'s <cylinder> has no radius",
        ),
        (
            format!(
                "<robot name=\"a\">{base}\n<joint name=\"w\" type=\"continuous\"><parent link=\"base_link\"/><child link=\"base_link\"/>\n<origin xyz=\"0 zero 0\"/></joint></robot>"
            ),
            "line 3: joint `w`'s <origin xyz=\"0 zero 0\">: expected three numbers",
        ),
        (
            "<robot name=\"a\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\"><xacro:macro name=\"m\"/></robot>".into(),
            "<xacro:macro>: the URDF is not expanded",
        ),
    ];
    for (text, says) in cases {
        let e = wheels(&text).unwrap_err().to_string();
        assert!(e.contains(says), "{text}\n{e}");
    }
}

#[test]
fn transforms_compose_and_invert() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..100 {
        let mut t = || {
            Transform::from_xyz_rpy(
                [
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                ],
                [
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-3.0..3.0),
                ],
            )
        };
        let (a, b) = (t(), t());
        let id = a.then(&b).then(&b.inverse()).then(&a.inverse());
        for i in 0..3 {
            assert!(id.t[i].abs() < 1e-12);
            for j in 0..3 {
                assert!((id.r[i][j] - Transform::IDENTITY.r[i][j]).abs() < 1e-12);
            }
        }
    }
    // rpy is roll about x, then pitch about y, then yaw about z (fixed axes):
    // roll 90° then yaw 90° takes z to −y, then to x.
    let r = Transform::from_xyz_rpy([0.0; 3], [FRAC_PI_2, 0.0, FRAC_PI_2]);
    let v = r.rotate([0.0, 0.0, 1.0]);
    assert!(
        (v[0] - 1.0).abs() < 1e-12 && v[1].abs() < 1e-12 && v[2].abs() < 1e-12,
        "{v:?}"
    );
}

/// What twindrive writes of a robot reads back to the same wheels, to
/// the last bit (halving and doubling are exact; numbers print in full).
#[test]
fn a_described_robot_reads_back_exactly() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..100 {
        let params = twindrive_kinematics::DiffDriveParams {
            left_diameter_m: rng.random_range(0.03..0.5),
            right_diameter_m: rng.random_range(0.03..0.5),
            wheelbase_m: rng.random_range(0.1..1.0),
        };
        let frames = vec![(
            "lidar<1>_link".to_string(),
            twindrive_kinematics::Pose::new(
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.2..0.2),
                rng.random_range(-3.0..3.0),
            ),
        )];
        let text = describe(
            "rover \"one\"",
            &params,
            rng.random_range(0.1..0.5),
            ["wheel_left_joint", "wheel_right_joint"],
            &frames,
        );
        let w = wheels(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(w.robot, "rover \"one\"");
        assert_eq!(
            (w.left.joint.as_str(), w.right.joint.as_str()),
            ("wheel_left_joint", "wheel_right_joint")
        );
        assert_eq!(w.left_diameter_m(), params.left_diameter_m);
        assert_eq!(w.right_diameter_m(), params.right_diameter_m);
        assert_eq!(w.wheelbase_m(), params.wheelbase_m);
    }
}
