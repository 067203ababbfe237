//! Signed plans: a plan signed by a trusted key for this robot, inside its
//! validity window and above the last counter, is accepted byte for byte;
//! anything else is refused with its reason.

use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::envelope::{
    Envelope, PlanGate, Rejection, SigningKey, Supervision, private_key_pem, public_key_pem,
    read_private_key_pem, read_public_key_pem, sign_plan,
};
use twindrive_plan::WheelLimits;
use twindrive_plan::{MissionPlan, PlanHeader, PlanSample, RobotInfo};

/// A key of its own for each seed (tests need no randomness).
fn test_key(seed: u8) -> SigningKey {
    SigningKey::from_bytes(&[seed; 32])
}

/// A short straight plan, as `plan.json` bytes.
fn plan_json() -> Vec<u8> {
    let samples = (0..200)
        .map(|k| PlanSample {
            t_s: k as f64 * 0.01,
            x_m: k as f64 * 0.002,
            y_m: 0.0,
            heading_rad: 0.0,
            v_m_s: 0.2,
            omega_rad_s: 0.0,
            left_rad_s: 6.1,
            right_rad_s: 6.0,
            expected_bump: false,
        })
        .collect();
    let plan = MissionPlan::new(
        PlanHeader {
            robot: RobotInfo {
                scenario: "test".into(),
                footprint_radius_m: 0.15,
                ticks_per_rev: 512,
                range_sensors: Vec::new(),
            },
            calibrated: DiffDriveParams::new(0.0652, 0.0665, 0.2678),
            limits: WheelLimits {
                max_speed_rad_s: 12.0,
                max_accel_rad_s2: 30.0,
            },
            time_step_s: 0.01,
            start: Pose::new(0.0, 0.0, 0.0),
            start_covariance: None,
            site_map: Default::default(),
            freedom: Default::default(),
            goals: Default::default(),
            source_log_sha256: "0".repeat(64),
            settings: serde_json::json!({}),
            summary: serde_json::json!({}),
        },
        samples,
    );
    let mut bytes = serde_json::to_vec_pretty(&plan).unwrap();
    bytes.push(b'\n');
    bytes
}

fn envelope(robot: &str, counter: u64) -> Envelope {
    Envelope {
        format: String::new(),
        version: 0,
        plan_sha256: String::new(),
        plan_file_sha256: String::new(),
        plan_bytes: 0,
        plan_encoding: String::new(),
        robot_id: robot.into(),
        counter,
        not_before_unix_s: 1_000,
        expires_unix_s: 2_000,
        world_sha256: "a".repeat(64),
        supervision: Supervision {
            dead_man_timeout_s: Some(30.0),
        },
        tolerances: Default::default(),
    }
}

fn gate(key: &ed25519_dalek::SigningKey) -> PlanGate {
    PlanGate {
        robot_id: "rover".into(),
        trusted: vec![key.verifying_key()],
        max_signed_bytes: 1 << 20,
        max_plan_bytes: 16 << 20,
    }
}

#[test]
fn a_signed_plan_is_accepted_byte_for_byte() {
    let key = test_key(1);
    let json = plan_json();
    let signed = sign_plan(&key, &json, envelope("rover", 5)).unwrap();
    // Compressed: far smaller than the document.
    assert!(
        signed.len() * 4 < json.len(),
        "{} of {}",
        signed.len(),
        json.len()
    );
    let accepted = gate(&key).check(&signed, 4, 1_500).unwrap();
    assert_eq!(accepted.plan_json, json);
    assert_eq!(accepted.envelope.counter, 5);
    assert_eq!(accepted.envelope.supervision.dead_man_timeout_s, Some(30.0));
    // Keys survive their PEM files.
    let again = read_private_key_pem(&private_key_pem(&key)).unwrap();
    assert_eq!(again.to_bytes(), key.to_bytes());
    let public = read_public_key_pem(&public_key_pem(&key.verifying_key())).unwrap();
    assert_eq!(public, key.verifying_key());
    assert!(
        read_public_key_pem("-----BEGIN PUBLIC KEY-----\nAAAA\n-----END PUBLIC KEY-----\n")
            .is_err()
    );
}

