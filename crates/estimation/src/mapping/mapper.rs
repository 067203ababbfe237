//! Where the robot was while it drew the map: each scan matched against
//! the map drawn so far ([`PointMap`], the project's one matcher), from
//! the pose the calibrated odometry predicts since the last scan. A drive
//! that comes back to where it started is matched against the walls it
//! drew on the way out, so it does not draw them a second time.
//!
//! Then the occupancy grid: each scan's beams from the pose found, each
//! return drawn where the surface it fell on lies. [`Surfaces`] averages
//! every return of the drive at its final pose per voxel, so a return is
//! moved onto the local line of its nearest surface point (when it lies
//! within `snap_m` of it): the walls are drawn a cell thick where the raw
//! returns, 1-3 cm of noise either side, would mark the cells behind the
//! wall occupied too.

use crate::localize::{MatchSettings, PointMap, Refusal, Scan, ScanMatch, register};

use super::grid::{Beam, LogOdds, LogOddsGrid};
use crate::se2::{apply, between, compose, inverse, wrap};

/// A return that lies on no line is drawn only where the surface point
/// near it averages at least this many returns.
const MIN_SUPPORT: u32 = 3;

/// How a map is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MappingSettings {
    /// The occupancy grid's cell (m).
    pub resolution_m: f64,
    /// The matcher's map averages returns per voxel of this size (m).
    pub voxel_m: f64,
    /// A scan adds its points to the matcher's map once the robot has
    /// moved this far (m) or turned this much (rad) since the last that did,
    /// if at least `novel_fraction` of its returns lie farther than
    /// `novel_m` from every map point (it sees something new), or the robot
    /// has moved `refresh_m` since (the map's averages keep improving).
    pub keyframe_m: f64,
    pub keyframe_rad: f64,
    pub novel_m: f64,
    pub novel_fraction: f64,
    pub refresh_m: f64,
    /// After this much travel (m) with no match, a scan's points are added
    /// from the odometry's pose, so a drive into a place the map has not
    /// seen (a new room through a door) keeps drawing.
    pub bridge_m: f64,
    /// A match that moves the odometry's prediction further than this (m,
    /// rad) is not believed.
    pub max_correction_m: f64,
    pub max_correction_rad: f64,
    pub matching: MatchSettings,
    /// A return within this of the map's local line is drawn on it (m).
    pub snap_m: f64,
    /// A drive is located by the SLAM (and then, with a prior map, placed
    /// on it).
    pub slam: crate::slam::SlamSettings,
    /// How a drive is placed on a prior map.
    pub placement: super::PlacementSettings,
    /// Returns farther than this are left out of the grid (m): their
    /// angular error spreads them over several cells.
    pub max_range_m: f64,
    pub log_odds: LogOdds,
}

impl Default for MappingSettings {
    fn default() -> Self {
        Self {
            resolution_m: 0.05,
            voxel_m: 0.025,
            keyframe_m: 0.1,
            keyframe_rad: 0.1,
            novel_m: 0.1,
            novel_fraction: 0.02,
            refresh_m: 1.0,
            bridge_m: 0.5,
            max_correction_m: 0.3,
            max_correction_rad: 0.2,
            matching: MatchSettings {
                // A map being drawn has places it has not seen yet: the
                // matcher keeps the directions the map pins and leaves the
                // rest to the odometry, rather than refusing.
                min_information_ratio: 0.0,
                ..MatchSettings::scan_to_scan()
            },
            snap_m: 0.1,
            slam: crate::slam::SlamSettings::default(),
            placement: super::PlacementSettings::default(),
            max_range_m: 10.0,
            log_odds: LogOdds::default(),
        }
    }
}

/// Where one scan was taken, and how that was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// The robot's pose in the map's frame (x, y in m, heading in rad).
    pub pose: [f64; 3],
    /// The match against the map, or why there was none (the pose is then
    /// the odometry's prediction).
    pub matched: Result<ScanMatch, MatchFailure>,
}

