//! Covariance arithmetic specialised to the structure of the augmented model.
//!
//! Covariances are nalgebra [`Mat6`]s, which store columns contiguously. The
//! kernels here work on those columns as plain `[f64; 6]` arrays with
//! column-times-scalar updates, which the compiler maps onto SIMD lanes, and
//! they skip every product that the structure makes trivial:
//!
//! - a step Jacobian is `[[A, B], [0, I]]` with
//!   `A = [[1, 0, a], [0, 1, b], [0, 0, 1]]` ([`Transition`]);
//! - measurements observe the pose directly, `H = [I_M 0]`;
//! - measurement and wheel noise are diagonal.
//!
//! Unit tests compare every kernel with the dense textbook formula.

use std::ops::Index;

use twindrive_kinematics::{Mat6, StateVec, Transition};
use wide::{f64x2, f64x4};

/// One column of a 6x6 matrix.
pub(crate) type Col = [f64; 6];

/// `a * b + c`, fused where the target has an FMA unit (one rounding; the
/// software fallback would be slow, so other targets round twice).
#[inline(always)]
pub(crate) fn fma(a: f64, b: f64, c: f64) -> f64 {
    #[cfg(target_feature = "fma")]
    {
        a.mul_add(b, c)
    }
    #[cfg(not(target_feature = "fma"))]
    {
        a * b + c
    }
}

/// A column in SIMD registers (4 + 2 lanes). Explicit vectors keep the
/// compiler from vectorising across columns instead, with gathers.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lanes {
    lo: f64x4,
    hi: f64x2,
}

impl Lanes {
    pub(crate) const ZERO: Lanes = Lanes {
        lo: f64x4::ZERO,
        hi: f64x2::ZERO,
    };

    #[inline(always)]
    pub(crate) fn load(c: &Col) -> Self {
        Self {
            lo: f64x4::new([c[0], c[1], c[2], c[3]]),
            hi: f64x2::new([c[4], c[5]]),
        }
    }

    #[inline(always)]
    pub(crate) fn store(self, c: &mut Col) {
        c[..4].copy_from_slice(&self.lo.to_array());
        c[4..].copy_from_slice(&self.hi.to_array());
    }

    #[inline(always)]
    pub(crate) fn to_col(self) -> Col {
        let mut c = [0.0; 6];
        self.store(&mut c);
        c
    }

    /// `self += s x`.
    #[inline(always)]
    pub(crate) fn axpy(&mut self, s: f64, x: &Lanes) {
        self.lo = x.lo.mul_add(f64x4::splat(s), self.lo);
        self.hi = x.hi.mul_add(f64x2::splat(s), self.hi);
    }

    #[inline(always)]
    pub(crate) fn scale(&mut self, s: f64) {
        self.lo *= f64x4::splat(s);
        self.hi *= f64x2::splat(s);
    }

    /// `s self − x`.
    #[inline(always)]
    fn scaled_minus(&self, s: f64, x: &Lanes) -> Lanes {
        Lanes {
            lo: self.lo.mul_sub(f64x4::splat(s), x.lo),
            hi: self.hi.mul_sub(f64x2::splat(s), x.hi),
        }
    }
}

/// Loads all six columns.
#[inline(always)]
pub(crate) fn load_all(c: &[Col; 6]) -> [Lanes; 6] {
    [
        Lanes::load(&c[0]),
        Lanes::load(&c[1]),
        Lanes::load(&c[2]),
        Lanes::load(&c[3]),
        Lanes::load(&c[4]),
        Lanes::load(&c[5]),
    ]
}

/// Copies the lower triangle onto the upper one (`c` holds columns).
/// Written out: a loop here gets vectorised into scatters.
#[inline(always)]
pub(crate) fn mirror_lower(c: &mut [Col; 6]) {
    c[1][0] = c[0][1];
    c[2][0] = c[0][2];
    c[3][0] = c[0][3];
    c[4][0] = c[0][4];
    c[5][0] = c[0][5];
    c[2][1] = c[1][2];
    c[3][1] = c[1][3];
    c[4][1] = c[1][4];
    c[5][1] = c[1][5];
    c[3][2] = c[2][3];
    c[4][2] = c[2][4];
    c[5][2] = c[2][5];
    c[4][3] = c[3][4];
    c[5][3] = c[3][5];
    c[5][4] = c[4][5];
}

