//! Where the robot is while it drives a plan: the augmented EKF over pose
//! and wheel parameters, fed with the encoders, any absolute pose (a
//! tracker) and the [`Localizer`]'s matches against the plan's map. The
//! executive tracks the plan from this estimate, in the site's frame. No
//! I/O; time comes with each reading.

use twindrive_estimation::{
    FilterConfig, Mat6, OnlineCalibrator, PoseSample, StateAndCovariance, WheelSample,
};
use twindrive_kinematics::{DiffDriveParams, Pose, WheelOdometry};
use twindrive_mission::plan::MissionPlan;

use crate::backend::Reading;
use crate::executive::Belief;
use crate::localize::{LocalizeSettings, Localizer, Mode};

/// Standard deviations of the robot's pose (x, y m; heading rad) before it
/// has estimated any: it was placed at its start by hand.
pub const START_POSE_STD: [f64; 3] = [0.05, 0.05, 0.05];

/// The filter's start for `plan`: `pose` with its covariance (row major;
/// [`START_POSE_STD`] when `None` or not finite, and never below a few
/// millimetres), and the plan's calibrated parameters at 3 % standard
/// deviation.
pub fn initial_estimate(
    pose: [f64; 3],
    pose_covariance: Option<&[f64; 9]>,
    calibrated: &DiffDriveParams,
) -> StateAndCovariance {
    let c = calibrated;
    let known = pose_covariance.filter(|p| p.iter().all(|v| v.is_finite()));
    let mut covariance = Mat6::zeros();
    for i in 0..3 {
        for j in 0..3 {
            covariance[(i, j)] = match known {
                Some(p) => p[3 * i + j],
                None if i == j => START_POSE_STD[i] * START_POSE_STD[i],
                None => 0.0,
            };
        }
    }
    for i in 0..3 {
        covariance[(i, i)] = covariance[(i, i)].max(0.003f64.powi(2));
    }
    let params = [c.left_diameter_m, c.right_diameter_m, c.wheelbase_m];
    for (i, p) in params.iter().enumerate() {
        covariance[(3 + i, 3 + i)] = (0.03 * p).powi(2);
    }
    StateAndCovariance {
        state: [pose[0], pose[1], pose[2], params[0], params[1], params[2]].into(),
        covariance,
    }
}

/// `estimate` with the wheel parameters the robot learnt driving earlier
/// plans (diameters and wheelbase, m, and their 3 x 3 covariance, row
/// major) instead of the plan's: calibration carries on across plans. Kept
/// as they are when not finite or not positive.
pub fn with_learnt_params(
    mut estimate: StateAndCovariance,
    params: [f64; 3],
    covariance: &[f64; 9],
) -> StateAndCovariance {
    let usable = params.iter().all(|p| p.is_finite() && *p > 0.0)
        && covariance.iter().all(|v| v.is_finite())
        && (0..3).all(|i| covariance[4 * i] > 0.0);
    if usable {
        for i in 0..3 {
            estimate.state[3 + i] = params[i];
            for j in 0..3 {
                estimate.covariance[(3 + i, 3 + j)] = covariance[3 * i + j];
                // The pose's start is not known jointly with them.
                estimate.covariance[(i, 3 + j)] = 0.0;
                estimate.covariance[(3 + i, j)] = 0.0;
            }
        }
    }
    estimate
}

/// The robot's estimate over one plan.
pub struct Navigator {
    ekf: Option<OnlineCalibrator>,
    initial: StateAndCovariance,
    localizer: Localizer,
    rad_per_tick: f64,
    /// Steer by odometry alone (localization off): dead reckoning with the
    /// plan's parameters.
    odometry: Option<(WheelOdometry, DiffDriveParams)>,
}

impl Navigator {
    /// For `plan` on a robot whose encoders count `ticks_per_rev`, starting
    /// from `initial` at the first reading.
    pub fn new(
        plan: &MissionPlan,
        initial: StateAndCovariance,
        ticks_per_rev: u32,
        settings: LocalizeSettings,
    ) -> Self {
        let s = initial.state;
        Self {
            ekf: None,
            initial,
            localizer: Localizer::new(plan, settings),
            rad_per_tick: std::f64::consts::TAU / f64::from(ticks_per_rev.max(1)),
            odometry: (!settings.enabled).then(|| {
                (
                    WheelOdometry::new(Pose::new(s[0], s[1], s[2])),
                    plan.header.calibrated,
                )
            }),
        }
    }