/// Why a scan's pose is the odometry's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MatchFailure {
    /// The first scan: it defines the map.
    First,
    Refused(Refusal),
    /// The match moved the prediction by more than the settings allow.
    TooFar {
        moved_m: f64,
        turned_rad: f64,
    },
}

impl std::fmt::Display for MatchFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::First => write!(f, "the first scan"),
            Self::Refused(r) => write!(f, "{r}"),
            Self::TooFar {
                moved_m,
                turned_rad,
            } => write!(
                f,
                "the match moved the odometry's pose by {:.2} m and {:.1} deg, more than believed",
                moved_m,
                turned_rad.to_degrees()
            ),
        }
    }
}

/// The poses of a drive in the map being drawn.
#[derive(Debug)]
pub struct Mapper {
    settings: MappingSettings,
    /// The lidar's pose on the robot.
    mount: [f64; 3],
    points: PointMap,
    /// The last scan's odometry pose and map pose.
    last: Option<([f64; 3], [f64; 3])>,
    /// Where the last scan that added points was taken.
    last_key: Option<[f64; 3]>,
    /// Travel since the last match (m).
    unmatched_m: f64,
}

impl Mapper {
    /// A mapper for a lidar mounted at `mount` (x, y, heading on the robot).
    pub fn new(mount: [f64; 3], settings: MappingSettings) -> Self {
        Self {
            settings,
            mount,
            points: PointMap::new(settings.voxel_m, settings.matching.outlier_m),
            last: None,
            last_key: None,
            unmatched_m: 0.0,
        }
    }

    /// A mapper that starts from a map already drawn (its occupied cells'
    /// centres): the drive is located in that map's frame from its first
    /// scan, and the odometry's first pose must be in that frame too.
    pub fn with_map(mount: [f64; 3], settings: MappingSettings, points: &[[f64; 2]]) -> Self {
        let mut m = Self::new(mount, settings);
        m.points.extend(points.iter().copied());
        m
    }

    /// The matcher's map: voxel-averaged returns.
    pub fn points(&self) -> &PointMap {
        &self.points
    }

    /// The next scan, with the robot's pose by odometry at its time
    /// (any frame; the first scan's odometry pose is its map pose).
    pub fn locate(&mut self, odometry: [f64; 3], scan: &Scan) -> Located {
        let predicted = match self.last {
            None => odometry,
            Some((o, m)) => compose(m, between(o, odometry)),
        };
        if let Some((o, _)) = self.last {
            self.unmatched_m += (odometry[0] - o[0]).hypot(odometry[1] - o[1]);
        }
        let points = scan.points();
        let matched = if self.points.is_empty() {
            Err(MatchFailure::First)
        } else {
            let prior = compose(predicted, self.mount);
            match register(&self.points, &points, prior, &self.settings.matching) {
                Err(r) => Err(MatchFailure::Refused(r)),
                Ok(m) => {
                    let moved_m = (m.pose[0] - prior[0]).hypot(m.pose[1] - prior[1]);
                    let turned_rad = wrap(m.pose[2] - prior[2]).abs();
                    if moved_m > self.settings.max_correction_m
                        || turned_rad > self.settings.max_correction_rad
                    {
                        Err(MatchFailure::TooFar {
                            moved_m,
                            turned_rad,
                        })
                    } else {
                        Ok(m)
                    }
                }
            }
        };
        let pose = match &matched {
            Ok(m) => compose(m.pose, inverse(self.mount)),
            Err(_) => predicted,
        };
        if matched.is_ok() {
            self.unmatched_m = 0.0;
        }
        self.last = Some((odometry, pose));
        let sensor = compose(pose, self.mount);
        let add = match matched {
            Ok(_) => self.last_key.is_none_or(|k| {
                let moved = (pose[0] - k[0]).hypot(pose[1] - k[1]);
                (moved >= self.settings.keyframe_m
                    || wrap(pose[2] - k[2]).abs() >= self.settings.keyframe_rad)
                    && (moved >= self.settings.refresh_m || self.novel(sensor, &points))
            }),
            Err(MatchFailure::First) => true,
            Err(_) => self.unmatched_m >= self.settings.bridge_m,
        };
        if add {
            self.points.extend(points.iter().map(|p| apply(sensor, *p)));
            self.last_key = Some(pose);
            self.unmatched_m = 0.0;
        }
        Located { pose, matched }
    }

