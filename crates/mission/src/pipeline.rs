//! The whole chain on one mission log: planner → redundancy removal →
//! re-compute control → filter control signals (and the time-optimal
//! alternative). Each stage's output is kept for figures and reports.

use serde::{Deserialize, Serialize};
use twindrive_kinematics::DiffDriveParams;
use twindrive_log::MissionLog;

use crate::control::{WheelCommand, recompute};
use crate::error::PipelineError;
use crate::path::{PathSample, path_length_m};
use crate::planner::{PlannerSettings, executed_path};
use crate::redundancy::{Pruned, RedundancyConfig, remove_redundancy};
use crate::retime::WheelLimits;
use crate::spikes::{FilterSettings, Filtered, filter_spikes, time_optimal};

/// Every setting of the pipeline (the plan records them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineSettings {
    #[serde(default)]
    pub planner: PlannerSettings,
    pub redundancy: RedundancyConfig,
    #[serde(default)]
    pub filter: FilterSettings,
}

/// Each stage's output.
#[derive(Debug, Clone)]
pub struct Stages {
    /// The executed path from the encoders (mission planner).
    pub executed: Vec<PathSample>,
    pub pruned: Pruned,
    /// The path without its redundant parts; every junction is driven in
    /// one control period, as the deletion leaves it.
    pub cleaned: Vec<PathSample>,
    pub cleaned_commands: Vec<WheelCommand>,
    /// The plan: spikes filtered (Fig. 8b); its `spikes` are those of the
    /// cleaned path (Fig. 8a).
    pub filtered: Filtered,
    /// The same path as fast as the limits allow, or why not.
    pub fastest: Result<(Vec<PathSample>, Vec<WheelCommand>), PipelineError>,
    /// The control period of the source (mean encoder period).
    pub period_s: f64,
}

/// Numbers for people.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageSummary {
    pub executed_length_m: f64,
    pub executed_duration_s: f64,
    pub deletions: usize,
    pub loops_removed: usize,
    pub kinks_removed: usize,
    /// The path with its redundant parts removed (jumps included).
    pub cleaned_length_m: f64,
    pub spikes_found: usize,
    /// The plan's own path and duration.
    pub filtered_length_m: f64,
    pub filtered_duration_s: f64,
    pub filter_windows: usize,
    /// The longest the plan holds one wheel command (s).
    pub longest_hold_s: f64,
    /// `None` when the time-optimal re-timing failed (`time_optimal_error`).
    pub time_optimal_duration_s: Option<f64>,
    pub time_optimal_error: Option<String>,
    /// Every deletion: time span and length on the executed path, and why.
    pub deletion_list: Vec<crate::redundancy::Deletion>,
}

impl Stages {
    pub fn summary(&self) -> StageSummary {
        use crate::redundancy::DeletionReason;
        let duration = |p: &[PathSample]| match (p.first(), p.last()) {
            (Some(a), Some(b)) => b.t_s - a.t_s,
            _ => 0.0,
        };
        let kinks = self
            .pruned
            .deletions
            .iter()
            .filter(|d| d.reason == DeletionReason::Reversal)
            .count();
        StageSummary {
            executed_length_m: path_length_m(&self.executed),
            executed_duration_s: duration(&self.executed),
            deletions: self.pruned.deletions.len(),
            loops_removed: self.pruned.deletions.len() - kinks,
            kinks_removed: kinks,
            cleaned_length_m: path_length_m(&self.cleaned),
            spikes_found: self.filtered.spikes.len(),
            filtered_length_m: path_length_m(&self.filtered.samples),
            filtered_duration_s: duration(&self.filtered.samples),
            filter_windows: self.filtered.windows.len(),
            longest_hold_s: crate::spikes::longest_hold_s(&self.filtered.samples),
            time_optimal_duration_s: self.fastest.as_ref().ok().map(|(p, _)| duration(p)),
            time_optimal_error: self.fastest.as_ref().err().map(|e| e.to_string()),
            deletion_list: self.pruned.deletions.clone(),
        }
    }
}

/// Re-times kept samples: each kept stretch keeps its durations, and each
/// junction a deletion left is given one control period.
fn close_gaps(path: &[PathSample], kept: &[usize], period_s: f64) -> Vec<PathSample> {
    let mut out: Vec<PathSample> = Vec::with_capacity(kept.len());
    for (n, &k) in kept.iter().enumerate() {
        let t = match n.checked_sub(1) {
            None => path[k].t_s,
            Some(m) => {
                let previous = kept[m];
                let step = if k == previous + 1 {
                    path[k].t_s - path[previous].t_s
                } else {
                    period_s
                };
                out[m].t_s + step
            }
        };
        out.push(PathSample { t_s: t, ..path[k] });
    }
    out
}

/// Runs the pipeline on `log` with the calibrated `params`.
pub fn run(
    log: &MissionLog,
    params: &DiffDriveParams,
    limits: &WheelLimits,
    settings: &PipelineSettings,
) -> Result<Stages, PipelineError> {
    limits.validate()?;
    let executed = executed_path(log, params, &settings.planner)?;
    let period_s = (executed.last().expect("two samples at least").t_s - executed[0].t_s)
        / (executed.len() - 1) as f64;
    let pruned = remove_redundancy(&executed, &settings.redundancy)?;
    let mut cleaned = close_gaps(&executed, &pruned.kept, period_s);
    let cleaned_commands = recompute(&mut cleaned, params);
    let filtered = filter_spikes(&cleaned, params, limits, period_s, &settings.filter)?;
    // The alternative must not cost the plan: its failure is reported.
    let fastest = time_optimal(&filtered.samples, params, limits, period_s);
    Ok(Stages {
        executed,
        pruned,
        cleaned,
        cleaned_commands,
        filtered,
        fastest,
        period_s,
    })
}
