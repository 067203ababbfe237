//! A sparse pose graph in SE(2): poses joined by measured relative poses,
//! solved by Gauss-Newton with Levenberg damping on a sparse Cholesky
//! factorisation (`faer`, AMD-ordered). Edges may carry a Huber loss (loop
//! closures: a wrong one pulls with a bounded force) and may be switched
//! off after a solve when they disagree with the rest.
//!
//! The residual of an edge `i -> j` measuring `z` is the one of Grisetti et
//! al., "A tutorial on graph-based SLAM" (2010), in the REP-103 sense:
//! `e = [Rz^T (Ri^T (tj - ti) - tz); wrap(θj - θi - θz)]`.

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};

use super::se2::{between, wrap};

/// A measured relative pose between two poses of the graph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    pub from: usize,
    pub to: usize,
    /// `to` seen from `from` (x, y in m, heading in rad).
    pub measured: [f64; 3],
    /// Standard deviation of the measurement along x and y (m) and heading
    /// (rad), in `from`'s frame.
    pub std: [f64; 3],
    /// Whitened residual norm beyond which the edge's pull stops growing
    /// (Huber); `None` for a least-squares edge.
    pub huber: Option<f64>,
    /// Whether the edge takes part (a rejected loop closure does not).
    pub active: bool,
}

impl Edge {
    /// The edge's whitened residual at `poses`.
    pub fn residual(&self, poses: &[[f64; 3]]) -> [f64; 3] {
        let e = raw_residual(poses[self.from], poses[self.to], self.measured);
        [e[0] / self.std[0], e[1] / self.std[1], e[2] / self.std[2]]
    }

    /// The norm of the whitened residual (a chi, not a chi-squared).
    pub fn chi(&self, poses: &[[f64; 3]]) -> f64 {
        let r = self.residual(poses);
        (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt()
    }
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solved {
    pub iterations: usize,
    /// Robust cost before and after (half the sum of the edges' losses).
    pub initial_cost: f64,
    pub final_cost: f64,
}

/// Why a solve failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("edge {edge} joins pose {pose}, but the graph has {poses} poses")]
    NoSuchPose {
        edge: usize,
        pose: usize,
        poses: usize,
    },
    #[error("edge {edge}: standard deviations must be positive and finite, got {std:?}")]
    BadStd { edge: usize, std: [f64; 3] },
    #[error("the normal equations could not be factorised ({0})")]
    Factorisation(String),
}

/// Poses and the edges between them; pose 0 is held where it is.
#[derive(Debug, Clone, Default)]
pub struct PoseGraph {
    pub poses: Vec<[f64; 3]>,
    pub edges: Vec<Edge>,
}

impl PoseGraph {
    /// Adds a pose (an initial guess), returning its index.
    pub fn add_pose(&mut self, pose: [f64; 3]) -> usize {
        self.poses.push(pose);
        self.poses.len() - 1
    }

    /// Adds an edge, returning its index.
    pub fn add_edge(&mut self, edge: Edge) -> usize {
        self.edges.push(edge);
        self.edges.len() - 1
    }

    /// The robust cost at the current poses.
    pub fn cost(&self) -> f64 {
        cost_at(&self.edges, &self.poses)
    }

    fn check(&self) -> Result<(), SolveError> {
        let n = self.poses.len();
        for (k, e) in self.edges.iter().enumerate() {
            for pose in [e.from, e.to] {
                if pose >= n {
                    return Err(SolveError::NoSuchPose {
                        edge: k,
                        pose,
                        poses: n,
                    });
                }
            }
            if !e.std.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(SolveError::BadStd {
                    edge: k,
                    std: e.std,
                });
            }
        }
        Ok(())
    }

    /// Levenberg-Marquardt from the current poses, at most `max_iterations`
    /// steps, stopping when a step moves no pose by more than 1e-6 (m and
    /// rad). Pose 0 stays fixed.
    pub fn optimize(&mut self, max_iterations: usize) -> Result<Solved, SolveError> {
        self.check()?;
        let n = self.poses.len();
        let initial_cost = self.cost();
        let mut cost = initial_cost;
        let mut lambda = 1e-6;
        let mut iterations = 0;
        if n < 2 {
            return Ok(Solved {
                iterations,
                initial_cost,
                final_cost: cost,
            });
        }
        let (mut triplets, mut gradient) = (Vec::new(), vec![0.0; 3 * n]);
        while iterations < max_iterations {
            iterations += 1;
            linearise(&self.edges, &self.poses, &mut triplets, &mut gradient);
            let (step, new_poses, new_cost) = loop {
                let step = solve(n, &triplets, &gradient, lambda)?;
                let moved = self
                    .poses
                    .iter()
                    .zip(step.chunks_exact(3))
                    .map(|(p, d)| [p[0] + d[0], p[1] + d[1], wrap(p[2] + d[2])])
                    .collect::<Vec<_>>();
                let c = cost_at(&self.edges, &moved);
                if c <= cost || lambda > 1e6 {
                    break (step, moved, c);
                }
                lambda *= 10.0;
            };
            if new_cost > cost {
                break;
            }
            lambda = (lambda * 0.1).max(1e-9);
            self.poses = new_poses;
            cost = new_cost;
            if step.iter().all(|d| d.abs() < 1e-6) {
                break;
            }
        }
        Ok(Solved {
            iterations,
            initial_cost,
            final_cost: cost,
        })
    }
}

