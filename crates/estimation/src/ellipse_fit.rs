//! Direct least-squares ellipse fit (Fitzgibbon, Pilu and Fisher 1999, in
//! the numerically stable form of Halíř and Flusser 1998).

use nalgebra::{Matrix2, Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// A fitted ellipse. Axes are full lengths (diameters), as in the paper's
/// Table 1, so `area = π · major · minor / 4`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ellipse {
    pub centre: [f64; 2],
    pub major_axis_m: f64,
    pub minor_axis_m: f64,
    /// Angle of the major axis from +x.
    pub angle_rad: f64,
}

impl Ellipse {
    pub fn area_m2(&self) -> f64 {
        std::f64::consts::PI * self.major_axis_m * self.minor_axis_m / 4.0
    }
}

/// Fits an ellipse to at least five points; `None` if they do not determine one.
pub fn fit_ellipse(points: &[(f64, f64)]) -> Option<Ellipse> {
    if points.len() < 5 {
        return None;
    }
    // Centre and scale for conditioning.
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
    let scale = points
        .iter()
        .map(|p| (p.0 - mx).hypot(p.1 - my))
        .sum::<f64>()
        / n;
    if scale <= 0.0 {
        return None;
    }
    let (mut s1, mut s2, mut s3) = (Matrix3::zeros(), Matrix3::zeros(), Matrix3::zeros());
    for p in points {
        let (x, y) = ((p.0 - mx) / scale, (p.1 - my) / scale);
        let d1 = Vector3::new(x * x, x * y, y * y);
        let d2 = Vector3::new(x, y, 1.0);
        s1 += d1 * d1.transpose();
        s2 += d1 * d2.transpose();
        s3 += d2 * d2.transpose();
    }
    let t = -s3.try_inverse()? * s2.transpose();
    let m = s1 + s2 * t;
    // Premultiply by the inverse of the constraint matrix C1 = [[0,0,2],[0,-1,0],[2,0,0]].
    let c1_inv = Matrix3::new(0.0, 0.0, 0.5, 0.0, -1.0, 0.0, 0.5, 0.0, 0.0);
    let m = c1_inv * m;
    // The eigenvector with 4ac − b² > 0.
    let eig = m.complex_eigenvalues();
    let mut best: Option<Vector3<f64>> = None;
    for lambda in eig.iter() {
        if lambda.im.abs() > 1e-9 * (1.0 + lambda.re.abs()) {
            continue;
        }
        let shifted = m - Matrix3::identity() * lambda.re;
        let svd = shifted.svd(false, true);
        let v_t = svd.v_t?;
        let (k, _) = svd.singular_values.argmin();
        let v: Vector3<f64> = v_t.row(k).transpose();
        if 4.0 * v[0] * v[2] - v[1] * v[1] > 0.0 {
            best = Some(v);
        }
    }
    let a1 = best?;
    let a2 = t * a1;
    let (a, b, c, d, e, f) = (a1[0], a1[1], a1[2], a2[0], a2[1], a2[2]);
    // Centre: gradient of the conic is zero.
    let q = Matrix2::new(a, b / 2.0, b / 2.0, c);
    let centre = q.try_inverse()? * nalgebra::Vector2::new(-d / 2.0, -e / 2.0);
    let f0 = f + 0.5 * (d * centre[0] + e * centre[1]);
    let eig = q.symmetric_eigen();
    let semi: Vec<f64> = eig.eigenvalues.iter().map(|l| (-f0 / l).sqrt()).collect();
    if semi.iter().any(|s| !s.is_finite()) {
        return None;
    }
    let (major_i, minor_i) = if semi[0] >= semi[1] { (0, 1) } else { (1, 0) };
    let axis = eig.eigenvectors.column(major_i);
    Some(Ellipse {
        centre: [mx + scale * centre[0], my + scale * centre[1]],
        major_axis_m: 2.0 * scale * semi[major_i],
        minor_axis_m: 2.0 * scale * semi[minor_i],
        angle_rad: axis[1].atan2(axis[0]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_ellipse_from_noisy_points() {
        let (cx, cy, a, b, phi) = (1.5, -0.7, 1.2, 0.8, 0.4_f64);
        let mut pts = Vec::new();
        for k in 0..400 {
            let t = k as f64 * std::f64::consts::TAU / 400.0;
            let (x, y) = (a * t.cos(), b * t.sin());
            let noise = 1e-4 * ((k * 7919 % 13) as f64 - 6.0);
            pts.push((
                cx + x * phi.cos() - y * phi.sin() + noise,
                cy + x * phi.sin() + y * phi.cos() - noise,
            ));
        }
        let e = fit_ellipse(&pts).unwrap();
        assert!(
            (e.centre[0] - cx).abs() < 1e-3 && (e.centre[1] - cy).abs() < 1e-3,
            "{e:?}"
        );
        assert!(
            (e.major_axis_m - 2.0 * a).abs() < 1e-3 && (e.minor_axis_m - 2.0 * b).abs() < 1e-3,
            "{e:?}"
        );
        assert!(
            (e.angle_rad.rem_euclid(std::f64::consts::PI) - phi).abs() < 1e-3,
            "{e:?}"
        );
        assert!((e.area_m2() - std::f64::consts::PI * a * b).abs() < 1e-2);
    }

    #[test]
    fn degenerate_input_gives_none() {
        assert!(fit_ellipse(&[(0.0, 0.0); 10]).is_none());
        assert!(fit_ellipse(&[(0.0, 0.0), (1.0, 1.0)]).is_none());
        let line: Vec<(f64, f64)> = (0..20).map(|k| (k as f64, 2.0 * k as f64)).collect();
        assert!(fit_ellipse(&line).is_none());
    }
}
