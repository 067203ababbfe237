//! The check every plan passes before it is sent: the twin it was rehearsed
//! in, resolved from `--scenario` or the built-in scenario the plan names,
//! and its verification there. `sign`, `master` and `verify-plan` share it.

use std::path::Path;

use anyhow::bail;
use twindrive_link::envelope::Tolerances;
use twindrive_mission::plan::MissionPlan;
use twindrive_mission::verify::{self, Verdict};
use twindrive_sim::Scenario;

/// The twin a plan was rehearsed in: `scenario` if given, else the built-in
/// scenario the plan names.
pub fn twin_of(plan: &MissionPlan, scenario: Option<&Path>) -> anyhow::Result<Scenario> {
    match scenario {
        Some(p) => Scenario::load(p).map_err(|e| anyhow::anyhow!("--scenario: {e}")),
        None => match twindrive_sim::builtin::load(&plan.header.robot.scenario) {
            Some(s) => Ok(s?),
            None => bail!(
                "the plan's scenario `{}` is not built in; pass --scenario with the TOML it was rehearsed in",
                plan.header.robot.scenario
            ),
        },
    }
}

/// Verifies `plan` on `twin` against the deviation tolerance robots hand
/// back on. A plan that fails is refused with its reasons, unless
/// `allow_failed` (the operator insists): then the failure is said on
/// stderr and logged, and the plan goes.
pub fn check_before_sending(
    plan: &MissionPlan,
    twin: &Scenario,
    allow_failed: bool,
) -> anyhow::Result<Verdict> {
    let checked = verify::verify(
        plan,
        twin,
        &twindrive_agent::executive::criteria(&Tolerances::default()),
    )?;
    let verdict = checked.verdict;
    if !verdict.passed {
        let reasons = verdict.reasons.join("; ");
        if !allow_failed {
            bail!(
                "plan {} failed verification on the twin `{}`: {reasons}. It is not sent: what fails on the twin fails on the robot. To mend it: {}. Or pass --allow-failed-verification to send it anyway",
                &plan.sha256[..12],
                twin.name,
                verdict.advice().join("; ")
            );
        }
        eprintln!(
            "warning: plan {} FAILED verification ({reasons}); sending it anyway because of --allow-failed-verification",
            &plan.sha256[..12]
        );
        tracing::warn!(plan = %plan.sha256, reasons, "sending a plan that failed verification (operator override)");
    }
    Ok(verdict)
}
