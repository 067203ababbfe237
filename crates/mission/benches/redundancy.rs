//! Redundancy removal on wall-following paths at 2 cm per sample (the
//! generator in `examples/prune_peer.rs`): the fast pinch finder and the
//! whole removal at 10k, 100k and 1M samples (time per sample should stay
//! flat: the work grows like n, the spatial index being a hash), and the
//! fast finder against the paper's distance-matrix method at 4k samples
//! (the 20k-sample side by side with numpy is
//! `bench/prune_vs_distance_matrix.sh`).
//!
//! `cargo bench -p twindrive-mission --bench redundancy`

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use twindrive_mission::redundancy::{find_pinches, find_pinches_reference, remove_redundancy};

#[path = "../examples/prune_peer.rs"]
#[allow(dead_code)]
mod peer;

fn scaling(c: &mut Criterion) {
    let mut group = c.benchmark_group("redundancy");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(4));
    for n in [10_000, 100_000, 1_000_000] {
        let path = peer::wall_following_path(n, 1);
        let cfg = peer::bench_config(&path);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("find_pinches", n), &path, |b, path| {
            b.iter(|| black_box(find_pinches(path, &cfg).expect("valid path")))
        });
        group.bench_with_input(BenchmarkId::new("remove", n), &path, |b, path| {
            b.iter(|| black_box(remove_redundancy(path, &cfg).expect("valid path")))
        });
    }
    group.finish();
}

fn against_distance_matrix(c: &mut Criterion) {
    let n = 4_000;
    let path = peer::wall_following_path(n, 2);
    let cfg = peer::bench_config(&path);
    assert_eq!(
        find_pinches(&path, &cfg).expect("valid path"),
        find_pinches_reference(&path, &cfg).expect("fits in memory"),
    );
    let mut group = c.benchmark_group("pinches_4k");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(3));
    group.throughput(Throughput::Elements(n as u64));
    group.bench_function("grid_hash", |b| {
        b.iter(|| black_box(find_pinches(&path, &cfg).expect("valid path")))
    });
    group.bench_function("distance_matrix", |b| {
        b.iter(|| black_box(find_pinches_reference(&path, &cfg).expect("fits in memory")))
    });
    group.finish();
}

criterion_group!(benches, scaling, against_distance_matrix);
criterion_main!(benches);
