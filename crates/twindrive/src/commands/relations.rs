//! `twindrive relations`: a trajectory's error on the 2D SLAM benchmark's
//! relations (the metric is `twindrive_estimation::relations`).

use anyhow::{Context, bail};
use twindrive_estimation::relations::{self, MATCH_TOLERANCE_S, RelationsScore};

use crate::cli::RelationsArgs;

pub fn run(args: &RelationsArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.relations)
        .with_context(|| format!("--relations: reading {}", args.relations.display()))?;
    let relations = relations::parse_relations(&text)
        .with_context(|| format!("--relations {}", args.relations.display()))?;
    let trajectory: Vec<(f64, [f64; 3])> = twindrive_log::read_tum(&args.trajectory)?
        .into_iter()
        .map(|(t_ns, p)| {
            (
                twindrive_log::seconds_from_ns(t_ns),
                [p.x_m, p.y_m, p.heading_rad],
            )
        })
        .collect();
    let score = relations::score(&relations, &trajectory);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&score)?);
    } else {
        print!("{}", summary(&score));
    }
    if score.errors.is_none() {
        bail!(
            "none of the {} relations in {} has a pose of {} within {} ms of both its stamps \
             (is the trajectory stamped with the scans' own times?)",
            score.relations,
            args.relations.display(),
            args.trajectory.display(),
            MATCH_TOLERANCE_S * 1e3
        );
    }
    Ok(())
}

/// The score as text: the match count and the four errors.
fn summary(score: &RelationsScore) -> String {
    let mut out = format!(
        "relations matched: {} of {} (a pose within {} ms of both stamps)\n",
        score.matched,
        score.relations,
        MATCH_TOLERANCE_S * 1e3
    );
    if let Some(e) = &score.errors {
        for (what, s, unit, digits) in [
            ("absolute translational", e.abs_trans_m, "m", 4),
            ("squared translational", e.sq_trans_m2, "m²", 4),
            ("absolute rotational", e.abs_rot_deg, "deg", 3),
            ("squared rotational", e.sq_rot_deg2, "deg²", 3),
        ] {
            out.push_str(&format!(
                "{what} error: {:.digits$} ± {:.digits$} {unit} (max {:.digits$})\n",
                s.mean, s.std, s.max
            ));
        }
    }
    out
}