/// `e = [Rz^T (Ri^T (tj - ti) - tz); wrap(θj - θi - θz)]`: `between(i, j)`
/// minus the measurement, in the measurement's frame.
fn raw_residual(i: [f64; 3], j: [f64; 3], z: [f64; 3]) -> [f64; 3] {
    let seen = between(i, j);
    let (sz, cz) = z[2].sin_cos();
    let (dx, dy) = (seen[0] - z[0], seen[1] - z[1]);
    [cz * dx + sz * dy, -sz * dx + cz * dy, wrap(seen[2] - z[2])]
}

/// Huber's weight on a whitened residual of norm `chi`.
fn robust_weight(huber: Option<f64>, chi: f64) -> f64 {
    match huber {
        Some(k) if chi > k => k / chi,
        _ => 1.0,
    }
}

/// Huber's loss (half a squared norm inside, linear outside).
fn robust_loss(huber: Option<f64>, chi: f64) -> f64 {
    match huber {
        Some(k) if chi > k => k * chi - 0.5 * k * k,
        _ => 0.5 * chi * chi,
    }
}

fn cost_at(edges: &[Edge], poses: &[[f64; 3]]) -> f64 {
    edges
        .iter()
        .filter(|e| e.active)
        .map(|e| robust_loss(e.huber, e.chi(poses)))
        .sum()
}

/// The normal equations `H dx = -g` at `poses` (the upper triangle of H
/// as triplets, with pose 0 pinned), iteratively reweighted for the Huber
/// edges.
#[allow(clippy::needless_range_loop)] // 3×3 blocks read clearer by index
fn linearise(
    edges: &[Edge],
    poses: &[[f64; 3]],
    triplets: &mut Vec<Triplet<usize, usize, f64>>,
    gradient: &mut [f64],
) {
    triplets.clear();
    gradient.fill(0.0);
    for e in edges.iter().filter(|e| e.active) {
        let (pi, pj) = (poses[e.from], poses[e.to]);
        let r = raw_residual(pi, pj, e.measured);
        let w = robust_weight(e.huber, e.chi(poses));
        let info = [
            w / (e.std[0] * e.std[0]),
            w / (e.std[1] * e.std[1]),
            w / (e.std[2] * e.std[2]),
        ];
        let (a, b) = jacobians(pi, pj, e.measured);
        let blocks = [(e.from, &a), (e.to, &b)];
        for &(bi, ji) in &blocks {
            // g += J^T Ω r
            for c in 0..3 {
                gradient[3 * bi + c] += (0..3).map(|k| ji[k][c] * info[k] * r[k]).sum::<f64>();
            }
            for &(bj, jj) in &blocks {
                if bj < bi {
                    continue;
                }
                for c in 0..3 {
                    for d in 0..3 {
                        if bi == bj && d < c {
                            continue;
                        }
                        let v: f64 = (0..3).map(|k| ji[k][c] * info[k] * jj[k][d]).sum();
                        if v != 0.0 {
                            triplets.push(Triplet::new(3 * bi + c, 3 * bj + d, v));
                        }
                    }
                }
            }
        }
    }
    // Pose 0 is held: a stiff spring to where it is.
    for c in 0..3 {
        triplets.push(Triplet::new(c, c, 1e12));
        gradient[c] = 0.0;
    }
}

