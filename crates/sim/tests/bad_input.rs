//! Scenarios that cannot be simulated fail with the file and field named.

mod common;

fn error_of(text: &str) -> String {
    match common::parse(text) {
        Ok(_) => panic!("scenario was accepted"),
        Err(e) => e.to_string(),
    }
}

fn base() -> String {
    common::scenario_toml(
        "",
        "kind = \"scripted\"\nsegments = [{ duration_s = 1.0, left_rad_s = 1.0, right_rad_s = 1.0 }]",
        5.0,
        0.0,
    )
}

#[test]
fn unknown_key() {
    let text = base().replace("seed = 11", "seed = 11\nsed = 12");
    let err = error_of(&text);
    assert!(
        err.starts_with("test.toml:")
            && err.contains("unknown field `sed`")
            && err.contains("line"),
        "{err}"
    );
}

#[test]
fn non_positive_diameter() {
    let text = base().replace(
        "true_params = { left_diameter_m = 0.0652",
        "true_params = { left_diameter_m = -0.0652",
    );
    let err = error_of(&text);
    assert!(err.contains("test.toml: field `robot.true_params.left_diameter_m` must be a finite number > 0, got -0.0652"), "{err}");
}

#[test]
fn non_positive_time_step() {
    let err = error_of(&base().replace("dt_s = 0.01", "dt_s = 0.0"));
    assert!(
        err.contains("field `simulation.dt_s` must be a finite number > 0"),
        "{err}"
    );
}

#[test]
fn robot_inside_a_wall() {
    let text = base().replace("x_m = 5.0, y_m = 5.0", "x_m = 0.1, y_m = 5.0");
    let err = error_of(&text);
    assert!(
        err.contains("field `robot.start`") && err.contains("overlaps a wall"),
        "{err}"
    );
    let text = base().replace(
        "[world]\n",
        "[world]\nrectangles = [{ min = [4.0, 4.0], max = [6.0, 6.0] }]\n",
    );
    let err = error_of(&text);
    assert!(
        err.contains("field `robot.start`") && err.contains("inside an obstacle"),
        "{err}"
    );
}

#[test]
fn missing_map_file() {
    let text = base().replace("[world]\n", "[world]\nmap = \"no/such/map.yaml\"\n");
    let err = error_of(&text);
    assert!(
        err.contains("field `world.map`")
            && err.contains("no/such/map.yaml")
            && err.contains("does not exist"),
        "{err}"
    );
}

#[test]
fn unknown_side_sensor_and_bad_rates() {
    let text = common::scenario_toml(
        "",
        "kind = \"wall_follower\"\nside_sensor = \"ir\"\ntarget_range_m = 0.3\ncruise_speed_m_s = 0.2\ngain_rad_s_per_m = 1.0\nmax_turn_rate_rad_s = 1.0\nreverse_speed_m_s = 0.1\nreverse_duration_s = 1.0\nturn_rate_rad_s = 1.0\nturn_duration_s = 1.0",
        5.0,
        0.0,
    );
    assert!(
        error_of(&text).contains("field `controller.side_sensor` no range sensor is named `ir`")
    );
    let text = base().replace(
        "ticks_per_rev = 512",
        "ticks_per_rev = 512\nrate_hz = -50.0",
    );
    assert!(error_of(&text).contains("field `encoders.rate_hz` must be a finite number > 0"));
}

#[test]
fn steps_that_could_jump_a_wall_and_unseeable_contact() {
    let err = error_of(&base().replace("dt_s = 0.01", "dt_s = 1.0"));
    assert!(err.contains("field `simulation.dt_s` is too long"), "{err}");
    let err = error_of(&base().replace("[encoders]", "[bump]\ncontact_margin_m = 0.0\n[encoders]"));
    assert!(
        err.contains("field `bump.contact_margin_m` must be a finite number > 0"),
        "{err}"
    );
    let text = base().replace(
        "segments = [{ duration_s = 1.0,",
        "segments = [{ duration_s = 1e-10,",
    );
    let err = error_of(&text);
    assert!(
        err.contains("field `controller.segments[0].duration_s` must be at least one time step"),
        "{err}"
    );
}

#[test]
fn duration_overrides_are_checked_like_the_file() {
    let mut sc = common::parse(&base()).unwrap();
    assert!(
        sc.set_duration_s(-1.0)
            .unwrap_err()
            .contains("must be a finite number > 0")
    );
    assert!(
        sc.set_duration_s(1e12)
            .unwrap_err()
            .contains("need 1 to 2e9")
    );
    sc.set_duration_s(2.5).unwrap();
    assert_eq!(sc.steps, 250);
}

