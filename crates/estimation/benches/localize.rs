//! One localization step: a 360-beam scan matched against a 20 m x 20 m
//! site (an outer wall, inner walls and 40 boxes; the lookup at 5 cm) from a
//! prior 5 cm and 2 degrees off. The target is 50 us, so a 100 Hz control
//! loop on a small robot computer has room. Then laser odometry: the same
//! scan matched against the scan from 20 cm and 6 degrees back (the
//! reference built from its scan, then PL-ICP; target 60 us, a tenth of
//! Open3D's ICP on the same pairs: bench/scan_match_vs_open3d.sh), and
//! against a point map of four scans (kiddo's k-d tree).
//! `cargo bench -p twindrive-estimation --bench localize`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_estimation::localize::{
    MatchSettings, PointMap, Scan, ScanReference, SegmentMap, match_points, register,
};
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
    // The scan as the lidar reports it, and one from 20 cm and 6 degrees
    // back along the heading.
    let cast = |pose: [f64; 3], rng: &mut ChaCha8Rng| Scan {
        t_s: 0.0,
        angle_min_rad: 0.0,
        increment_rad: std::f64::consts::TAU / 360.0,
        range_min_m: 0.05,
        range_max_m: 8.0,
        ranges_m: (0..360)
            .map(|i| {
                let a = pose[2] + i as f64 * std::f64::consts::TAU / 360.0;
                let r = world.cast_ray(
                    Vector::new(pose[0], pose[1]),
                    Vector::new(a.cos(), a.sin()),
                    8.0,
                );
                if r < 8.0 {
                    (r + rng.random_range(-0.01..0.01)) as f32
                } else {
                    8.0
                }
            })
            .collect(),
    };
    let back = [
        truth[0] - 0.2 * truth[2].cos(),
        truth[1] - 0.2 * truth[2].sin(),
        truth[2] - 0.1,
    ];
    let previous = cast(back, &mut rng);
    let current = cast(truth, &mut rng).points();
    let odometry = [
        0.2 * 0.1f64.cos() + 0.03,
        -0.2 * 0.1f64.sin() - 0.02,
        0.1 + 0.03,
    ];
    let to_scan = MatchSettings::scan_to_scan();
    let reach = to_scan.outlier_m + 0.2;
    let m = register(
        &ScanReference::new(&previous, reach),
        &current,
        odometry,
        &to_scan,
    )
    .expect("a scan-to-scan match");
    assert!((m.pose[2] - 0.1).abs() < 0.01, "{:?}", m.pose);
    let mut point_map = PointMap::new(0.025, 0.4);
    for k in 0..4 {
        let pose = [truth[0] + 0.3 * k as f64, truth[1], truth[2]];
        let scan = cast(pose, &mut rng);
        point_map.extend(scan.points().into_iter().map(|p| {
            let (s, c) = pose[2].sin_cos();
            [pose[0] + c * p[0] - s * p[1], pose[1] + s * p[0] + c * p[1]]
        }));
    }
    register(&point_map, &current, prior, &to_scan).expect("a scan-to-map match");
    let m = match_points(&map, &points, prior, &settings).expect("a match");
    assert!((m.pose[0] - truth[0]).hypot(m.pose[1] - truth[1]) < 0.01);
    let mut group = c.benchmark_group("localize");
    group.bench_function("scan_360_beams_20x20m_map", |b| {
        b.iter(|| black_box(match_points(&map, black_box(&points), prior, &settings)))
    });
    group.bench_function("scan_to_scan_360_beams", |b| {
        b.iter(|| {
            let reference = ScanReference::new(black_box(&previous), reach);
            black_box(register(
                &reference,
                black_box(&current),
                odometry,
                &to_scan,
            ))
        })
    });
    group.bench_function("scan_to_point_map_360_beams", |b| {
        b.iter(|| black_box(register(&point_map, black_box(&current), prior, &to_scan)))
    });
    group.bench_function("lookup_build_20x20m_at_5cm", |b| {
        b.iter(|| black_box(SegmentMap::new(black_box(&walls), 0.05, 0.3)))
    });
    group.finish();
}

criterion_group!(localize, benches);
criterion_main!(localize);