/// `∂e/∂xi` and `∂e/∂xj`, rows of e by columns (x, y, θ).
fn jacobians(i: [f64; 3], j: [f64; 3], z: [f64; 3]) -> ([[f64; 3]; 3], [[f64; 3]; 3]) {
    let (si, ci) = i[2].sin_cos();
    let (sz, cz) = z[2].sin_cos();
    let (dx, dy) = (j[0] - i[0], j[1] - i[1]);
    // Rz^T Ri^T = rotation by -(θi + θz).
    let (s, c) = (si * cz + ci * sz, ci * cz - si * sz);
    let rt = [[c, s], [-s, c]];
    // d(Ri^T)/dθi (tj - ti), then Rz^T of it.
    let dri = [-si * dx + ci * dy, -ci * dx - si * dy];
    let d = [cz * dri[0] + sz * dri[1], -sz * dri[0] + cz * dri[1]];
    let a = [
        [-rt[0][0], -rt[0][1], d[0]],
        [-rt[1][0], -rt[1][1], d[1]],
        [0.0, 0.0, -1.0],
    ];
    let b = [
        [rt[0][0], rt[0][1], 0.0],
        [rt[1][0], rt[1][1], 0.0],
        [0.0, 0.0, 1.0],
    ];
    (a, b)
}

