//! The relations metric of Kümmerle et al., "On measuring the accuracy of
//! SLAM algorithms", Autonomous Robots 27(4), 2009: the 2D SLAM
//! benchmark's error of a trajectory against hand-verified relative poses.
//!
//! A relations file holds one `t1 t2 x y z roll pitch yaw` per line: the
//! pose at time `t2` seen from the pose at `t1` (m, rad; z, roll and pitch
//! are 0 in 2D). Each relation's error is the estimate's relative pose
//! `T(t1)⁻¹ T(t2)` minus the relation, component by component: the
//! translational error `sqrt(dx² + dy²)` (m) and the rotational error
//! `|wrap(dθ)|` (reported in degrees), and their squares. Over the
//! relations: mean, standard deviation (the sample's, divided by n - 1: the
//! figures the benchmark folder's own evaluator printed for the raw
//! odometry are reproduced with it, and not with the population's) and
//! maximum. A relation counts only when the trajectory has a pose
//! within [`MATCH_TOLERANCE_S`] of both of its stamps.

use serde::Serialize;
use twindrive_kinematics::wrap_angle;

use crate::se2::between;

/// How far a trajectory's stamp may be from a relation's and still be the
/// pose at that stamp (s). The benchmark's stamps are the scans' own, to
/// the microsecond.
pub const MATCH_TOLERANCE_S: f64 = 1e-3;

/// One relation: the pose at `t2_s` in the frame of the pose at `t1_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Relation {
    pub t1_s: f64,
    pub t2_s: f64,
    /// `[x_m, y_m, yaw_rad]`.
    pub delta: [f64; 3],
}

/// A relations file that does not parse: the line (1-based) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct RelationsError {
    pub line: usize,
    pub message: String,
}

/// Parses a relations file's text. Empty lines and `#` comments are
/// skipped; every other line is eight finite numbers.
pub fn parse_relations(text: &str) -> Result<Vec<Relation>, RelationsError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let body = line.trim();
        if body.is_empty() || body.starts_with('#') {
            continue;
        }
        let bad = |message: String| RelationsError {
            line: i + 1,
            message,
        };
        const NAMES: [&str; 8] = ["t1", "t2", "x", "y", "z", "roll", "pitch", "yaw"];
        let words: Vec<&str> = body.split_ascii_whitespace().collect();
        if words.len() != NAMES.len() {
            return Err(bad(format!(
                "expected 8 numbers `t1 t2 x y z roll pitch yaw`, found {}",
                words.len()
            )));
        }
        let mut v = [0.0; 8];
        for ((slot, word), name) in v.iter_mut().zip(&words).zip(NAMES) {
            *slot = word
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(format!("`{name}`: `{word}` is not a finite number")))?;
        }
        out.push(Relation {
            t1_s: v[0],
            t2_s: v[1],
            delta: [v[2], v[3], v[7]],
        });
    }
    Ok(out)
}

/// Mean, standard deviation (sample, n - 1; 0 for one value) and maximum
/// of one error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
    pub max: f64,
}

impl Stat {
    fn of(values: &[f64]) -> Self {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = if values.len() > 1 {
            values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        Self {
            mean,
            std: var.sqrt(),
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        }
    }
}

/// The four errors over the matched relations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RelationErrors {
    pub abs_trans_m: Stat,
    pub sq_trans_m2: Stat,
    pub abs_rot_deg: Stat,
    pub sq_rot_deg2: Stat,
}

/// A trajectory's score on a set of relations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RelationsScore {
    pub relations: usize,
    /// Relations whose two stamps both have a pose.
    pub matched: usize,
    /// `None` when no relation matched.
    pub errors: Option<RelationErrors>,
}

/// The pose of `trajectory` (sorted by time) nearest `t_s`, if within
/// [`MATCH_TOLERANCE_S`].
fn pose_at(trajectory: &[(f64, [f64; 3])], t_s: f64) -> Option<[f64; 3]> {
    let k = trajectory.partition_point(|(t, _)| *t < t_s);
    [k.checked_sub(1), Some(k)]
        .into_iter()
        .flatten()
        .filter_map(|i| trajectory.get(i))
        .map(|(t, p)| ((t - t_s).abs(), *p))
        .filter(|(dt, _)| *dt <= MATCH_TOLERANCE_S)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, p)| p)
}

