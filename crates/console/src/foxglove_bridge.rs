//! `--foxglove ADDR`: the console's live streams through the Foxglove SDK's
//! WebSocket server, so a Foxglove or Lichtblick user can attach next to
//! (or instead of) the console's page. Topics, all in frame `world`, stamped
//! with Unix time:
//!
//! - `/map` (`foxglove.SceneUpdate`): the twin's walls and boxes, and the
//!   blocks the twin learnt from each robot; `/map/grid` (`foxglove.Grid`)
//!   for a map_server world. Sent again every second, for late joiners.
//! - `/twin/pose` (`foxglove.PoseInFrame`) and `/twin/scan/<sensor>`
//!   (`foxglove.LaserScan`, the latest reading of every beam, the sensor's
//!   pose in the world).
//! - `/robots/<id>/pose` (the robot's reported pose) and
//!   `/robots/<id>/predicted` (the twin's prediction for the same plan
//!   time), `foxglove.PoseInFrame`.

use std::net::SocketAddr;

use foxglove::schemas::{
    Color, CubePrimitive, Grid, LaserScan, LinePrimitive, PackedElementField, Point3, Pose,
    PoseInFrame, Quaternion, SceneEntity, SceneUpdate, Timestamp, Vector2, Vector3,
};
use foxglove::{Channel, ChannelBuilder, Context, WebSocketServer, WebSocketServerHandle};
use twindrive_sim::Scenario;

use crate::core::Core;

const FRAME: &str = "world";

fn quat(yaw: f64) -> Quaternion {
    let (s, c) = (yaw / 2.0).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

fn pose(x: f64, y: f64, z: f64, yaw: f64) -> Pose {
    Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(quat(yaw)),
    }
}