    /// Whether enough of `points` (sensor frame, the sensor at `sensor`)
    /// lie away from every map point to be something new.
    fn novel(&self, sensor: [f64; 3], points: &[[f64; 2]]) -> bool {
        let needed = (self.settings.novel_fraction * points.len() as f64).ceil() as usize;
        let mut new = 0;
        for p in points {
            let w = apply(sensor, *p);
            if self
                .points
                .distance_to_nearest(w[0], w[1])
                .is_none_or(|d| d > self.settings.novel_m)
            {
                new += 1;
                if new >= needed.max(1) {
                    return true;
                }
            }
        }
        false
    }
}

/// The surfaces a drive saw: every return at its scan's final pose,
/// averaged per voxel, each with the line its neighbours lie along. What
/// the grid is drawn from.
#[derive(Debug)]
pub struct Surfaces {
    settings: MappingSettings,
    mount: [f64; 3],
    points: PointMap,
    /// Whether each point, where it lies on no line, is drawn: it averages
    /// at least [`MIN_SUPPORT`] returns and a quarter of the most any point
    /// within three voxels does (the tails of the range noise behind a
    /// corner are not).
    drawn: Vec<bool>,
}

impl Surfaces {
    /// The surfaces of `scans` taken at `poses` (the robot's, in the map).
    pub fn new(
        scans: &[(Scan, [f64; 3])],
        poses: &[[f64; 3]],
        mount: [f64; 3],
        settings: MappingSettings,
    ) -> Self {
        let mut points = PointMap::new(settings.voxel_m, settings.matching.outlier_m);
        points.extend(scans.iter().zip(poses).flat_map(|((scan, _), pose)| {
            let sensor = compose(*pose, mount);
            scan.endpoints().flatten().map(move |p| apply(sensor, p))
        }));
        let counts = points.counts();
        let drawn = points
            .points()
            .iter()
            .zip(counts)
            .map(|(p, &n)| {
                let mut most = n;
                points.within(p[0], p[1], 3.0 * settings.voxel_m, |i| {
                    most = most.max(counts[i]);
                });
                n >= MIN_SUPPORT && 4 * n >= most
            })
            .collect();
        Self {
            settings,
            mount,
            points,
            drawn,
        }
    }

    /// No surfaces: every return is drawn where it fell.
    pub fn none(mount: [f64; 3], settings: MappingSettings) -> Self {
        Self {
            settings,
            mount,
            points: PointMap::new(settings.voxel_m, settings.matching.outlier_m),
            drawn: Vec::new(),
        }
    }