#[test]
fn forged_replayed_expired_misaddressed_and_corrupted_plans_are_refused() {
    let key = test_key(2);
    let json = plan_json();
    let signed = sign_plan(&key, &json, envelope("rover", 5)).unwrap();
    let g = gate(&key);

    // Signed by a key the robot does not trust.
    let stranger = test_key(3);
    let forged = sign_plan(&stranger, &json, envelope("rover", 5)).unwrap();
    assert_eq!(
        g.check(&forged, 0, 1_500).unwrap_err(),
        Rejection::BadSignature
    );
    // The envelope changed after signing (a higher counter, say).
    let mut tampered = signed.clone();
    let at = tampered
        .windows(11)
        .position(|w| w == b"\"counter\":5")
        .unwrap();
    tampered[at + 10] = b'9';
    assert_eq!(
        g.check(&tampered, 0, 1_500).unwrap_err(),
        Rejection::BadSignature
    );
    // Replayed: the robot already accepted counter 5.
    assert!(matches!(
        g.check(&signed, 5, 1_500),
        Err(Rejection::Replay {
            counter: 5,
            last: 5
        })
    ));
    // Outside its window.
    assert!(matches!(
        g.check(&signed, 0, 999),
        Err(Rejection::NotYetValid { .. })
    ));
    assert!(matches!(
        g.check(&signed, 0, 2_000),
        Err(Rejection::Expired { .. })
    ));
    // For another robot.
    let other = sign_plan(&key, &json, envelope("rover-2", 6)).unwrap();
    assert!(matches!(
        g.check(&other, 0, 1_500),
        Err(Rejection::WrongRobot { .. })
    ));
    // A byte of the compressed plan flipped.
    let mut corrupted = signed.clone();
    let last = corrupted.len() - 3;
    corrupted[last] ^= 0xff;
    assert!(matches!(
        g.check(&corrupted, 0, 1_500),
        Err(Rejection::PlanMismatch(_) | Rejection::PlanInvalid(_))
    ));
    // Too large, checked before parsing; truncated; not a signed plan at all.
    let small = PlanGate {
        max_signed_bytes: 100,
        ..g.clone()
    };
    assert!(matches!(
        small.check(&signed, 0, 1_500),
        Err(Rejection::TooLarge { .. })
    ));
    assert!(matches!(
        g.check(&signed[..40], 0, 1_500),
        Err(Rejection::Malformed(_))
    ));
    assert!(matches!(
        g.check(b"{\"plan\": 1}", 0, 1_500),
        Err(Rejection::Malformed(_))
    ));
    // A document that is not a plan is not signed.
    assert!(matches!(
        sign_plan(&key, b"{}", envelope("rover", 1)),
        Err(Rejection::PlanInvalid(_))
    ));
}

#[test]
fn plans_travel_as_columns_and_other_json_as_compressed_text() {
    let key = test_key(4);
    // The canonical document: columns, rebuilt byte for byte.
    let json = plan_json();
    let signed = sign_plan(&key, &json, envelope("rover", 5)).unwrap();
    let env = twindrive_link::envelope::peek_envelope(&signed).unwrap();
    assert_eq!(
        env.plan_encoding,
        twindrive_link::envelope::ENCODING_COLUMNS
    );
    let packed = twindrive_link::plan_codec::encode(&json).unwrap();
    assert_eq!(
        twindrive_link::plan_codec::decode(&packed, 1 << 24).unwrap(),
        json
    );
    assert_eq!(gate(&key).check(&signed, 4, 1_500).unwrap().plan_json, json);
    // The same plan written compactly by another tool: it cannot be
    // rebuilt from columns, so it travels as text, still byte for byte.
    let plan: serde_json::Value = serde_json::from_slice(&json).unwrap();
    let compact = serde_json::to_vec(&plan).unwrap();
    assert!(twindrive_link::plan_codec::encode(&compact).is_none());
    let signed = sign_plan(&key, &compact, envelope("rover", 6)).unwrap();
    let env = twindrive_link::envelope::peek_envelope(&signed).unwrap();
    assert_eq!(env.plan_encoding, twindrive_link::envelope::ENCODING_JSON);
    assert_eq!(
        gate(&key).check(&signed, 4, 1_500).unwrap().plan_json,
        compact
    );
    // Truncated or garbled columns are an error, not a panic.
    for cut in [0, 8, 16, packed.len() / 2, packed.len() - 1] {
        assert!(twindrive_link::plan_codec::decode(&packed[..cut], 1 << 24).is_err());
    }
    assert!(twindrive_link::plan_codec::decode(&packed, 10).is_err());
}