/// The Jacobian of a chain followed by `next`: `F_next · F_first` (both
/// [`Transition`]s, the product one too).
#[inline]
pub fn chain(first: &Transition, next: &Transition) -> Transition {
    // [[An, Bn], [0, I]] [[As, Bs], [0, I]] = [[An As, An Bs + Bn], [0, I]];
    // the heading couplings of An As add up.
    let (s, n) = (&first.params, &next.params);
    let row = |i: usize, coupling: f64| -> [f64; 3] {
        std::array::from_fn(|k| fma(coupling, s[2][k], s[i][k]) + n[i][k])
    };
    Transition {
        heading_to_x: first.heading_to_x + next.heading_to_x,
        heading_to_y: first.heading_to_y + next.heading_to_y,
        params: [
            row(0, next.heading_to_x),
            row(1, next.heading_to_y),
            row(2, 0.0),
        ],
    }
}

/// Pose row `i` of `F` applied to the column `v`: `(F v)_i`.
#[inline(always)]
fn pose_row_times(f: &Transition, i: usize, v: &Col) -> f64 {
    let coupling = [f.heading_to_x, f.heading_to_y, 0.0][i];
    let b = &f.params[i];
    let mut acc = fma(coupling, v[2], v[i]);
    acc = fma(b[0], v[3], acc);
    acc = fma(b[1], v[4], acc);
    fma(b[2], v[5], acc)
}

/// Columns 0..3 of `P Fᵀ`; for symmetric `P` these are also the pose rows
/// of `F P`. Columns 3..6 of `P Fᵀ` are those of `P`.
#[inline(always)]
pub(crate) fn pose_columns_of_p_ft(c: &[Lanes; 6], f: &Transition) -> [Lanes; 3] {
    let mut w = [c[0], c[1], c[2]];
    w[0].axpy(f.heading_to_x, &c[2]);
    w[1].axpy(f.heading_to_y, &c[2]);
    for (wi, b) in w.iter_mut().zip(&f.params) {
        wi.axpy(b[0], &c[3]);
        wi.axpy(b[1], &c[4]);
        wi.axpy(b[2], &c[5]);
    }
    w
}

/// `P ← F P Fᵀ` for symmetric `P`; the result is exactly symmetric.
#[inline]
pub(crate) fn propagate(p: &mut Mat6, f: &Transition) {
    let c = &mut p.data.0;
    let w = pose_columns_of_p_ft(&load_all(c), f).map(Lanes::to_col);
    // With W = P Fᵀ, F P Fᵀ = F W. Rows 3..6 of F are [0 I], so the
    // parameter rows of F W are those of W; by symmetry its pose-parameter
    // block is Wᵀ's; only the pose block needs the pose rows of F.
    let row = |i: usize, j: usize| pose_row_times(f, i, &w[j]);
    let (b00, b10, b20) = (row(0, 0), row(1, 0), row(2, 0));
    let (b11, b21, b22) = (row(1, 1), row(2, 1), row(2, 2));
    let block = [[b00, b10, b20], [b10, b11, b21], [b20, b21, b22]];
    for j in 0..3 {
        c[j][..3].copy_from_slice(&block[j]);
        c[j][3..].copy_from_slice(&w[j][3..]);
    }
    for j in 3..6 {
        c[j][0] = w[0][j];
        c[j][1] = w[1][j];
        c[j][2] = w[2][j];
    }
}

/// `P += G diag(q) Gᵀ` where only the pose rows of `G` (`wheels`) are non-zero.
#[inline]
pub(crate) fn add_wheel_noise(p: &mut Mat6, wheels: &[[f64; 2]; 3], q: [f64; 2]) {
    let c = &mut p.data.0;
    for j in 0..3 {
        let gj = [wheels[j][0] * q[0], wheels[j][1] * q[1]];
        for i in j..3 {
            let v = fma(wheels[i][0], gj[0], wheels[i][1] * gj[1]);
            c[j][i] += v;
            if i != j {
                c[i][j] += v;
            }
        }
    }
}

