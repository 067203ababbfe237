//! One simulation step of the case-study robot (one IR + bump) and of the
//! ir-sim comparison setup (360-beam lidar, six obstacles).
//! `cargo bench -p twindrive-sim --bench step`

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use twindrive_sim::{Scenario, Simulator, StepOutput};

fn load(relative: &str) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(relative);
    let mut sc = Scenario::load(&path).expect("benchmark fixture loads");
    sc.steps = u64::MAX / 2; // never finishes during a benchmark
    sc
}

fn bench_step(c: &mut Criterion, name: &str, fixture: &str) {
    let mut sim = Simulator::new(load(fixture));
    let mut out = StepOutput::new(sim.beams());
    let mut group = c.benchmark_group("simulation_step");
    group.throughput(Throughput::Elements(1));
    group.bench_function(name, |b| {
        b.iter(|| {
            sim.step(&mut out);
            black_box(&out);
        })
    });
    group.finish();
}

fn steps(c: &mut Criterion) {
    bench_step(c, "wall_following_ir_bump", "scenarios/wall_following.toml");
    bench_step(c, "lidar_360_six_obstacles", "bench/irsim_setup.toml");
    bench_step(
        c,
        "no_sensor_six_obstacles",
        "bench/irsim_setup_nosensor.toml",
    );
    bench_step(c, "office_map_lidar_181", "scenarios/office_drive.toml");
}

criterion_group!(benches, steps);
criterion_main!(benches);