    pub fn localizer(&self) -> &Localizer {
        &self.localizer
    }

    /// Feeds one period's encoders, any absolute pose and any map match to
    /// the filter; the pose to steer by after it: the filter's estimate, or
    /// with localization off dead reckoning on the plan's parameters (how
    /// robots drove before plans carried maps; the filter still calibrates
    /// on any tracker, for the hand-back).
    pub fn update(&mut self, reading: &Reading) -> Belief {
        let t = reading.t_s;
        let initial = self.initial;
        let ekf = self.ekf.get_or_insert_with(|| {
            OnlineCalibrator::new(initial, t, FilterConfig::default(), false)
        });
        if let Some(p) = reading.pose
            && let Err(e) = ekf.push_pose(PoseSample {
                t_s: t,
                x_m: p.x_m,
                y_m: p.y_m,
                heading_rad: Some(p.heading_rad),
            })
        {
            tracing::debug!(error = %e, "a pose the filter did not take");
        }
        let wheels_rad = reading.encoder_ticks.map(|ticks| {
            [
                ticks[0] as f64 * self.rad_per_tick,
                ticks[1] as f64 * self.rad_per_tick,
            ]
        });
        if let (Some((odometry, params)), Some(w)) = (&mut self.odometry, wheels_rad) {
            odometry.advance(params, w);
        }
        if let Some([left_rad, right_rad]) = wheels_rad
            && let Err(e) = ekf.push_wheels(WheelSample {
                t_s: t,
                left_rad,
                right_rad,
            })
        {
            tracing::debug!(error = %e, "an encoder sample the filter did not take");
        }
        let e = ekf.estimate();
        let pose = [e.state[0], e.state[1], e.state[2]];
        let covariance = [0, 1, 2].map(|i| [0, 1, 2].map(|j| e.covariance[(i, j)]));
        let params = DiffDriveParams::new(e.state[3], e.state[4], e.state[5]);
        if let Some(fix) = self.localizer.observe(
            t,
            wheels_rad,
            &params,
            &reading.fresh_ranges_m,
            pose,
            &covariance,
        ) {
            match ekf.update_pose_information(fix.matched.pose, &fix.matched.information) {
                Ok(outcome) if outcome.accepted > 0 => self.localizer.fused(fix.t_s),
                Ok(_) => {}
                Err(e) => tracing::debug!(error = %e, "a map match the filter did not take"),
            }
        }
        let localizing = self.odometry.is_none() && self.localizer.mode() != Mode::None;
        Belief {
            pose: match &self.odometry {
                Some((odometry, _)) => odometry.pose,
                None => self.pose(),
            },
            pose_std: self.pose_std(),
            localizing,
        }
    }

    fn estimate(&self) -> StateAndCovariance {
        match &self.ekf {
            Some(ekf) => {
                let e = ekf.estimate();
                StateAndCovariance {
                    state: e.state,
                    covariance: e.covariance,
                }
            }
            None => self.initial,
        }
    }

    /// The pose estimate.
    pub fn pose(&self) -> Pose {
        let s = self.estimate().state;
        Pose::new(s[0], s[1], s[2])
    }

    /// The pose's standard deviations (x, y m; heading rad).
    pub fn pose_std(&self) -> [f64; 3] {
        let c = self.pose_covariance();
        [
            c[0].max(0.0).sqrt(),
            c[4].max(0.0).sqrt(),
            c[8].max(0.0).sqrt(),
        ]
    }

    /// The pose's 3 x 3 covariance, row major.
    pub fn pose_covariance(&self) -> [f64; 9] {
        self.block(0)
    }

    /// The wheel diameters and wheelbase (m) estimated.
    pub fn params(&self) -> [f64; 3] {
        let s = self.estimate().state;
        [s[3], s[4], s[5]]
    }

    /// The parameters' 3 x 3 covariance, row major.
    pub fn params_covariance(&self) -> [f64; 9] {
        self.block(3)
    }

    fn block(&self, at: usize) -> [f64; 9] {
        covariance_block(&self.estimate(), at)
    }
}

/// The 3 x 3 block of `estimate`'s covariance from row and column `at` (0:
/// the pose, 3: the parameters), row major.
pub fn covariance_block(estimate: &StateAndCovariance, at: usize) -> [f64; 9] {
    let c = &estimate.covariance;
    let mut out = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            out[3 * i + j] = c[(at + i, at + j)];
        }
    }
    out
}
