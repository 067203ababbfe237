//! Planar rigid motions as `[x, y, heading]` (m, m, rad; REP-103): the
//! composition, inverse and relative pose every estimator here shares.

/// The heading wrapped to (-π, π].
#[inline]
pub fn wrap(a: f64) -> f64 {
    twindrive_kinematics::wrap_angle(a)
}

/// `a ⊕ b`.
#[inline]
pub fn compose(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    let (s, c) = a[2].sin_cos();
    [
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        wrap(a[2] + b[2]),
    ]
}

/// `a⁻¹`.
#[inline]
pub fn inverse(a: [f64; 3]) -> [f64; 3] {
    let (s, c) = a[2].sin_cos();
    [-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2]]
}

/// `a⁻¹ ⊕ b`: `b` seen from `a`.
#[inline]
pub fn between(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    compose(inverse(a), b)
}

/// The point `p` of frame `a` in `a`'s parent frame.
#[inline]
pub fn apply(a: [f64; 3], p: [f64; 2]) -> [f64; 2] {
    let (s, c) = a[2].sin_cos();
    [a[0] + c * p[0] - s * p[1], a[1] + s * p[0] + c * p[1]]
}