/// The inverse of the symmetric innovation covariance `S` (its leading
/// `m` x `m` block, `m` = 2 or 3), or `None` if `S` is not positive-definite
/// (Sylvester's criterion on the leading minors; also rejects NaN).
#[inline]
pub(crate) fn symmetric_inverse(s: &[[f64; 3]; 3], m: usize) -> Option<[[f64; 3]; 3]> {
    let minor2 = s[0][0] * s[1][1] - s[0][1] * s[0][1];
    if !(s[0][0] > 0.0 && minor2 > 0.0) {
        return None;
    }
    if m == 2 {
        let inv_det = 1.0 / minor2;
        let off = -s[0][1] * inv_det;
        return Some([
            [s[1][1] * inv_det, off, 0.0],
            [off, s[0][0] * inv_det, 0.0],
            [0.0; 3],
        ]);
    }
    let c00 = s[1][1] * s[2][2] - s[1][2] * s[1][2];
    let c01 = s[0][2] * s[1][2] - s[0][1] * s[2][2];
    let c02 = s[0][1] * s[1][2] - s[0][2] * s[1][1];
    let det = s[0][0] * c00 + s[0][1] * c01 + s[0][2] * c02;
    // `> 0` is false for NaN too.
    if det.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let inv_det = 1.0 / det;
    let c11 = (s[0][0] * s[2][2] - s[0][2] * s[0][2]) * inv_det;
    let c12 = (s[0][1] * s[0][2] - s[0][0] * s[1][2]) * inv_det;
    let (c00, c01, c02) = (c00 * inv_det, c01 * inv_det, c02 * inv_det);
    Some([
        [c00, c01, c02],
        [c01, c11, c12],
        [c02, c12, minor2 * inv_det],
    ])
}

/// The Kalman gain `K = P Hᵀ S⁻¹` (its `M` columns) for `H = [I_M 0]`.
#[inline]
pub(crate) fn gain<const M: usize>(p: &Mat6, s_inv: &[[f64; 3]; 3]) -> [Col; M] {
    // Plain loops: `array::from_fn` and iterator adaptors were not inlined here.
    let c = &p.data.0;
    let mut out = [[0.0; 6]; M];
    for (m, km) in out.iter_mut().enumerate() {
        let mut k = Lanes::load(&c[0]);
        k.scale(s_inv[0][m]);
        for n in 1..M {
            k.axpy(s_inv[n][m], &Lanes::load(&c[n]));
        }
        k.store(km);
    }
    out
}

/// The Joseph form `(I − K H) P (I − K H)ᵀ + K R Kᵀ` with `H = [I_M 0]` and
/// `R = diag(r)`, in place; exactly symmetric. Valid for any gain `K`.
#[inline]
pub(crate) fn joseph_update<const M: usize>(p: &mut Mat6, k: &[Col; M], r: &[f64; M]) {
    let c = &mut p.data.0;
    let mut kl = [Lanes::ZERO; M];
    for (klm, km) in kl.iter_mut().zip(k) {
        *klm = Lanes::load(km);
    }
    // X = (I − K H) P: column j is P[:, j] − Σ_m K[:, m] P[m, j].
    let mut x = load_all(c);
    for (xj, cj) in x.iter_mut().zip(c.iter()) {
        for (km, pmj) in kl.iter().zip(cj) {
            xj.axpy(-pmj, km);
        }
    }
    // X (I − K H)ᵀ + K R Kᵀ = X + D Kᵀ with D[:, m] = r_m K[:, m] − X[:, m].
    let mut d = [Lanes::ZERO; M];
    for m in 0..M {
        d[m] = kl[m].scaled_minus(r[m], &x[m]);
    }
    for (j, (cj, xj)) in c.iter_mut().zip(&x).enumerate() {
        let mut col = *xj;
        for (dm, km) in d.iter().zip(k) {
            col.axpy(km[j], dm);
        }
        col.store(cj);
    }
    mirror_lower(c);
}

/// A symmetric 6x6 covariance kept as its lower triangle (21 numbers, column
/// by column): long filter histories take 40 % less memory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PackedCovariance([f64; 21]);

/// Start of column `j` of the packed lower triangle.
const COLUMN_START: [usize; 6] = [0, 6, 11, 15, 18, 20];

