//! `keygen` and `sign` end to end: the key pair on disk, a signed plan that
//! a robot with the public key accepts byte for byte, and bad input.

mod common;

use std::path::Path;

use common::{text, twindrive};
use twindrive_link::envelope::{PlanGate, read_public_key_pem};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn keygen_then_sign_gives_a_plan_the_robot_accepts() {
    let tmp = tempfile::tempdir().unwrap();
    let keys = tmp.path().join("keys");
    let out = twindrive(&["keygen", "--out", s(&keys)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(keys.join("master.key"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600);
    }
    // Never replaces a key.
    let before = std::fs::read(keys.join("master.key")).unwrap();
    let out = twindrive(&["keygen", "--out", s(&keys)]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("never replaces a key"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(std::fs::read(keys.join("master.key")).unwrap(), before);

    // A plan of the case study.
    let log = tmp.path().join("wf");
    let out = twindrive(&[
        "simulate",
        "scenarios/wall_following.toml",
        "--duration-s",
        "20",
        "--out",
        s(&log),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let calib = tmp.path().join("calib.json");
    std::fs::write(
        &calib,
        r#"{"left_diameter_m": 0.0652, "right_diameter_m": 0.0665, "wheelbase_m": 0.2678}"#,
    )
    .unwrap();
    let plan = tmp.path().join("plan/plan.json");
    let out = twindrive(&[
        "plan",
        s(&log),
        "--calibration",
        s(&calib),
        "--out",
        s(&plan),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    let signed = tmp.path().join("plan.signed");
    let out = twindrive(&[
        "sign",
        s(&plan),
        "--key",
        s(&keys.join("master.key")),
        "--robot",
        "rover-1",
        "--counter",
        "7",
        "--supervise",
        "30",
        "--out",
        s(&signed),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let bytes = std::fs::read(&signed).unwrap();
    let public =
        read_public_key_pem(&std::fs::read_to_string(keys.join("master.pub")).unwrap()).unwrap();
    let gate = PlanGate {
        robot_id: "rover-1".into(),
        trusted: vec![public],
        max_signed_bytes: 64 << 20,
        max_plan_bytes: 256 << 20,
    };
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    let accepted = gate.check(&bytes, 6, now).unwrap();
    assert_eq!(accepted.plan_json, std::fs::read(&plan).unwrap());
    assert_eq!(accepted.envelope.counter, 7);
    assert_eq!(accepted.envelope.supervision.dead_man_timeout_s, Some(30.0));
    // The world hash is the built-in scenario's.
    assert_eq!(
        accepted.envelope.world_sha256,
        twindrive_link::envelope::sha256_hex(twindrive_sim::builtin::WALL_FOLLOWING.as_bytes())
    );
    // Expired tomorrow and a day after.
    assert!(gate.check(&bytes, 6, now + 86_400 + 1).is_err());

    // Bad input: no such key, not a key, a file that is not a plan.
    for (key, plan_file, expect) in [
        (tmp.path().join("none.key"), plan.clone(), "none.key"),
        (calib.clone(), plan.clone(), "not an ed25519 private key"),
        (
            keys.join("master.key"),
            calib.clone(),
            "calib.json is not a twindrive mission plan: a JSON document, but not a twindrive mission plan",
        ),
    ] {
        let out = twindrive(&[
            "sign",
            s(&plan_file),
            "--key",
            s(&key),
            "--robot",
            "rover-1",
            "--out",
            s(&tmp.path().join("bad.signed")),
        ]);
        assert!(!out.status.success());
        assert!(text(&out.stderr).contains(expect), "{}", text(&out.stderr));
        assert!(!tmp.path().join("bad.signed").exists());
    }
}

#[test]
fn robot_keys_and_fleet_certificates_are_never_replaced() {
    let tmp = tempfile::tempdir().unwrap();
    let keys = tmp.path().join("keys");
    let out = twindrive(&["keygen", "--out", s(&keys), "--robot", "rover-1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let public = std::fs::read_to_string(keys.join("rover-1.pub")).unwrap();
    assert!(read_public_key_pem(&public).is_ok());
    let before = std::fs::read(keys.join("rover-1.key")).unwrap();
    let out = twindrive(&["keygen", "--out", s(&keys), "--robot", "rover-1"]);
    assert!(!out.status.success());
    assert_eq!(std::fs::read(keys.join("rover-1.key")).unwrap(), before);
    // A robot id that is not one: a usage error.
    let out = twindrive(&["keygen", "--out", s(&keys), "--robot", "a/b"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));

    let certs = tmp.path().join("certs");
    let certs_for = |robots: &[&str]| {
        let mut args = vec!["certs", "--out", s(&certs)];
        for r in robots {
            args.extend(["--robot", r]);
        }
        twindrive(&args)
    };
    let out = certs_for(&["r1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        for key in ["ca.key", "router.key", "master.key", "r1.key"] {
            let mode = std::fs::metadata(certs.join(key))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600, "{key}");
        }
    }
    let key = std::fs::read(certs.join("r1.key")).unwrap();
    let out = certs_for(&["r1", "r2"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("never replaces"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(std::fs::read(certs.join("r1.key")).unwrap(), key);
    // A robot named like a fleet file: refused, nothing written.
    let other = tmp.path().join("other");
    let out = twindrive(&["certs", "--out", s(&other), "--robot", "router"]);
    assert!(!out.status.success());
    assert!(!other.exists());

    // deploy/tls/ holds what `certs --robot r1` writes, byte for byte:
    // the example is the command's own output. TWINDRIVE_BLESS=1 rewrites
    // it. Its files name each other relative to themselves, never by where
    // they were made.
    let deploy = common::repo().join("deploy/tls");
    let absolute = std::path::absolute(&certs).unwrap();
    for name in ["router.json5", "master.json5", "r1.json5"] {
        let made = std::fs::read_to_string(certs.join(name)).unwrap();
        assert!(
            !made.contains(&absolute.display().to_string()),
            "{name} names where it was made"
        );
        let path = deploy.join(name);
        if std::env::var_os("TWINDRIVE_BLESS").is_some() {
            std::fs::create_dir_all(&deploy).unwrap();
            std::fs::write(&path, &made).unwrap();
        }
        assert_eq!(
            std::fs::read_to_string(&path).unwrap_or_default(),
            made,
            "{} is not what `twindrive certs` writes",
            path.display()
        );
    }
}
