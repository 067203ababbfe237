//! Goal-level planning on a 20 m x 20 m site with rooms and clutter at
//! 5 cm cells (the site of `examples/route_peer.rs`): building the grid of
//! footprint clearances, a way from one corner to the other on it (the
//! issue's target: under 50 ms a goal on one core, the grid included), and
//! the refusal of a goal shut in a box of walls (under 100 ms).
//! The side by side with a Python A* on the same grid is
//! `bench/route_vs_python.sh`.
//!
//! `cargo bench -p twindrive-mission --bench route`

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use twindrive_mission::route::{RoutePlanner, RouteSettings};

#[path = "../examples/route_peer.rs"]
#[allow(dead_code)]
mod peer;

fn route(c: &mut Criterion) {
    let mut group = c.benchmark_group("route 20x20 m at 5 cm");
    group.sample_size(20);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(4));
    let (world, start, goal) = peer::site(1);
    let settings = RouteSettings::default();
    group.bench_function("site grid", |b| {
        b.iter(|| RoutePlanner::new(black_box(&world), &[], peer::FOOTPRINT_M, settings))
    });
    let planner = RoutePlanner::new(&world, &[], peer::FOOTPRINT_M, settings).unwrap();
    group.bench_function("corner to corner", |b| {
        b.iter(|| planner.route(black_box(start), &[goal]).unwrap())
    });
    // A goal shut in a box of walls: the search exhausts the ground it can
    // reach before it says where the way is closed.
    let (x, y) = (16.5, 3.5);
    let mut walls = world.walls();
    walls.extend([
        [x - 1.0, y - 1.0, x + 1.0, y - 1.0],
        [x + 1.0, y - 1.0, x + 1.0, y + 1.0],
        [x + 1.0, y + 1.0, x - 1.0, y + 1.0],
        [x - 1.0, y + 1.0, x - 1.0, y - 1.0],
    ]);
    let shut = twindrive_sim::World::from_walls(&walls, &world.blocks());
    let shut = RoutePlanner::new(&shut, &[], peer::FOOTPRINT_M, settings).unwrap();
    let goal_in_box = [x + 0.5, y + 0.5];
    assert!(
        matches!(
            shut.route(start, &[goal_in_box]),
            Err(twindrive_mission::route::Unreachable::Closed { .. })
        ),
        "the goal in the box is closed off"
    );
    group.bench_function("a goal shut in", |b| {
        b.iter(|| shut.route(black_box(start), &[goal_in_box]).unwrap_err())
    });
    group.bench_function("grid and way", |b| {
        b.iter(|| {
            RoutePlanner::new(&world, &[], peer::FOOTPRINT_M, settings)
                .unwrap()
                .route(start, &[goal])
                .unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, route);
criterion_main!(benches);