    /// Draws one scan taken at `pose` (the robot's, in the map) into
    /// `grid`: each return moved onto the local line of the surface it fell
    /// on, and the cells its beam crossed cleared only where the beam ran
    /// more than a cell from that surface. A return on no line is drawn where
    /// the returns near it average, if enough fell there; a stray one (noise
    /// past a corner) is not drawn, though its beam clears what it crossed.
    pub fn draw(&self, grid: &mut LogOddsGrid, pose: [f64; 3], scan: &Scan) {
        let sensor = compose(pose, self.mount);
        let origin = [sensor[0], sensor[1]];
        let max_sq = self.settings.max_range_m * self.settings.max_range_m;
        let cell = self.settings.resolution_m;
        let beams: Vec<Beam> = scan
            .endpoints()
            .flatten()
            .filter(|p| p[0] * p[0] + p[1] * p[1] <= max_sq)
            .map(|p| {
                let w = apply(sensor, p);
                let (d, r) = {
                    let (dx, dy) = (w[0] - origin[0], w[1] - origin[1]);
                    let r = dx.hypot(dy);
                    ([dx / r, dy / r], r)
                };
                let back_by = |back: f64| {
                    let back = back.min(r);
                    [w[0] - back * d[0], w[1] - back * d[1]]
                };
                match self.points.nearest(w[0], w[1]) {
                    // On a wall: drawn on its line; cleared up to where the
                    // beam comes within a cell of it.
                    Some((_, a, _)) if a.normal != [0.0, 0.0] => {
                        let (res, g) = a.residual(w);
                        if res.abs() > self.settings.snap_m {
                            return Beam { end: w, free_to: w };
                        }
                        let end = [w[0] - res * g[0], w[1] - res * g[1]];
                        let incidence = (d[0] * g[0] + d[1] * g[1]).abs().max(1e-3);
                        let back = (cell / incidence).min(r);
                        Beam {
                            end,
                            free_to: [end[0] - back * d[0], end[1] - back * d[1]],
                        }
                    }
                    // A corner or clutter seen often enough: drawn where
                    // its returns average.
                    Some((i, a, _))
                        if self.drawn[i]
                            && (a.at[0] - w[0]).hypot(a.at[1] - w[1]) <= self.settings.snap_m =>
                    {
                        Beam {
                            end: a.at,
                            free_to: back_by(2.0 * cell),
                        }
                    }
                    // A stray return (noise beyond a wall's corner): the
                    // beam clears what it crossed, short of it, and marks
                    // nothing.
                    Some(_) => Beam {
                        end: [f64::NAN, f64::NAN],
                        free_to: back_by(2.0 * cell),
                    },
                    None => Beam { end: w, free_to: w },
                }
            })
            .collect();
        grid.integrate_beams(origin, &beams);
    }
}

/// A drive mapped: the robot's pose at each scan, the grid, and how the
/// poses were found.
#[derive(Debug, Clone)]
pub struct Mapping {
    pub poses: Vec<[f64; 3]>,
    pub grid: LogOddsGrid,
    /// Scans matched against the map.
    pub matched: usize,
    /// Whether each scan matched the map (the first of a drive with no
    /// prior map has nothing to match and does not).
    pub matched_each: Vec<bool>,
    /// Scans left at the odometry's pose, counted by reason (the first
    /// scan is not counted).
    pub unmatched: Vec<(String, usize)>,
    /// Each match's RMS residual (m), in scan order.
    pub rms_m: Vec<f64>,
    /// Where the drive was placed on the prior map (none without one, or
    /// when it matched nowhere on it).
    pub placement: Option<super::Placement>,
    /// With a prior map: how well the whole drive, located, agrees with it
    /// ([`super::drive_agreement`]).
    pub prior_agreement: Option<f64>,
    /// What the SLAM that located the drive did: its loop closures, those
    /// switched off, the loops it saw but did not take.
    pub slam: crate::slam::SlamStats,
}