#[test]
fn gyro_and_dropout_fields_are_named() {
    let with_gyro =
        |gyro: &str| base().replace("[encoders]", &format!("[gyro]\n{gyro}\n[encoders]"));
    assert!(common::parse(&with_gyro("rate_hz = 100.0")).is_ok());
    for (gyro, want) in [
        (
            "rate_hz = 0.0",
            "field `gyro.rate_hz` must be a finite number > 0, got 0",
        ),
        ("noise_std_rad_s = 0.1", "missing field `rate_hz`"),
        ("rate_hz = 100.0\nbias = 0.1", "unknown field `bias`"),
        (
            "rate_hz = 100.0\nnoise_std_rad_s = -0.1",
            "field `gyro.noise_std_rad_s` must be a finite number >= 0, got -0.1",
        ),
        (
            "rate_hz = 100.0\nbias_rad_s = inf",
            "field `gyro.bias_rad_s` must be finite, got inf",
        ),
        (
            "rate_hz = 100.0\nscale_error = -1.0",
            "field `gyro.scale_error` must be a fraction in (-1, 1) (0.01 reads 1 % high), got -1",
        ),
        (
            "rate_hz = 100.0\nname = \"yaw rate\"",
            "field `gyro.name` must be non-empty letters, digits or `_`, got `yaw rate`",
        ),
    ] {
        let err = error_of(&with_gyro(gyro));
        assert!(err.contains(want), "{gyro}: {err}");
    }

    let sensor = |dropout: &str| {
        base().replace(
            "[encoders]",
            &format!(
                "[[range_sensors]]\nname = \"scan\"\nmount = {{ x_m = 0.0, y_m = 0.0, heading_rad = 0.0 }}\nmax_range_m = 5.0\n{dropout}\n[encoders]"
            ),
        )
    };
    assert!(common::parse(&sensor("dropout_probability = 0.25")).is_ok());
    for p in ["1.0", "-0.1", "nan"] {
        let err = error_of(&sensor(&format!("dropout_probability = {p}")));
        assert!(
            err.contains("field `range_sensors[0].dropout_probability` must be in [0, 1), got"),
            "{p}: {err}"
        );
    }
}

#[test]
fn a_sensor_kind_its_beams_contradict_is_refused_by_field() {
    let sensor = |fields: &str| {
        base().replace(
            "[encoders]",
            &format!(
                "[[range_sensors]]\nname = \"front\"\nmount = {{ x_m = 0.0, y_m = 0.0, heading_rad = 0.0 }}\nmax_range_m = 5.0\n{fields}\n[encoders]"
            ),
        )
    };
    let kind_of = |fields: &str| {
        common::parse(&sensor(fields)).unwrap().range_sensors[0]
            .info
            .kind
    };
    use twindrive_log::SensorKind;
    assert_eq!(kind_of(""), SensorKind::Ranger);
    assert_eq!(kind_of("kind = \"ranger\""), SensorKind::Ranger);
    assert_eq!(kind_of("beams = 12\nfov_rad = 1.0"), SensorKind::Lidar);
    assert_eq!(
        kind_of("kind = \"lidar\"\nbeams = 12\nfov_rad = 1.0"),
        SensorKind::Lidar
    );
    for (fields, want) in [
        (
            "kind = \"ranger\"\nbeams = 12\nfov_rad = 1.0",
            "field `range_sensors[0].kind` is \"ranger\": a ranger has one beam, got 12",
        ),
        (
            "kind = \"lidar\"",
            "field `range_sensors[0].kind` is \"lidar\": a lidar sweeps a fan of at least 2 beams, got 1",
        ),
        ("kind = \"sonar\"", "unknown variant `sonar`"),
    ] {
        let err = error_of(&sensor(fields));
        assert!(err.contains(want), "{fields}: {err}");
    }
}

#[test]
fn a_wall_follower_on_a_lidar_is_refused_by_kind() {
    let follower = "kind = \"wall_follower\"\nside_sensor = \"side\"\ntarget_range_m = 0.3\ncruise_speed_m_s = 0.2\ngain_rad_s_per_m = 1.0\nmax_turn_rate_rad_s = 1.0\nreverse_speed_m_s = 0.1\nreverse_duration_s = 1.0\nturn_rate_rad_s = 1.0\nturn_duration_s = 1.0";
    let with_side = |fields: &str| {
        common::scenario_toml("", follower, 5.0, 0.0).replace(
            "[encoders]",
            &format!(
                "[[range_sensors]]\nname = \"side\"\nmount = {{ x_m = 0.0, y_m = -0.1, heading_rad = -1.5 }}\nmax_range_m = 2.0\n{fields}\n[encoders]"
            ),
        )
    };
    common::parse(&with_side("")).unwrap();
    let err = error_of(&with_side("kind = \"lidar\"\nbeams = 90\nfov_rad = 1.0"));
    assert!(
        err.contains("field `controller.side_sensor` `side` is a lidar")
            && err.contains("kind = \"ranger\""),
        "{err}"
    );
}
