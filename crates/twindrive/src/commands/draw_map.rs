use std::io::Write;
use std::path::Path;

use anyhow::Context;

use twindrive_files::Staging;

pub fn run(dir: &Path) -> anyhow::Result<()> {
    let (pgm, yaml) = twindrive_sim::map::draw_office_map();
    let staging = Staging::new(dir, "draw-map")?;
    std::fs::write(staging.path("office.pgm"), pgm).context("writing office.pgm")?;
    std::fs::write(staging.path("office.yaml"), yaml).context("writing office.yaml")?;
    staging.commit()?;
    writeln!(
        std::io::stdout().lock(),
        "wrote {0}/office.pgm and {0}/office.yaml",
        dir.display()
    )?;
    Ok(())
}
