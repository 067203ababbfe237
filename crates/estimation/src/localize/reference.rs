//! What a scan is matched against: anything that gives a point's residual
//! (a signed distance to the nearest surface, or the distance to the
//! nearest point) and its gradient in the point.

/// A reference for the matcher.
pub trait Reference {
    /// What a point is paired with (a wall, a reading's tangent line): the
    /// matcher may hold the pairing fixed while the pose settles.
    type Feature: Copy;

    /// The feature nearest the point (x, y), in the reference's frame;
    /// `None` where the reference has nothing near.
    fn associate(&self, x: f64, y: f64) -> Option<Self::Feature>;

    /// The residual of the point against `feature` (a signed distance from
    /// a line, or a distance from a point) and its gradient in the point.
    fn measure(&self, feature: &Self::Feature, x: f64, y: f64) -> (f64, [f64; 2]);

    /// [`associate`](Self::associate) then [`measure`](Self::measure).
    #[inline]
    fn residual(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
        self.associate(x, y).map(|f| self.measure(&f, x, y))
    }
}

impl Reference for super::SegmentMap {
    /// The point itself: the map's lookup is exact and as fast as a held
    /// pairing would be.
    type Feature = [f64; 2];

    #[inline]
    fn associate(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        super::SegmentMap::residual(self, x, y).map(|_| [x, y])
    }

    #[inline]
    fn measure(&self, _: &[f64; 2], x: f64, y: f64) -> (f64, [f64; 2]) {
        super::SegmentMap::residual(self, x, y).unwrap_or((f64::INFINITY, [0.0, 0.0]))
    }

    #[inline]
    fn residual(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
        super::SegmentMap::residual(self, x, y)
    }
}

/// The residual of a point against a reference point with a surface normal
/// (`[0, 0]` when the neighbourhood is not a line): the signed distance
/// from the tangent line, else the distance from the point itself.
#[inline]
fn point_to_line(q: [f64; 2], p: [f64; 2], normal: [f64; 2]) -> (f64, [f64; 2]) {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    if normal != [0.0, 0.0] {
        return (dx * normal[0] + dy * normal[1], normal);
    }
    let d = (dx * dx + dy * dy).sqrt();
    if d > 0.0 {
        (d, [dx / d, dy / d])
    } else {
        (0.0, [0.0, 0.0])
    }
}

/// A point of a reference and the line its neighbourhood lies along.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anchor {
    /// On the line: the neighbourhood's centroid, which averages the
    /// readings' noise (the reading itself when there is no line).
    pub at: [f64; 2],
    /// Unit normal of the line; `[0, 0]` for none.
    pub normal: [f64; 2],
}

impl Anchor {
    /// The least-squares line through `points`, the first of which is the
    /// reading being anchored; no line when they do not lie along one:
    /// fewer than three, or spread across more than `max_flatness`
    /// (smallest over largest variance: a corner, a clump).
    #[cfg(test)]
    pub(crate) fn fit(points: &[[f64; 2]], max_flatness: f64) -> Self {
        let mut m = Moments::default();
        for p in points {
            m.add(*p);
        }
        let reading = points.first().copied().unwrap_or([f64::NAN; 2]);
        Self::from_moments(&m, reading, max_flatness)
    }

    /// As [`fit`](Self::fit), from the points' moments; `reading` is the
    /// anchor when there is no line.
    pub(crate) fn from_moments(m: &Moments, reading: [f64; 2], max_flatness: f64) -> Self {
        let none = Self {
            at: reading,
            normal: [0.0, 0.0],
        };
        if m.n < 3.0 {
            return none;
        }
        let (mx, my) = (m.sx / m.n, m.sy / m.n);
        let sxx = (m.sxx - m.sx * mx).max(0.0);
        let syy = (m.syy - m.sy * my).max(0.0);
        let sxy = m.sxy - m.sx * my;
        // Eigenvalues of the 2x2 scatter matrix.
        let half_trace = 0.5 * (sxx + syy);
        let disc = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
        let (big, small) = (half_trace + disc, half_trace - disc);
        if big <= 0.0 || small > max_flatness * big {
            return none;
        }
        // The line's direction is the eigenvector of `big`; the normal is
        // perpendicular to it.
        let (ux, uy) = if sxy.abs() > 1e-300 {
            (sxy, big - sxx)
        } else if sxx >= syy {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        let len = (ux * ux + uy * uy).sqrt();
        Self {
            at: [mx, my],
            normal: [-uy / len, ux / len],
        }
    }

    /// The residual of `q` against this anchor.
    #[inline]
    pub(crate) fn residual(&self, q: [f64; 2]) -> (f64, [f64; 2]) {
        point_to_line(q, self.at, self.normal)
    }
}

/// Sums of a set of points and of their products, for line fits over
/// sliding neighbourhoods.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Moments {
    pub n: f64,
    pub sx: f64,
    pub sy: f64,
    pub sxx: f64,
    pub sxy: f64,
    pub syy: f64,
}

