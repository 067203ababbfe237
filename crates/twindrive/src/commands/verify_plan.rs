//! `twindrive verify-plan`: replay a plan on the twin before the real robot
//! sees it (the work is `twindrive-workflow`'s).

use std::path::Path;

use twindrive_workflow::verification::twin_of;
use twindrive_workflow::verify::{self, PlanFailed};

pub fn run(plan_path: &Path, scenario: Option<&Path>, out: &Path) -> anyhow::Result<()> {
    let plan = twindrive_workflow::inputs::read_plan(plan_path)?;
    let scenario = twin_of(&plan, scenario)?;
    let v = verify::verify(&plan, &scenario)?;
    verify::write_outputs(&plan, &v, &scenario, out)?;
    verify::print_report(&v.report, out, &mut std::io::stdout().lock())?;
    if !v.report.verdict.passed {
        return Err(PlanFailed(v.report.verdict.clone()).into());
    }
    Ok(())
}
