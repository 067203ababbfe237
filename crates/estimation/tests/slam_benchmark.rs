//! The relations metric (`twindrive_estimation::relations`) on the public
//! 2D SLAM benchmark (Kümmerle et al. 2009, `../shared/data/slam2d_benchmark/`,
//! not made by this project): the raw odometry of each CARMEN log (the
//! `ODOM` poses interpolated at the laser stamps; the laser lines' own
//! odometry for MIT CSAIL and the hospital, which have no `ODOM` lines),
//! read with `twindrive_log::carmen`, scores what each folder's
//! `odometry_baseline.json` says (someone else's evaluator). Skips (with a
//! message) if `../shared/data` is absent.

use std::path::{Path, PathBuf};

use twindrive_estimation::relations::{self, Stat};
use twindrive_log::carmen::CarmenLog;

/// (folder, log, relations file)
const SETS: [(&str, &str, &str); 5] = [
    ("aces", "aces.rebuilt.clf.gz", "aces.relations"),
    ("intel", "intel.rebuilt.clf.gz", "intel.relations"),
    ("fr079", "fr079.rebuilt.clf.gz", "fr079.relations"),
    ("mit-csail", "mit-csail.clf.gz", "mit-csail.relations"),
    (
        "fr-hospital",
        "fr-clinic_robotlaser.rebuilt.clf.gz",
        "fr-clinic.relations",
    ),
];

fn data_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/slam2d_benchmark");
    dir.is_dir().then_some(dir)
}

/// The baseline's `(mean, std)` of one error.
fn baseline(json: &serde_json::Value, key: &str) -> (f64, f64) {
    let s = &json["odometry"][key];
    (s["mean"].as_f64().unwrap(), s["std"].as_f64().unwrap())
}

#[test]
fn raw_odometry_scores_the_published_baseline() {
    let Some(dir) = data_dir() else {
        eprintln!("SKIPPED: ../shared/data/slam2d_benchmark is absent");
        return;
    };
    for (folder, log, rel) in SETS {
        let dir = dir.join(folder);
        let log = CarmenLog::read(&dir.join(log)).unwrap();
        let text = std::fs::read_to_string(dir.join(rel)).unwrap();
        let relations = relations::parse_relations(&text).unwrap();
        let track: Vec<(f64, [f64; 3])> = log
            .odometry_at_lasers()
            .into_iter()
            .map(|(t, p)| (t, [p.x_m, p.y_m, p.heading_rad]))
            .collect();
        let score = relations::score(&relations, &track);
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("odometry_baseline.json")).unwrap())
                .unwrap();
        assert_eq!(
            score.relations as u64,
            json["relations"].as_u64().unwrap(),
            "{folder}"
        );
        assert_eq!(
            score.matched as u64,
            json["odometry"]["matched"].as_u64().unwrap(),
            "{folder}"
        );
        let e = score.errors.unwrap();
        for (key, ours) in [
            ("abs_trans_m", e.abs_trans_m),
            ("sq_trans_m2", e.sq_trans_m2),
            ("abs_rot_deg", e.abs_rot_deg),
            ("sq_rot_deg2", e.sq_rot_deg2),
        ] {
            let (mean, std) = baseline(&json, key);
            let Stat {
                mean: m, std: s, ..
            } = ours;
            eprintln!(
                "{folder} {key}: ours {m:.6} ± {s:.6}, baseline {mean:.6} ± {std:.6} (rel. {:.1e}, {:.1e})",
                (m - mean).abs() / mean,
                (s - std).abs() / std
            );
            // The baseline's JSON has every digit: within a part in 10⁹
            // (far inside PUBLISHED.md's printed three or four figures).
            assert!(
                (m - mean).abs() <= 1e-9 * mean && (s - std).abs() <= 1e-9 * std,
                "{folder} {key}: ours {m} ± {s}, the baseline's {mean} ± {std}"
            );
        }
    }
}
