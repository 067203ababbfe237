//! `twindrive demo`: the case study end to end (the work is
//! `twindrive-experiment`'s).

use std::path::Path;

pub fn run(out: &Path) -> anyhow::Result<()> {
    twindrive_experiment::demo::run(out, &mut std::io::stdout().lock())
}
