//! Motion of the simulated robot: exact arcs, encoders that track the true
//! wheel rotation, and walls that are never penetrated.

mod common;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_sim::{Simulator, StepOutput, Vector};

#[test]
fn constant_wheel_speeds_drive_the_closed_form_circle() {
    let ctrl = r#"kind = "scripted"
segments = [{ duration_s = 60.0, left_rad_s = 4.0, right_rad_s = 6.0 }]"#;
    let sc = common::parse(&common::scenario_toml("", ctrl, 40.0, 0.0)).unwrap();
    let p = sc.robot.true_params;
    let (vl, vr) = (
        4.0 * p.left_diameter_m / 2.0,
        6.0 * p.right_diameter_m / 2.0,
    );
    let radius = 0.5 * p.wheelbase_m * (vr + vl) / (vr - vl);
    let mut sim = Simulator::new(sc);
    let mut out = StepOutput::new(sim.beams());
    let mut centre = None;
    let mut checked = 0;
    while sim.step(&mut out) {
        let s = &out.record;
        // Once both wheels are at speed the path is one exact circle.
        if s.wheel_rad_s != [4.0, 6.0] {
            continue;
        }
        let g = s.ground_truth;
        let c = *centre.get_or_insert((
            g.x_m - radius * g.heading_rad.sin(),
            g.y_m + radius * g.heading_rad.cos(),
        ));
        let r = (g.x_m - c.0).hypot(g.y_m - c.1);
        assert!(
            (r - radius).abs() < 1e-9,
            "t = {} s: radius {r} vs closed form {radius}",
            s.t_s()
        );
        checked += 1;
    }
    assert!(checked > 3900, "{checked} steps at constant speed");
}

#[test]
fn encoder_counts_stay_within_one_tick_of_the_true_wheel_travel() {
    let ctrl = r#"kind = "scripted"
repeat = true
segments = [
  { duration_s = 3.0, left_rad_s = 6.0, right_rad_s = 4.0 },
  { duration_s = 2.0, left_rad_s = -5.0, right_rad_s = 5.0 },
  { duration_s = 2.5, left_rad_s = -3.0, right_rad_s = -6.0 },
]"#;
    let sc = common::parse(&common::scenario_toml("", ctrl, 60.0, 0.002)).unwrap();
    let enc = sc.robot.encoder;
    let dt_s = sc.dt_s();
    let mut sim = Simulator::new(sc);
    let mut out = StepOutput::new(sim.beams());
    let mut integrated = [0.0f64; 2];
    let mut samples = 0;
    let mut rotation_abs = [0.0f64; 2];
    let mut went_backwards = [false; 2];
    loop {
        let true_angle = sim.wheel_angle_rad();
        if !sim.step(&mut out) {
            break;
        }
        let ticks = out
            .record
            .encoder_ticks
            .expect("encoders sample every step by default");
        for w in 0..2 {
            let exact_ticks = true_angle[w] / enc.rad_per_tick();
            let lag = exact_ticks - ticks[w] as f64;
            assert!(
                (0.0..1.0).contains(&lag),
                "wheel {w}: {} ticks for {exact_ticks} exact",
                ticks[w]
            );
            // The logged actual wheel speeds integrate to the same rotation.
            assert!((integrated[w] - true_angle[w]).abs() < 1e-9);
        }
        for w in 0..2 {
            integrated[w] += out.record.wheel_rad_s[w] * dt_s;
            rotation_abs[w] += (out.record.wheel_rad_s[w] * dt_s).abs();
            went_backwards[w] |= out.record.wheel_rad_s[w] < 0.0;
        }
        samples += 1;
    }
    assert_eq!(samples, 6000);
    // Both wheels turned a lot, both ways, so counting down was exercised too.
    assert!(rotation_abs.iter().all(|&r| r > 200.0), "{rotation_abs:?}");
    assert_eq!(went_backwards, [true, true]);
}

#[test]
fn a_long_random_drive_never_penetrates_a_wall() {
    let seed = 5;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let segments: Vec<String> = (0..150)
        .map(|_| {
            format!(
                "{{ duration_s = {:.2}, left_rad_s = {:.3}, right_rad_s = {:.3} }}",
                rng.random_range(0.5..4.0),
                rng.random_range(-12.0..12.0),
                rng.random_range(-12.0..12.0)
            )
        })
        .collect();
    let ctrl = format!("kind = \"scripted\"\nsegments = [{}]", segments.join(",\n"));
    let world = r#"rectangles = [{ min = [2.0, 2.0], max = [3.0, 4.5] }, { min = [6.5, 6.0], max = [8.0, 6.4] }]
segments = [[[1.0, 8.0], [4.0, 7.0]], [[7.0, 1.0], [7.0, 3.5]]]"#;
    let sc = common::parse(&common::scenario_toml(world, &ctrl, 400.0, 0.01)).unwrap();
    let world = sc.world.clone();
    let radius = sc.robot.footprint_radius_m;
    let mut sim = Simulator::new(sc);
    let mut out = StepOutput::new(sim.beams());
    let (mut contacts, mut min_gap) = (0, f64::INFINITY);
    let mut distance = 0.0;
    let mut prev = sim.pose();
    while sim.step(&mut out) {
        let p = sim.pose();
        distance += p.distance_to(&prev);
        prev = p;
        if let Some(n) = world.nearest_within(Vector::new(p.x_m, p.y_m), radius + 0.01) {
            min_gap = min_gap.min(n.distance_m - radius);
        }
        contacts += usize::from(out.record.bump);
    }
    assert!(
        min_gap >= -1e-12,
        "seed {seed}: footprint penetrated a wall by {}",
        -min_gap
    );
    assert!(
        min_gap < 1e-3,
        "seed {seed}: never touched a wall, the test proves nothing"
    );
    assert!(
        contacts > 20,
        "seed {seed}: only {contacts} steps with the bumper pressed"
    );
    assert!(distance > 30.0, "seed {seed}: drove only {distance} m");
}
