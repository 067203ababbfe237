//! One localization step: a 360-beam scan matched against a 20 m x 20 m
//! site (an outer wall, inner walls and 40 boxes; the lookup at 5 cm) from a
//! prior 5 cm and 2 degrees off. The target is 50 us, so a 100 Hz control
//! loop on a small robot computer has room.
//! `cargo bench -p twindrive-estimation --bench localize`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_estimation::localize::{MatchSettings, SegmentMap, match_points};
use twindrive_sim::{Vector, World};

fn site(rng: &mut ChaCha8Rng) -> Vec<[f64; 4]> {
    let mut walls = vec![
        [0.0, 0.0, 20.0, 0.0],
        [20.0, 0.0, 20.0, 20.0],
        [20.0, 20.0, 0.0, 20.0],
        [0.0, 20.0, 0.0, 0.0],
        [10.0, 0.0, 10.0, 8.0],
        [10.0, 12.0, 10.0, 20.0],
        [0.0, 10.0, 6.0, 10.0],
    ];
    for _ in 0..40 {
        let (x, y) = (rng.random_range(1.0..18.0), rng.random_range(1.0..18.0));
        let (w, h) = (rng.random_range(0.2..1.0), rng.random_range(0.2..1.0));
        walls.extend([
            [x, y, x + w, y],
            [x + w, y, x + w, y + h],
            [x + w, y + h, x, y + h],
            [x, y + h, x, y],
        ]);
    }
    walls
}

fn benches(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let walls = site(&mut rng);
    let world = World::from_walls(&walls, &[]);
    let settings = MatchSettings::default();
    let map = SegmentMap::new(&walls, 0.05, settings.outlier_m + 0.05);
    // A pose clear of everything, and its scan (8 m lidar, 1 cm noise).
    let truth = loop {
        let p = [
            rng.random_range(2.0..18.0),
            rng.random_range(2.0..18.0),
            0.7,
        ];
        if world.clearance_m(p[0], p[1], 1.0) > 0.5 {
            break p;
        }
    };
    let points: Vec<[f64; 2]> = (0..360)
        .filter_map(|i| {
            let a = i as f64 * std::f64::consts::TAU / 360.0;
            let dir = Vector::new((truth[2] + a).cos(), (truth[2] + a).sin());
            let r = world.cast_ray(Vector::new(truth[0], truth[1]), dir, 8.0);
            (r < 8.0).then(|| {
                let r = r + rng.random_range(-0.01..0.01);
                [r * a.cos(), r * a.sin()]
            })
        })
        .collect();
    let prior = [truth[0] + 0.05, truth[1] - 0.04, truth[2] + 0.035];
    let m = match_points(&map, &points, prior, &settings).expect("a match");
    assert!((m.pose[0] - truth[0]).hypot(m.pose[1] - truth[1]) < 0.01);
    let mut group = c.benchmark_group("localize");
    group.bench_function("scan_360_beams_20x20m_map", |b| {
        b.iter(|| black_box(match_points(&map, black_box(&points), prior, &settings)))
    });
    group.bench_function("lookup_build_20x20m_at_5cm", |b| {
        b.iter(|| black_box(SegmentMap::new(black_box(&walls), 0.05, 0.3)))
    });
    group.finish();
}

criterion_group!(localize, benches);
criterion_main!(localize);