/// Solves `(H + λ diag(H)) dx = -g` (H given by its upper triangle).
fn solve(
    n: usize,
    triplets: &[Triplet<usize, usize, f64>],
    gradient: &[f64],
    lambda: f64,
) -> Result<Vec<f64>, SolveError> {
    let mut diagonal = vec![0.0; 3 * n];
    for t in triplets.iter().filter(|t| t.row == t.col) {
        diagonal[t.row] += t.val;
    }
    let damped: Vec<Triplet<usize, usize, f64>> = triplets
        .iter()
        .copied()
        .chain(
            diagonal
                .iter()
                .enumerate()
                .map(|(k, d)| Triplet::new(k, k, lambda * d.max(1e-9) + 1e-12)),
        )
        .collect();
    let h = SparseColMat::<usize, f64>::try_new_from_triplets(3 * n, 3 * n, &damped)
        .map_err(|e| SolveError::Factorisation(format!("{e:?}")))?;
    let llt = h
        .sp_cholesky(Side::Upper)
        .map_err(|e| SolveError::Factorisation(format!("{e:?}")))?;
    let rhs = Mat::<f64>::from_fn(3 * n, 1, |k, _| -gradient[k]);
    let x = llt.solve(&rhs);
    Ok((0..3 * n).map(|k| x[(k, 0)]).collect())
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    use super::super::se2::compose;
    use super::*;

    fn edge(from: usize, to: usize, measured: [f64; 3], std: [f64; 3]) -> Edge {
        Edge {
            from,
            to,
            measured,
            std,
            huber: None,
            active: true,
        }
    }

    /// A loop of poses around a circle, measured with noise, with drifted
    /// initial guesses: the solve from the drifted guess reaches the same
    /// optimum as a solve from the truth, and the drift is gone.
    #[test]
    fn a_drifted_loop_reaches_the_optimum_a_solve_from_the_truth_reaches() {
        for seed in 0..5 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let n = 40 + (seed as usize) * 10;
            let radius = rng.random_range(2.0..6.0);
            let truth: Vec<[f64; 3]> = (0..n)
                .map(|k| {
                    let a = k as f64 / n as f64 * std::f64::consts::TAU;
                    [
                        radius * a.cos(),
                        radius * a.sin(),
                        wrap(a + std::f64::consts::FRAC_PI_2),
                    ]
                })
                .collect();
            let noise = Normal::new(0.0, 1.0).unwrap();
            let std = [0.01, 0.01, 0.002];
            let mut drifted = PoseGraph::default();
            let mut guess = truth[0];
            drifted.add_pose(guess);
            for k in 1..=n {
                let (a, b) = (k - 1, k % n);
                let z = between(truth[a], truth[b]);
                let z = [
                    z[0] + std[0] * noise.sample(&mut rng),
                    z[1] + std[1] * noise.sample(&mut rng),
                    z[2] + std[2] * noise.sample(&mut rng),
                ];
                if k < n {
                    // The guess drifts: a heading bias per step.
                    guess = compose(guess, [z[0], z[1], z[2] + 0.01]);
                    drifted.add_pose(guess);
                }
                drifted.add_edge(edge(a, b, z, std));
            }
            let mut from_truth = PoseGraph {
                poses: truth.clone(),
                edges: drifted.edges.clone(),
            };
            let worst = |a: &[[f64; 3]], b: &[[f64; 3]]| {
                a.iter()
                    .zip(b)
                    .map(|(p, t)| (p[0] - t[0]).hypot(p[1] - t[1]))
                    .fold(0.0, f64::max)
            };
            assert!(
                worst(&drifted.poses, &truth) > 0.5,
                "seed {seed}: the guess must drift"
            );
            let solved = drifted.optimize(50).unwrap();
            from_truth.optimize(50).unwrap();
            assert!(solved.final_cost < solved.initial_cost);
            assert!(
                (solved.final_cost - from_truth.cost()).abs() <= 1e-6 * from_truth.cost().max(1.0),
                "seed {seed}: cost {} against the optimum's {}",
                solved.final_cost,
                from_truth.cost()
            );
            let apart = worst(&drifted.poses, &from_truth.poses);
            assert!(
                apart < 1e-3,
                "seed {seed}: the two solves end {apart:.2e} m apart"
            );
            // Heading noise of 2 mrad a step over tens of metres.
            assert!(
                worst(&drifted.poses, &truth) < 0.3,
                "seed {seed}: {:.3} m from the truth",
                worst(&drifted.poses, &truth)
            );
        }
    }

    /// A straight chain closed by a true loop edge and a false one: with a
    /// Huber loss the false edge barely moves the chain's end; as least
    /// squares it drags it half way.
    #[test]
    fn a_huber_edge_pulls_less_than_a_least_squares_one() {
        let n = 30;
        let truth: Vec<[f64; 3]> = (0..n).map(|k| [0.2 * k as f64, 0.0, 0.0]).collect();
        let build = |huber| {
            let mut g = PoseGraph::default();
            for p in &truth {
                g.add_pose(*p);
            }
            for k in 1..n {
                g.add_edge(edge(
                    k - 1,
                    k,
                    between(truth[k - 1], truth[k]),
                    [0.01, 0.01, 0.002],
                ));
            }
            let mut right = edge(
                0,
                n - 1,
                between(truth[0], truth[n - 1]),
                [0.02, 0.02, 0.01],
            );
            right.huber = huber;
            g.add_edge(right);
            // A false loop: the last pose "seen" 1 m to the side.
            let mut wrong = edge(
                0,
                n - 1,
                [0.2 * (n - 1) as f64, 1.0, 0.0],
                [0.02, 0.02, 0.01],
            );
            wrong.huber = huber;
            g.add_edge(wrong);
            g
        };
        let mut plain = build(None);
        let mut robust = build(Some(1.0));
        plain.optimize(50).unwrap();
        robust.optimize(50).unwrap();
        let off = |g: &PoseGraph| g.poses[n - 1][1].abs();
        assert!(off(&plain) > 0.3, "least squares moves {:.3}", off(&plain));
        assert!(
            off(&robust) < 0.1,
            "robust {:.3} against plain {:.3}",
            off(&robust),
            off(&plain)
        );
    }

    #[test]
    fn a_bad_edge_is_an_error_not_a_panic() {
        let mut g = PoseGraph::default();
        g.add_pose([0.0; 3]);
        g.add_edge(edge(0, 3, [1.0, 0.0, 0.0], [0.1, 0.1, 0.1]));
        assert!(matches!(g.optimize(5), Err(SolveError::NoSuchPose { .. })));
        let mut g = PoseGraph::default();
        g.add_pose([0.0; 3]);
        g.add_pose([1.0, 0.0, 0.0]);
        g.add_edge(edge(0, 1, [1.0, 0.0, 0.0], [0.0, 0.1, 0.1]));
        assert!(matches!(g.optimize(5), Err(SolveError::BadStd { .. })));
    }

    /// The analytic Jacobians agree with finite differences.
    #[test]
    fn jacobians_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let mut p = || {
                [
                    rng.random_range(-5.0..5.0),
                    rng.random_range(-5.0..5.0),
                    rng.random_range(-3.0..3.0),
                ]
            };
            let (i, j, z) = (p(), p(), p());
            let (a, b) = jacobians(i, j, z);
            let h = 1e-6;
            for c in 0..3 {
                let mut ip = i;
                ip[c] += h;
                let mut jp = j;
                jp[c] += h;
                let (r0, ri, rj) = (
                    raw_residual(i, j, z),
                    raw_residual(ip, j, z),
                    raw_residual(i, jp, z),
                );
                for k in 0..3 {
                    let di = wrap(ri[k] - r0[k]) / h;
                    let dj = wrap(rj[k] - r0[k]) / h;
                    assert!(
                        (di - a[k][c]).abs() < 1e-4,
                        "dA[{k}][{c}] {di} vs {}",
                        a[k][c]
                    );
                    assert!(
                        (dj - b[k][c]).abs() < 1e-4,
                        "dB[{k}][{c}] {dj} vs {}",
                        b[k][c]
                    );
                }
            }
        }
    }
}