/// Maps a drive: `scans` with the robot's odometry pose at each, in time
/// order. `prior` is a map already drawn of the same site, in the frame
/// the odometry's first pose is in, which the drive extends. Calls
/// `progress(done, total)` as it goes (two passes over the scans, three
/// with a prior).
///
/// With a prior, the drive is located by the SLAM (as without a prior),
/// placed on the prior ([`super::place`]: near where it says it started,
/// else anywhere), then each scan is located against the prior's occupied
/// cells from its SLAM pose carried there. A map of cell centres places
/// each scan only to within a fraction of a cell (a wall's cells all sit
/// in one row, wherever in it the wall is), so the poses are the drive's
/// own, carried onto the prior by the rigid motion that best takes them to
/// the poses located against it, over the scans that matched it. The
/// matches reported are those against the prior.
pub fn map_drive(
    scans: &[(Scan, [f64; 3])],
    mount: [f64; 3],
    settings: MappingSettings,
    prior: Option<&LogOddsGrid>,
    mut progress: impl FnMut(usize, usize),
) -> Mapping {
    let passes = if prior.is_some() { 3 } else { 2 };
    let total = passes * scans.len();
    let mut placement = None;
    let slam_stats;
    let located = match prior {
        None => {
            let slam =
                crate::slam::locate_drive(scans, mount, settings.slam, |k, _| progress(k, total));
            slam_stats = slam.stats;
            DriveLocated {
                matched: slam.matched_each.iter().filter(|m| **m).count(),
                unmatched: match slam.matched_each.iter().skip(1).filter(|m| !**m).count() {
                    0 => Vec::new(),
                    n => vec![("not matched to its submap".to_string(), n)],
                },
                poses: slam.poses,
                matched_each: slam.matched_each,
                rms_m: slam.rms_m,
            }
        }
        Some(g) => {
            let slam =
                crate::slam::locate_drive(scans, mount, settings.slam, |k, _| progress(k, total));
            slam_stats = slam.stats;
            let own = slam.poses;
            let occupied = g.occupied_centres();
            placement = super::place(
                &occupied,
                scans,
                &own,
                mount,
                settings.max_range_m,
                &settings.placement,
            );
            // Unplaced, the drive stays where it says it started (its
            // first SLAM pose is its first odometry pose), and its scans
            // are matched there to say how far they disagree.
            let carry = placement.map_or([0.0; 3], |p| p.onto);
            let predicted: Vec<[f64; 3]> = own.iter().map(|p| compose(carry, *p)).collect();
            let against = locate_all(
                Mapper::with_map(mount, settings, &occupied),
                scans,
                &predicted,
                |k| progress(scans.len() + k, total),
            );
            let onto = rigid_fit(&own, &against.poses, &against.matched_each);
            let carried: Vec<[f64; 3]> = own.iter().map(|p| compose(onto, *p)).collect();
            DriveLocated {
                poses: held_to_prior(&own, carried, &against.poses, &against.matched_each),
                ..against
            }
        }
    };
    let prior_agreement = prior.map(|g| {
        super::drive_agreement(
            g,
            scans,
            &located.poses,
            mount,
            settings.max_range_m,
            &settings.placement,
        )
    });
    let mut grid = prior
        .cloned()
        .unwrap_or_else(|| LogOddsGrid::new(settings.resolution_m, settings.log_odds));
    // The grid's extent, once: every sensor pose and the range drawn.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &located.poses {
        let sensor = compose(*p, mount);
        for k in 0..2 {
            lo[k] = lo[k].min(sensor[k] - settings.max_range_m);
            hi[k] = hi[k].max(sensor[k] + settings.max_range_m);
        }
    }
    grid.reserve_m(lo, hi);
    let surfaces = Surfaces::new(scans, &located.poses, mount, settings);
    let drawn_from = (passes - 1) * scans.len();
    for (k, ((scan, _), pose)) in scans.iter().zip(&located.poses).enumerate() {
        surfaces.draw(&mut grid, *pose, scan);
        if k % 64 == 0 {
            progress(drawn_from + k, total);
        }
    }
    progress(total, total);
    Mapping {
        placement,
        prior_agreement,
        poses: located.poses,
        grid,
        matched: located.matched,
        matched_each: located.matched_each,
        unmatched: located.unmatched,
        rms_m: located.rms_m,
        slam: slam_stats,
    }
}

/// A drive's scans located by one mapper.
struct DriveLocated {
    poses: Vec<[f64; 3]>,
    matched: usize,
    matched_each: Vec<bool>,
    unmatched: Vec<(String, usize)>,
    rms_m: Vec<f64>,
}

/// Every scan located by `mapper`, each predicted by the motion from the
/// previous scan's `predicted` pose.
fn locate_all(
    mut mapper: Mapper,
    scans: &[(Scan, [f64; 3])],
    predicted: &[[f64; 3]],
    mut progress: impl FnMut(usize),
) -> DriveLocated {
    let mut out = DriveLocated {
        poses: Vec::with_capacity(scans.len()),
        matched: 0,
        matched_each: Vec::with_capacity(scans.len()),
        unmatched: Vec::new(),
        rms_m: Vec::new(),
    };
    for (k, ((scan, _), odometry)) in scans.iter().zip(predicted).enumerate() {
        let located = mapper.locate(*odometry, scan);
        out.matched_each.push(located.matched.is_ok());
        match located.matched {
            Ok(m) => {
                out.matched += 1;
                out.rms_m.push(m.rms_m);
            }
            Err(MatchFailure::First) => {}
            Err(f) => {
                let kind = match f {
                    MatchFailure::Refused(r) => r.kind(),
                    _ => "moved too far",
                };
                match out.unmatched.iter_mut().find(|(k, _)| k == kind) {
                    Some((_, n)) => *n += 1,
                    None => out.unmatched.push((kind.to_string(), 1)),
                }
            }
        }
        out.poses.push(located.pose);
        if k % 64 == 0 {
            progress(k);
        }
    }
    out
}