impl PackedCovariance {
    /// Packs the lower triangle of `p` (assumed symmetric).
    #[inline]
    pub fn pack(p: &Mat6) -> Self {
        let c = &p.data.0;
        #[rustfmt::skip]
        let packed = [
            c[0][0], c[0][1], c[0][2], c[0][3], c[0][4], c[0][5],
            c[1][1], c[1][2], c[1][3], c[1][4], c[1][5],
            c[2][2], c[2][3], c[2][4], c[2][5],
            c[3][3], c[3][4], c[3][5],
            c[4][4], c[4][5],
            c[5][5],
        ];
        Self(packed)
    }

    #[inline]
    pub fn unpack(&self) -> Mat6 {
        let v = &self.0;
        #[rustfmt::skip]
        let columns = [
            [v[0], v[1], v[2], v[3], v[4], v[5]],
            [v[1], v[6], v[7], v[8], v[9], v[10]],
            [v[2], v[7], v[11], v[12], v[13], v[14]],
            [v[3], v[8], v[12], v[15], v[16], v[17]],
            [v[4], v[9], v[13], v[16], v[18], v[19]],
            [v[5], v[10], v[14], v[17], v[19], v[20]],
        ];
        Mat6::from_data(nalgebra::ArrayStorage(columns))
    }
}

impl Index<(usize, usize)> for PackedCovariance {
    type Output = f64;

    fn index(&self, (i, j): (usize, usize)) -> &f64 {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        assert!(i < 6, "index ({i}, {j}) out of a 6x6 matrix");
        &self.0[COLUMN_START[j] + i - j]
    }
}

/// The estimate: mean and covariance (the filter's contract).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateAndCovariance {
    pub state: StateVec,
    pub covariance: Mat6,
}

/// A state with its packed covariance (filter histories, smoothed tracks).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PackedEstimate {
    pub state: StateVec,
    pub covariance: PackedCovariance,
}

impl PackedEstimate {
    pub fn pack(e: &StateAndCovariance) -> Self {
        Self {
            state: e.state,
            covariance: PackedCovariance::pack(&e.covariance),
        }
    }

    pub fn unpack(&self) -> StateAndCovariance {
        StateAndCovariance {
            state: self.state,
            covariance: self.covariance.unpack(),
        }
    }

    /// Standard deviation of state component `i`.
    pub fn std(&self, i: usize) -> f64 {
        self.covariance[(i, i)].max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SMatrix;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use twindrive_kinematics::{StepJacobian, step_with_jacobian};

    fn random_spd(rng: &mut ChaCha8Rng) -> Mat6 {
        let m = Mat6::from_fn(|_, _| rng.random_range(-1.0..1.0));
        let p = m * m.transpose() + Mat6::identity() * 0.1;
        (p + p.transpose()) * 0.5
    }

    fn random_step(rng: &mut ChaCha8Rng) -> StepJacobian {
        let state = StateVec::new(0.3, -1.0, rng.random_range(-3.0..3.0), 0.065, 0.066, 0.27);
        step_with_jacobian(
            &state,
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .1
    }

    fn dense_h<const M: usize>() -> SMatrix<f64, M, 6> {
        SMatrix::<f64, M, 6>::from_fn(|i, j| if i == j { 1.0 } else { 0.0 })
    }

    fn assert_symmetric(p: &Mat6) {
        assert_eq!(*p, p.transpose(), "exactly symmetric");
    }

    #[test]
    fn propagation_and_noise_match_the_dense_formulas() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..300 {
            let p = random_spd(&mut rng);
            let j = random_step(&mut rng);
            let f = j.state_matrix();
            let mut fast = p;
            propagate(&mut fast, &j.state);
            assert!((fast - f * p * f.transpose()).abs().max() < 1e-12);
            assert_symmetric(&fast);

            let mut noisy = p;
            add_wheel_noise(&mut noisy, &j.wheels, [0.3, 0.7]);
            let g = j.wheel_matrix();
            let q = nalgebra::Matrix2::new(0.3, 0.0, 0.0, 0.7);
            assert!((noisy - (p + g * q * g.transpose())).abs().max() < 1e-12);
            assert_symmetric(&noisy);
        }
    }

    #[test]
    fn chained_transitions_are_matrix_products() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut chained = Transition::IDENTITY;
        let mut dense = Mat6::identity();
        for _ in 0..20 {
            let step = random_step(&mut rng).state;
            chained = chain(&chained, &step);
            dense = step.state_matrix() * dense;
            assert!((chained.state_matrix() - dense).abs().max() < 1e-12);
        }
    }

