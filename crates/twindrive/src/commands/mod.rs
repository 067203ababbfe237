//! One file per subcommand.

mod calibrate;
mod demo;
mod draw_map;
mod simulate;

use crate::cli::{Args, Command};

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Simulate {
            scenario,
            out,
            seed,
            duration_s,
        } => simulate::run(&scenario, &out, seed, duration_s),
        Command::Calibrate(a) => calibrate::run(&a),
        Command::Demo { out } => demo::run(&out),
        Command::DrawMap { dir } => draw_map::run(&dir),
    }
}
