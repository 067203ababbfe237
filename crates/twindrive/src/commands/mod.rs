//! One file per subcommand.

mod bag;
mod calibrate;
mod console;
mod demo;
mod draw_map;
mod experiment;
mod keys;
mod map;
mod ops;
mod plan;
mod prune;
mod rehearse;
mod relations;
mod rosbag;
mod simulate;
mod site_sim;
mod verify_plan;

use crate::cli::{Args, Command};

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Simulate {
            scenario,
            out,
            seed,
            duration_s,
        } => simulate::run(&scenario, &out, seed, duration_s),
        Command::Rehearse {
            scenario,
            goals,
            freedom,
            route_only,
            out,
            seed,
        } => rehearse::run(&rehearse::Args {
            scenario,
            goals,
            freedom,
            route_only,
            out,
            seed,
        }),
        Command::Calibrate(a) => calibrate::run(&a),
        Command::Map(a) => map::run(&a),
        Command::Plan(a) => plan::run(&a),
        Command::VerifyPlan {
            plan,
            scenario,
            out,
        } => verify_plan::run(&plan, scenario.as_deref(), &out),
        Command::Prune(a) => prune::run(&a),
        Command::Relations(a) => relations::run(&a),
        Command::Demo { out } => demo::run(&out),
        Command::DrawMap { dir } => draw_map::run(&dir),
        Command::Keygen { out, robot } => keys::keygen(&out, robot.as_deref()),
        Command::Certs {
            out,
            robots,
            router_host,
            port,
            days,
        } => keys::certs(twindrive_ops::certs::CertsRequest {
            out,
            robots,
            router_hosts: router_host,
            port,
            days,
        }),
        Command::Sign(a) => keys::sign(&a),
        Command::Robot(a) => ops::robot(&a),
        Command::Master(a) => ops::master(&a),
        Command::Console(a) => console::run(&a),
        Command::Rosbag(a) => rosbag::run(&a),
        Command::Bag { command } => bag::run(&command),
        Command::SiteSim { site } => site_sim::run(&site),
        Command::Experiment { command } => experiment::run(&command),
        Command::Router {
            listen,
            zenoh_config,
        } => ops::router(listen, zenoh_config),
    }
}