    fn check_update<const M: usize>(rng: &mut ChaCha8Rng) {
        let p = random_spd(rng);
        let r: [f64; M] = std::array::from_fn(|_| rng.random_range(0.01..0.5));
        let r_dense = SMatrix::<f64, M, M>::from_fn(|i, j| if i == j { r[i] } else { 0.0 });
        let h = dense_h::<M>();
        let s_dense = h * p * h.transpose() + r_dense;
        let mut s = [[0.0; 3]; 3];
        for i in 0..M {
            for j in 0..M {
                s[i][j] = s_dense[(i, j)];
            }
        }
        let s_inv = symmetric_inverse(&s, M).expect("S is positive-definite");
        let s_inv_dense = s_dense.try_inverse().unwrap();
        for i in 0..M {
            for j in 0..M {
                assert!((s_inv[i][j] - s_inv_dense[(i, j)]).abs() < 1e-10);
            }
        }
        let k = gain::<M>(&p, &s_inv);
        let k_dense = p * h.transpose() * s_inv_dense;
        for m in 0..M {
            for i in 0..6 {
                assert!((k[m][i] - k_dense[(i, m)]).abs() < 1e-10);
            }
        }
        // Joseph form with an arbitrary (sub-optimal) gain.
        let k_any: [Col; M] =
            std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)));
        let k_any_dense = SMatrix::<f64, 6, M>::from_fn(|i, m| k_any[m][i]);
        let a = Mat6::identity() - k_any_dense * h;
        let expected = a * p * a.transpose() + k_any_dense * r_dense * k_any_dense.transpose();
        let mut fast = p;
        joseph_update(&mut fast, &k_any, &r);
        assert!((fast - expected).abs().max() < 1e-12);
        assert_symmetric(&fast);
    }

    #[test]
    fn updates_match_the_dense_formulas() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..300 {
            check_update::<2>(&mut rng);
            check_update::<3>(&mut rng);
        }
    }

    #[test]
    fn indefinite_innovation_covariances_have_no_inverse() {
        let s = [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(symmetric_inverse(&s, 2).is_none());
        assert!(symmetric_inverse(&s, 3).is_none());
        let s = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]];
        assert!(symmetric_inverse(&s, 2).is_some());
        assert!(symmetric_inverse(&s, 3).is_none());
        let s = [[f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(symmetric_inverse(&s, 3).is_none());
    }

    /// Which multiply-add the kernels compute is decided when they are
    /// compiled: fused (one rounding) where the target has FMA, which
    /// `-C target-cpu=native` (`.cargo/config.toml`) turns on for a CPU that
    /// has it, unfused (two roundings) otherwise. So the last bits of a
    /// filter's result depend on the CPU the build was made for.
    #[test]
    fn multiply_adds_are_fused_exactly_when_the_target_has_fma() {
        use std::hint::black_box;
        // (1 + 2^-30)(1 - 2^-30) = 1 - 2^-60 exactly, which rounds to 1.
        let e = 2f64.powi(-30);
        let (a, b, c) = (black_box(1.0 + e), black_box(1.0 - e), black_box(-1.0));
        let fused = -(e * e);
        let unfused = 0.0;
        assert_eq!(a.mul_add(b, c), fused);
        assert_eq!(a * b + c, unfused);

        let scalar = if cfg!(target_feature = "fma") {
            fused
        } else {
            unfused
        };
        assert_eq!(fma(a, b, c).to_bits(), scalar.to_bits());

        // The SIMD column updates go through `wide`, which also fuses with
        // NEON on aarch64 (where Rust has no `fma` target feature).
        let simd = if cfg!(any(
            target_feature = "fma",
            all(target_arch = "aarch64", target_feature = "neon")
        )) {
            fused
        } else {
            unfused
        };
        let mut column = Lanes::load(&[c; 6]);
        column.axpy(b, &Lanes::load(&[a; 6]));
        for v in column.to_col() {
            assert_eq!(v.to_bits(), simd.to_bits());
        }
    }

    #[test]
    fn packing_round_trips_and_indexes_symmetrically() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let p = random_spd(&mut rng);
        let packed = PackedCovariance::pack(&p);
        assert_eq!(packed.unpack(), p);
        for i in 0..6 {
            for j in 0..6 {
                assert_eq!(packed[(i, j)], p[(i, j)]);
            }
        }
    }
}