impl Moments {
    pub(crate) fn add(&mut self, p: [f64; 2]) {
        self.n += 1.0;
        self.sx += p[0];
        self.sy += p[1];
        self.sxx += p[0] * p[0];
        self.sxy += p[0] * p[1];
        self.syy += p[1] * p[1];
    }

    /// `self - other`, for prefix sums.
    pub(crate) fn minus(&self, other: &Self) -> Self {
        Self {
            n: self.n - other.n,
            sx: self.sx - other.sx,
            sy: self.sy - other.sy,
            sxx: self.sxx - other.sxx,
            sxy: self.sxy - other.sxy,
            syy: self.syy - other.syy,
        }
    }
}

/// `atan2(y, x)` to about 1e-5 rad, several times faster than the exact
/// one: enough to find the beam a point falls on.
#[inline]
pub(crate) fn fast_atan2(y: f64, x: f64) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = if ax < ay { (ax, ay) } else { (ay, ax) };
    if hi == 0.0 {
        return 0.0;
    }
    let a = lo / hi;
    let s = a * a;
    // Abramowitz and Stegun 4.4.49 on [0, 1].
    let mut r = a
        * (0.999_866_0
            + s * (-0.330_299_5 + s * (0.180_141_0 + s * (-0.085_133_0 + s * 0.020_835_1))));
    if ay > ax {
        r = std::f64::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = std::f64::consts::PI - r;
    }
    if y < 0.0 { -r } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_of_a_noisy_line_and_none_for_a_corner() {
        for a in [0.0f64, 0.3, 1.2, 2.0, -0.7, std::f64::consts::FRAC_PI_2] {
            let (c, s) = (a.cos(), a.sin());
            let pts: Vec<[f64; 2]> = (0..9)
                .map(|k| {
                    let t = k as f64 * 0.02;
                    let e = if k % 2 == 0 { 0.002 } else { -0.002 };
                    [1.0 + t * c - e * s, 2.0 + t * s + e * c]
                })
                .collect();
            let anchor = Anchor::fit(&pts, 0.1);
            let n = anchor.normal;
            assert!((n[0] * c + n[1] * s).abs() < 0.05, "normal at {a}: {n:?}");
            assert!((n[0].hypot(n[1]) - 1.0).abs() < 1e-12);
            // The centroid is on the line, between the noisy readings.
            let (r, _) = anchor.residual([1.0, 2.0]);
            assert!(r.abs() < 0.001, "{r}");
        }
        let corner = [[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.2, 0.1], [0.2, 0.2]];
        assert_eq!(Anchor::fit(&corner, 0.1).normal, [0.0, 0.0]);
        assert_eq!(
            Anchor::fit(&corner, 0.1).at,
            [0.0, 0.0],
            "the reading itself"
        );
        assert_eq!(Anchor::fit(&[[1.0, 1.0]], 0.1).normal, [0.0, 0.0]);
    }

    #[test]
    fn fast_atan2_is_within_2e_5_of_the_exact_one() {
        for i in 0..10_000 {
            let a = -std::f64::consts::PI + i as f64 * std::f64::consts::TAU / 10_000.0;
            for r in [1e-3, 1.0, 30.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                let d = (fast_atan2(y, x) - y.atan2(x)).abs();
                assert!(
                    d < 2e-5 || (d - std::f64::consts::TAU).abs() < 2e-5,
                    "{a}: {d}"
                );
            }
        }
        assert_eq!(fast_atan2(0.0, 0.0), 0.0);
    }

    #[test]
    fn point_to_line_is_signed_and_falls_back_to_the_point() {
        let (r, g) = point_to_line([1.0, 0.3], [0.0, 0.0], [0.0, 1.0]);
        assert_eq!((r, g), (0.3, [0.0, 1.0]));
        let (r, g) = point_to_line([3.0, 4.0], [0.0, 0.0], [0.0, 0.0]);
        assert!((r - 5.0).abs() < 1e-12 && (g[0] - 0.6).abs() < 1e-12);
    }
}