/// The error of one relation against the trajectory, `[dx, dy, dθ]`
/// (m, m, rad, dθ wrapped), when both its stamps have a pose.
pub fn relation_error(trajectory: &[(f64, [f64; 3])], r: &Relation) -> Option<[f64; 3]> {
    let a = pose_at(trajectory, r.t1_s)?;
    let b = pose_at(trajectory, r.t2_s)?;
    let est = between(a, b);
    Some([
        est[0] - r.delta[0],
        est[1] - r.delta[1],
        wrap_angle(est[2] - r.delta[2]),
    ])
}

/// Scores `trajectory` (`(t_s, [x_m, y_m, heading_rad])`, sorted by time)
/// on `relations`.
pub fn score(relations: &[Relation], trajectory: &[(f64, [f64; 3])]) -> RelationsScore {
    let errors: Vec<[f64; 3]> = relations
        .iter()
        .filter_map(|r| relation_error(trajectory, r))
        .collect();
    let pick = |f: &dyn Fn(&[f64; 3]) -> f64| -> Vec<f64> { errors.iter().map(f).collect() };
    RelationsScore {
        relations: relations.len(),
        matched: errors.len(),
        errors: (!errors.is_empty()).then(|| RelationErrors {
            abs_trans_m: Stat::of(&pick(&|e| e[0].hypot(e[1]))),
            sq_trans_m2: Stat::of(&pick(&|e| e[0] * e[0] + e[1] * e[1])),
            abs_rot_deg: Stat::of(&pick(&|e| e[2].abs().to_degrees())),
            sq_rot_deg2: Stat::of(&pick(&|e| e[2].to_degrees().powi(2))),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se2::compose;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random walk of `n` poses 0.1 s apart, and relations between
    /// random pairs of them, exact.
    fn random_case(seed: u64, n: usize) -> (Vec<(f64, [f64; 3])>, Vec<Relation>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut pose = [
            rng.random_range(-50.0..50.0),
            rng.random_range(-50.0..50.0),
            0.0,
        ];
        let mut track = Vec::new();
        for k in 0..n {
            track.push((1000.0 + 0.1 * k as f64 + rng.random_range(0.0..1e-4), pose));
            let step = [
                rng.random_range(-0.2..0.5),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.5..0.5),
            ];
            pose = compose(pose, step);
        }
        let relations = (0..3 * n)
            .map(|_| {
                let i = rng.random_range(0..n);
                let j = rng.random_range(0..n);
                Relation {
                    t1_s: track[i].0,
                    t2_s: track[j].0,
                    delta: between(track[i].1, track[j].1),
                }
            })
            .collect();
        (track, relations)
    }

    #[test]
    fn a_perfect_trajectory_scores_zero_in_any_frame() {
        for seed in 0..20 {
            let (track, relations) = random_case(seed, 200);
            // The same trajectory moved rigidly: relative poses unchanged.
            let frame = [3.0, -7.0, 2.5];
            let moved: Vec<_> = track
                .iter()
                .map(|(t, p)| (*t, compose(frame, *p)))
                .collect();
            let s = score(&relations, &moved);
            assert_eq!((s.relations, s.matched), (600, 600), "seed {seed}");
            let e = s.errors.unwrap();
            for stat in [e.abs_trans_m, e.sq_trans_m2, e.abs_rot_deg, e.sq_rot_deg2] {
                assert!(stat.mean < 1e-9 && stat.max < 1e-9, "seed {seed}: {e:?}");
            }
        }
    }

    #[test]
    fn a_known_perturbation_scores_what_it_should() {
        for seed in 0..20 {
            let (track, _) = random_case(seed, 100);
            // Every relation says the second pose is 0.3 m ahead and 2°
            // left of where the trajectory has it: each error is then
            // exactly (-0.3, 0, -2°) in the first pose's frame.
            let offset = [0.3, 0.0, 2f64.to_radians()];
            let relations: Vec<Relation> = track
                .windows(2)
                .map(|w| Relation {
                    t1_s: w[0].0,
                    t2_s: w[1].0,
                    delta: {
                        let d = between(w[0].1, w[1].1);
                        [d[0] + offset[0], d[1] + offset[1], d[2] + offset[2]]
                    },
                })
                .collect();
            let e = score(&relations, &track).errors.unwrap();
            let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
            assert!(
                close(e.abs_trans_m.mean, 0.3) && close(e.abs_trans_m.std, 0.0),
                "seed {seed}: {e:?}"
            );
            assert!(close(e.sq_trans_m2.mean, 0.09), "seed {seed}: {e:?}");
            assert!(
                close(e.abs_rot_deg.mean, 2.0) && close(e.sq_rot_deg2.mean, 4.0),
                "seed {seed}: {e:?}"
            );
        }
    }

    #[test]
    fn the_deviation_is_the_samples() {
        let track = vec![(0.0, [0.0, 0.0, 0.0]), (1.0, [0.0, 0.0, 0.0])];
        // Errors of 1 m and 3 m: mean 2, sample deviation √2.
        let relations = [1.0, 3.0].map(|x| Relation {
            t1_s: 0.0,
            t2_s: 1.0,
            delta: [x, 0.0, 0.0],
        });
        let e = score(&relations, &track).errors.unwrap();
        assert_eq!(e.abs_trans_m.mean, 2.0);
        assert!((e.abs_trans_m.std - 2f64.sqrt()).abs() < 1e-15);
        assert_eq!(e.abs_trans_m.max, 3.0);
        assert_eq!(e.sq_trans_m2.mean, 5.0);
    }

    #[test]
    fn a_stamp_without_a_pose_within_a_millisecond_is_not_counted() {
        let (track, relations) = random_case(7, 50);
        let perfect = score(&relations, &track);
        assert_eq!(perfect.matched, relations.len());
        // One relation's stamp 1.5 ms off any pose, one 0.9 ms off; a
        // wildly wrong relation on a stamp the trajectory lacks.
        let mut more = relations.clone();
        more.push(Relation {
            t1_s: track[3].0 + 1.5e-3,
            ..relations[0]
        });
        more.push(Relation {
            t1_s: track[4].0,
            t2_s: 5000.0,
            delta: [100.0, 0.0, 3.0],
        });
        let near = Relation {
            t1_s: track[5].0 + 0.9e-3,
            t2_s: track[6].0,
            delta: between(track[5].1, track[6].1),
        };
        more.push(near);
        let s = score(&more, &track);
        assert_eq!(
            (s.relations, s.matched),
            (relations.len() + 3, relations.len() + 1)
        );
        assert!(s.errors.unwrap().abs_trans_m.max < 1e-9);
        assert!(
            score(&more[relations.len()..relations.len() + 2], &track)
                .errors
                .is_none()
        );
    }

    #[test]
    fn rotational_error_wraps() {
        let track = vec![(0.0, [0.0, 0.0, 3.1]), (1.0, [0.0, 0.0, -3.1])];
        // Estimated turn: -6.2 rad ≡ +0.083 rad; the relation says +0.083.
        let turn = wrap_angle(-6.2);
        let r = Relation {
            t1_s: 0.0,
            t2_s: 1.0,
            delta: [0.0, 0.0, turn + 0.01],
        };
        let e = score(&[r], &track).errors.unwrap();
        assert!(
            (e.abs_rot_deg.mean - 0.01f64.to_degrees()).abs() < 1e-9,
            "{e:?}"
        );
    }

    #[test]
    fn parse_errors_name_the_line() {
        let ok = "# t1 t2 x y z roll pitch yaw\n\n1.5 2.5 0.1 -0.2 0 0 -0.000000 0.3\n";
        assert_eq!(
            parse_relations(ok).unwrap(),
            vec![Relation {
                t1_s: 1.5,
                t2_s: 2.5,
                delta: [0.1, -0.2, 0.3]
            }]
        );
        for (text, says) in [
            ("1 2 3\n", "line 1: expected 8 numbers"),
            (
                "# c\n1 2 3 4 0 0 0 x\n",
                "line 2: `yaw`: `x` is not a finite number",
            ),
            ("1 inf 3 4 0 0 0 0\n", "line 1: `t2`: `inf`"),
        ] {
            let err = parse_relations(text).unwrap_err().to_string();
            assert!(err.contains(says), "{err}");
        }
    }
}
