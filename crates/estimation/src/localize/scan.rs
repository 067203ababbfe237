//! One planar range scan as a sensor reports it: a fan of beams and a
//! range per beam, where a reading outside (range_min, range_max) or not
//! finite is no return (a max-range reading, a dropout).

/// A scan in the sensor's frame (REP-103: x forward, y left, angles
/// counter-clockwise from x).
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// Time of the scan (s).
    pub t_s: f64,
    /// Bearing of the first beam (rad).
    pub angle_min_rad: f64,
    /// Bearing step between beams (rad; negative for a clockwise scanner).
    pub increment_rad: f64,
    pub range_min_m: f64,
    pub range_max_m: f64,
    /// One range per beam (m).
    pub ranges_m: Vec<f32>,
}

impl Scan {
    /// Whether beam `i`'s reading is a return.
    #[inline]
    pub fn valid(&self, i: usize) -> bool {
        let r = f64::from(self.ranges_m[i]);
        r.is_finite() && r > self.range_min_m && r < self.range_max_m
    }

    /// Bearing of beam `i` (rad).
    #[inline]
    pub fn bearing(&self, i: usize) -> f64 {
        self.angle_min_rad + i as f64 * self.increment_rad
    }

    /// The endpoint of beam `i` in the sensor's frame, when it is a return.
    #[inline]
    pub fn endpoint(&self, i: usize) -> Option<[f64; 2]> {
        self.valid(i).then(|| {
            let r = f64::from(self.ranges_m[i]);
            let (s, c) = self.bearing(i).sin_cos();
            [r * c, r * s]
        })
    }

    /// Endpoints of the returns, in beam order.
    pub fn points(&self) -> Vec<[f64; 2]> {
        self.endpoints().flatten().collect()
    }

    /// The endpoint of every beam, `None` for no return, with the bearings
    /// rotated along rather than a sine and cosine a beam (re-seeded every
    /// 64 beams, so they stay within 1e-14 rad).
    pub fn endpoints(&self) -> impl Iterator<Item = Option<[f64; 2]>> + '_ {
        let (ds, dc) = self.increment_rad.sin_cos();
        let mut unit = [0.0, 0.0];
        (0..self.ranges_m.len()).map(move |i| {
            if i % 64 == 0 {
                let (s, c) = self.bearing(i).sin_cos();
                unit = [c, s];
            } else {
                unit = [unit[0] * dc - unit[1] * ds, unit[0] * ds + unit[1] * dc];
            }
            self.valid(i).then(|| {
                let r = f64::from(self.ranges_m[i]);
                [r * unit[0], r * unit[1]]
            })
        })
    }

    /// Whether the fan closes on itself (a 360-degree scanner).
    pub fn full_circle(&self) -> bool {
        let n = self.ranges_m.len() as f64;
        (self.increment_rad.abs() * n - std::f64::consts::TAU).abs() < self.increment_rad.abs()
    }
}