/// The drive's poses on the prior: its own shape (`own`, the SLAM's: each
/// step to within millimetres, drifting over a long drive) held to the
/// poses located against the prior where they matched (each to within a
/// fraction of the prior's cell, no drift), by a pose graph: a chain of the
/// SLAM's steps and, from a fixed origin, each matched pose, with a Huber
/// loss (a wrong match pulls with a bounded force). `start` is the rigid
/// placement, the solve's first guess; it is returned unchanged if the
/// solve fails or nothing matched.
fn held_to_prior(
    own: &[[f64; 3]],
    start: Vec<[f64; 3]>,
    against: &[[f64; 3]],
    matched: &[bool],
) -> Vec<[f64; 3]> {
    use crate::slam::{Edge, PoseGraph};
    if !matched.iter().any(|m| *m) {
        return start;
    }
    let mut graph = PoseGraph::default();
    graph.add_pose([0.0; 3]);
    for p in &start {
        graph.add_pose(*p);
    }
    for k in 1..own.len() {
        graph.add_edge(Edge {
            from: k,
            to: k + 1,
            measured: crate::se2::between(own[k - 1], own[k]),
            std: [0.005, 0.005, 0.002],
            huber: None,
            active: true,
        });
    }
    for (k, p) in against.iter().enumerate() {
        if matched[k] {
            graph.add_edge(Edge {
                from: 0,
                to: k + 1,
                measured: *p,
                std: [0.03, 0.03, 0.02],
                huber: Some(2.0),
                active: true,
            });
        }
    }
    // A step of the SLAM's that the prior contradicts by more than 10σ (a
    // scan the SLAM matched wrongly, out of line with its neighbours) is
    // loosened twentyfold and the graph solved again, so that scan
    // follows its match against the prior.
    let chain = own.len().saturating_sub(1);
    let solved = graph.optimize(30).and_then(|_| {
        let poses = graph.poses.clone();
        let mut loosened = 0;
        for e in graph.edges.iter_mut().take(chain) {
            if e.chi(&poses) > 10.0 {
                e.std = e.std.map(|s| 20.0 * s);
                loosened += 1;
            }
        }
        if loosened > 0 {
            graph.optimize(30)?;
        }
        Ok(())
    });
    match solved {
        Ok(()) => graph.poses[1..].to_vec(),
        // A chain anchored by one matched pose or more always factorises;
        // should it not, the rigid placement stands.
        Err(_) => start,
    }
}

/// The rigid motion `t` for which `t ⊕ from[i]` best matches `to[i]` over
/// the `use_[i]`: the mean turn, then the mean of what is left in
/// position (least squares for the positions given the turn). The
/// identity when none is used.
fn rigid_fit(from: &[[f64; 3]], to: &[[f64; 3]], use_: &[bool]) -> [f64; 3] {
    let pairs = || {
        from.iter()
            .zip(to)
            .zip(use_)
            .filter(|(_, u)| **u)
            .map(|(p, _)| p)
    };
    let n = pairs().count();
    if n == 0 {
        return [0.0, 0.0, 0.0];
    }
    let (s, c) = pairs().fold((0.0, 0.0), |(s, c), (a, b)| {
        let d = wrap(b[2] - a[2]);
        (s + d.sin(), c + d.cos())
    });
    let turn = s.atan2(c);
    let (sn, cs) = turn.sin_cos();
    let (mut x, mut y) = (0.0, 0.0);
    for (a, b) in pairs() {
        x += b[0] - (cs * a[0] - sn * a[1]);
        y += b[1] - (sn * a[0] + cs * a[1]);
    }
    [x / n as f64, y / n as f64, turn]
}
