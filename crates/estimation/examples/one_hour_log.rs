//! Writes a one-hour calibration log as generic CSVs (encoders at 50 Hz,
//! tracker at 120 Hz) for `bench/calibrate_one_hour.sh`:
//! `cargo run --release -p twindrive-estimation --example one_hour_log -- DIR [SECONDS]`
//! (default 3600 s; the benchmark's smoke mode asks for less).

use std::io::Write;
use std::path::Path;

use twindrive_sim::{ControllerConfig, Scenario, Simulator, StepOutput};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .ok_or("usage: one_hour_log DIR [SECONDS]")?;
    let duration_s: f64 = match std::env::args().nth(2) {
        Some(s) => s.parse()?,
        None => 3600.0,
    };
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir)?;
    let mut sc = Scenario::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/calibration_drive.toml"),
    )?;
    if let ControllerConfig::Scripted(spec) = &mut sc.controller {
        spec.segments
            .retain(|s| s.left_rad_s != 0.0 || s.right_rad_s != 0.0);
        spec.repeat = true;
    }
    sc.set_duration_s(duration_s)?;
    let mut sim = Simulator::new(sc);
    let mut out = StepOutput::new(sim.beams());
    let mut enc = std::io::BufWriter::new(std::fs::File::create(dir.join("encoders.csv"))?);
    let mut pose = std::io::BufWriter::new(std::fs::File::create(dir.join("poses.csv"))?);
    writeln!(enc, "t,left_ticks,right_ticks")?;
    writeln!(pose, "t,x,y,theta")?;
    let (mut n_enc, mut n_pose) = (0, 0);
    while sim.step(&mut out) {
        let s = &out.record;
        let t = twindrive_log::format_seconds(s.t_ns);
        if let Some([l, r]) = s.encoder_ticks {
            writeln!(enc, "{t},{l},{r}")?;
            n_enc += 1;
        }
        if let Some(p) = s.tracker {
            writeln!(pose, "{t},{},{},{}", p.x_m, p.y_m, p.heading_rad)?;
            n_pose += 1;
        }
    }
    enc.flush()?;
    pose.flush()?;
    println!(
        "wrote {n_enc} encoder rows and {n_pose} pose rows to {}",
        dir.display()
    );
    Ok(())
}