fn stamp(unix_ns: u64) -> Timestamp {
    Timestamp::new(
        (unix_ns / 1_000_000_000) as u32,
        (unix_ns % 1_000_000_000) as u32,
    )
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

fn cube(min: [f64; 2], max: [f64; 2], color: Color) -> CubePrimitive {
    CubePrimitive {
        pose: Some(pose(
            (min[0] + max[0]) / 2.0,
            (min[1] + max[1]) / 2.0,
            0.15,
            0.0,
        )),
        size: Some(Vector3 {
            x: max[0] - min[0],
            y: max[1] - min[1],
            z: 0.3,
        }),
        color: Some(color),
    }
}

/// The Foxglove side of a running console.
pub struct Bridge {
    /// The server holds its context weakly: the bridge keeps it alive.
    _context: std::sync::Arc<Context>,
    handle: Option<WebSocketServerHandle>,
    map: Channel<SceneUpdate>,
    grid: Option<(Channel<Grid>, Grid)>,
    walls: SceneEntity,
    twin_pose: Channel<PoseInFrame>,
    scans: Vec<Channel<LaserScan>>,
    robots: Vec<(Channel<PoseInFrame>, Channel<PoseInFrame>)>,
    next_map_ns: u64,
}

impl Bridge {
    /// Starts the server on `addr` with channels for the twin of `scenario`
    /// and the robots `ids`.
    pub async fn start(
        addr: SocketAddr,
        scenario: &Scenario,
        ids: &[String],
    ) -> anyhow::Result<Self> {
        let ctx = Context::new();
        let handle = WebSocketServer::new()
            .name("twindrive console")
            .bind(addr.ip().to_string(), addr.port())
            .context(&ctx)
            .start()
            .await
            .map_err(|e| anyhow::anyhow!("--foxglove {addr}: {e}"))?;
        let channel = |topic: &str| ChannelBuilder::new(topic).context(&ctx);
        let map = scenario.world.log_map();
        let mut points = Vec::new();
        for [x0, y0, x1, y1] in &map.segments {
            points.push(Point3 {
                x: *x0,
                y: *y0,
                z: 0.0,
            });
            points.push(Point3 {
                x: *x1,
                y: *y1,
                z: 0.0,
            });
        }
        let walls = SceneEntity {
            frame_id: FRAME.into(),
            id: "twin".into(),
            lines: vec![LinePrimitive {
                r#type: 2, // line list
                pose: Some(pose(0.0, 0.0, 0.0, 0.0)),
                thickness: 0.03,
                scale_invariant: false,
                points,
                color: Some(rgba(0.1, 0.1, 0.1, 1.0)),
                ..Default::default()
            }],
            cubes: map
                .boxes
                .iter()
                .map(|b| cube([b[0], b[1]], [b[2], b[3]], rgba(0.35, 0.35, 0.35, 1.0)))
                .collect(),
            ..Default::default()
        };
        let grid = map.grid.as_ref().map(|g| {
            (
                channel("/map/grid").build::<Grid>(),
                Grid {
                    frame_id: FRAME.into(),
                    pose: Some(pose(g.origin[0], g.origin[1], 0.0, g.origin[2])),
                    column_count: g.width,
                    cell_size: Some(Vector2 {
                        x: g.resolution_m,
                        y: g.resolution_m,
                    }),
                    row_stride: g.width,
                    cell_stride: 1,
                    fields: vec![PackedElementField {
                        name: "occupancy".into(),
                        offset: 0,
                        r#type: 1, // uint8
                    }],
                    data: g.cells.clone().into(),
                    ..Default::default()
                },
            )
        });
        Ok(Self {
            map: channel("/map").build(),
            grid,
            walls,
            twin_pose: channel("/twin/pose").build(),
            scans: scenario
                .range_sensors
                .iter()
                .map(|s| channel(&format!("/twin/scan/{}", s.info.name)).build())
                .collect(),
            robots: ids
                .iter()
                .map(|id| {
                    (
                        channel(&format!("/robots/{id}/pose")).build(),
                        channel(&format!("/robots/{id}/predicted")).build(),
                    )
                })
                .collect(),
            next_map_ns: 0,
            handle: Some(handle),
            _context: ctx,
        })
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.handle.as_ref().map_or(0, WebSocketServerHandle::port)
    }

    /// Publishes the picture now (`unix_ns`: the stamp).
    pub fn publish(&mut self, core: &Core, unix_ns: u64) {
        let ts = Some(stamp(unix_ns));
        let pose_msg = |p: [f64; 3]| PoseInFrame {
            timestamp: ts,
            frame_id: FRAME.into(),
            pose: Some(pose(p[0], p[1], 0.0, p[2])),
        };
        let robots: Vec<_> = core.robots.iter().map(|r| r.lock().poses()).collect();
        if unix_ns >= self.next_map_ns {
            self.next_map_ns = unix_ns + 1_000_000_000;
            let mut walls = self.walls.clone();
            walls.timestamp = ts;
            let learnt = robots
                .iter()
                .zip(&core.robots)
                .map(|((_, _, blocks), slot)| SceneEntity {
                    timestamp: ts,
                    frame_id: FRAME.into(),
                    id: format!("learnt/{}", slot.lock().id),
                    cubes: blocks
                        .iter()
                        .map(|(min, max)| cube(*min, *max, rgba(0.8, 0.2, 0.2, 0.7)))
                        .collect(),
                    ..Default::default()
                });
            self.map.log_with_time(
                &SceneUpdate {
                    deletions: Vec::new(),
                    entities: std::iter::once(walls).chain(learnt).collect(),
                },
                unix_ns,
            );
            if let Some((channel, grid)) = &self.grid {
                let mut g = grid.clone();
                g.timestamp = ts;
                channel.log_with_time(&g, unix_ns);
            }
        }
        let ws = &core.ws;
        let p = ws.pose();
        self.twin_pose
            .log_with_time(&pose_msg([p.x_m, p.y_m, p.heading_rad]), unix_ns);
        let ranges = ws.ranges();
        let mut k = 0;
        for (channel, s) in self.scans.iter().zip(&ws.scenario().range_sensors) {
            let info = &s.info;
            let n = info.beams as usize;
            let (first, last) = (info.beam_angle_rad(0), info.beam_angle_rad(info.beams - 1));
            let [x, y, heading] = ws.mount_in_world(info);
            channel.log_with_time(
                &LaserScan {
                    timestamp: ts,
                    frame_id: FRAME.into(),
                    pose: Some(pose(x, y, 0.05, heading)),
                    start_angle: first,
                    end_angle: last,
                    ranges: ranges[k..k + n].to_vec(),
                    intensities: Vec::new(),
                },
                unix_ns,
            );
            k += n;
        }
        for ((reported, predicted), (r, q, _)) in self.robots.iter().zip(&robots) {
            if let Some(r) = r {
                reported.log_with_time(&pose_msg(*r), unix_ns);
            }
            if let Some(q) = q {
                predicted.log_with_time(&pose_msg(*q), unix_ns);
            }
        }
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        // Stops accepting; open connections close with the runtime.
        if let Some(h) = self.handle.take() {
            drop(h.stop());
        }
    }
}
