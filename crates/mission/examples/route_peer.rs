//! The goal planner's side of `bench/route_vs_python.sh`, and the site the
//! criterion bench (`benches/route.rs`) plans on: a 20 m x 20 m site with
//! rooms and clutter at 5 cm cells.
//!
//! `route_peer --write SEED DIR`: writes the cells that keep the clearance
//! (`passable.txt`, one row of 0/1 per line, y up from the first line) and
//! the query (`query.json`: start and goal cells, the cell size), the
//! grid the peer searches.
//! `route_peer --run SEED REPEAT`: plans the way REPEAT times (the grid
//! built each time, as a fresh site would be) and prints the best time
//! and the way's length.

use std::time::Instant;

use rand::{RngExt, SeedableRng};
use twindrive_mission::route::{RoutePlanner, RouteSettings};
use twindrive_sim::World;

pub const FOOTPRINT_M: f64 = 0.15;

/// A 20 m square with a wall across it in two places (doors in each) and
/// 60 blocks of clutter, and a start and a goal in opposite corners.
pub fn site(seed: u64) -> (World, [f64; 2], [f64; 2]) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let s = 20.0;
    let mut walls = vec![
        [0.0, 0.0, s, 0.0],
        [s, 0.0, s, s],
        [s, s, 0.0, s],
        [0.0, s, 0.0, 0.0],
    ];
    for x in [7.0, 13.0] {
        let door = rng.random_range(2.0..s - 3.0);
        walls.push([x, 0.0, x, door]);
        walls.push([x, door + 1.0, x, s]);
    }
    let mut blocks = Vec::new();
    while blocks.len() < 60 {
        let (x, y) = (
            rng.random_range(0.5..s - 1.5),
            rng.random_range(0.5..s - 1.5),
        );
        let b = (
            [x, y],
            [
                x + rng.random_range(0.2..1.2),
                y + rng.random_range(0.2..1.2),
            ],
        );
        let clear_of = |p: [f64; 2]| {
            p[0] < b.0[0] - 0.8 || p[0] > b.1[0] + 0.8 || p[1] < b.0[1] - 0.8 || p[1] > b.1[1] + 0.8
        };
        if clear_of([1.0, 1.0])
            && clear_of([19.0, 19.0])
            && (b.1[0] < 6.2 || b.0[0] > 7.8)
            && (b.1[0] < 12.2 || b.0[0] > 13.8)
        {
            blocks.push(b);
        }
    }
    (
        World::from_walls(&walls, &[]).with_blocks(&blocks),
        [1.0, 1.0],
        [19.0, 19.0],
    )
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = || -> ! {
        eprintln!("usage: route_peer --write SEED DIR | --run SEED REPEAT");
        std::process::exit(2)
    };
    if args.len() != 4 {
        usage()
    }
    let seed: u64 = args[2].parse().unwrap_or_else(|_| usage());
    let (world, start, goal) = site(seed);
    let settings = RouteSettings::default();
    match args[1].as_str() {
        "--write" => {
            let dir = std::path::Path::new(&args[3]);
            let planner = RoutePlanner::new(&world, &[], FOOTPRINT_M, settings).unwrap();
            let cell = settings.cell_m;
            let b = world.bounds().unwrap();
            let (nx, ny) = (
                ((b.maxs.x - b.mins.x) / cell).round() as usize,
                ((b.maxs.y - b.mins.y) / cell).round() as usize,
            );
            let centre = |i: usize, j: usize| {
                [
                    b.mins.x + (i as f64 + 0.5) * cell,
                    b.mins.y + (j as f64 + 0.5) * cell,
                ]
            };
            let mut text = String::with_capacity((nx + 1) * ny);
            for j in 0..ny {
                for i in 0..nx {
                    let ok = planner.clearance_at(centre(i, j)) >= settings.clearance_m;
                    text.push(if ok { '1' } else { '0' });
                }
                text.push('\n');
            }
            std::fs::write(dir.join("passable.txt"), text).unwrap();
            let cell_of = |p: [f64; 2]| {
                [
                    ((p[0] - b.mins.x) / cell) as usize,
                    ((p[1] - b.mins.y) / cell) as usize,
                ]
            };
            let query = format!(
                "{{\"start\": {:?}, \"goal\": {:?}, \"cell_m\": {cell}}}\n",
                cell_of(start),
                cell_of(goal)
            );
            std::fs::write(dir.join("query.json"), query).unwrap();
        }
        "--run" => {
            let repeat: usize = args[3].parse().unwrap_or_else(|_| usage());
            let mut best = f64::INFINITY;
            let mut length = 0.0;
            let mut search_best = f64::INFINITY;
            for _ in 0..repeat.max(1) {
                let t0 = Instant::now();
                let planner = RoutePlanner::new(&world, &[], FOOTPRINT_M, settings).unwrap();
                let t1 = Instant::now();
                let route = planner.route(start, &[goal]).expect("a way across");
                let done = Instant::now();
                best = best.min((done - t0).as_secs_f64() * 1e3);
                search_best = search_best.min((done - t1).as_secs_f64() * 1e3);
                length = route.length_m;
            }
            println!("twindrive_ms {best:.3}");
            println!("twindrive_search_ms {search_best:.3}");
            println!("twindrive_length_m {length:.3}");
        }
        _ => usage(),
    }
}
