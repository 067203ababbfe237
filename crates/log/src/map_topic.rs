//! The world a log was made in, as the `/map` topic of an MCAP file, so the
//! log opens in Foxglove (or Lichtblick) with its walls: walls as one
//! `foxglove.SceneUpdate` line list and solid boxes as cubes in frame
//! `world`, and an occupancy grid, when there is one, as `foxglove.Grid`
//! on `/map/grid` (one `uint8` field `occupancy`: 0 free, 100 occupied, 255
//! unknown; row 0 at the bottom, as map_server's origin has it). Both are
//! written once, at time zero.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use serde_json::{Value, json};

/// An occupancy grid for `/map/grid`.
#[derive(Debug, Clone, PartialEq)]
pub struct MapGrid {
    pub width: u32,
    pub height: u32,
    pub resolution_m: f64,
    /// x, y (m) and yaw (rad) of the lower-left corner of cell (0, 0).
    pub origin: [f64; 3],
    /// Row-major from the bottom row: 0 free, 100 occupied, 255 unknown.
    pub cells: Vec<u8>,
}

/// What `/map` draws.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WorldMap {
    /// Walls: x0, y0, x1, y1 (m).
    pub segments: Vec<[f64; 4]>,
    /// Solid boxes: min x, min y, max x, max y (m).
    pub boxes: Vec<[f64; 4]>,
    pub grid: Option<MapGrid>,
}

/// Wall height and thickness drawn (m): a floor plan, seen from above.
const WALL_HEIGHT_M: f64 = 0.3;
const WALL_THICKNESS_M: f64 = 0.03;

fn identity_pose(x: f64, y: f64, z: f64) -> Value {
    json!({"position": {"x": x, "y": y, "z": z}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}})
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Value {
    json!({"r": r, "g": g, "b": b, "a": a})
}

/// The `foxglove.SceneUpdate` message of `map`.
pub fn scene_update(map: &WorldMap) -> Value {
    let zero = json!({"sec": 0, "nsec": 0});
    let points: Vec<Value> = map
        .segments
        .iter()
        .flat_map(|[x0, y0, x1, y1]| {
            [
                json!({"x": x0, "y": y0, "z": 0.0}),
                json!({"x": x1, "y": y1, "z": 0.0}),
            ]
        })
        .collect();
    let cubes: Vec<Value> = map
        .boxes
        .iter()
        .map(|[x0, y0, x1, y1]| {
            json!({
                "pose": identity_pose((x0 + x1) / 2.0, (y0 + y1) / 2.0, WALL_HEIGHT_M / 2.0),
                "size": {"x": x1 - x0, "y": y1 - y0, "z": WALL_HEIGHT_M},
                "color": color(0.35, 0.35, 0.35, 1.0),
            })
        })
        .collect();
    json!({
        "deletions": [],
        "entities": [{
            "timestamp": zero,
            "frame_id": "world",
            "id": "map",
            "lifetime": zero,
            "frame_locked": false,
            "metadata": [],
            "arrows": [], "spheres": [], "cylinders": [], "triangles": [], "texts": [], "models": [],
            "lines": [{
                "type": 2,
                "pose": identity_pose(0.0, 0.0, 0.0),
                "thickness": WALL_THICKNESS_M,
                "scale_invariant": false,
                "points": points,
                "color": color(0.1, 0.1, 0.1, 1.0),
                "colors": [],
                "indices": [],
            }],
            "cubes": cubes,
        }],
    })
}

/// The `foxglove.Grid` message of `grid` (its data base64, as Foxglove's
/// JSON encoding has bytes).
pub fn grid_message(grid: &MapGrid) -> Value {
    let (s, c) = (grid.origin[2] / 2.0).sin_cos();
    json!({
        "timestamp": {"sec": 0, "nsec": 0},
        "frame_id": "world",
        "pose": {
            "position": {"x": grid.origin[0], "y": grid.origin[1], "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": s, "w": c},
        },
        "column_count": grid.width,
        "cell_size": {"x": grid.resolution_m, "y": grid.resolution_m},
        "row_stride": grid.width,
        "cell_stride": 1,
        "fields": [{"name": "occupancy", "offset": 0, "type": 1}],
        "data": base64(&grid.cells),
    })
}

/// Standard base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(A[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn schema(title: &str) -> Vec<u8> {
    // A permissive JSON schema naming the Foxglove type: Foxglove picks its
    // renderer by the schema name.
    serde_json::to_vec(&json!({"title": title, "type": "object"})).expect("static schema")
}

/// Adds `/map` (and `/map/grid`) with their one message at time zero.
pub fn write_map<W: Write + Seek>(w: &mut mcap::Writer<W>, map: &WorldMap) -> mcap::McapResult<()> {
    let none = BTreeMap::new();
    let put = |w: &mut mcap::Writer<W>, topic: &str, name: &str, msg: Value| {
        let s = w.add_schema(name, "jsonschema", &schema(name))?;
        let ch = w.add_channel(s, topic, "json", &none)?;
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: 0,
            log_time: 0,
            publish_time: 0,
        };
        w.write_to_known_channel(&header, &serde_json::to_vec(&msg).expect("json"))
    };
    put(w, "/map", "foxglove.SceneUpdate", scene_update(map))?;
    if let Some(grid) = &map.grid {
        put(w, "/map/grid", "foxglove.Grid", grid_message(grid))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_rfc_examples() {
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), coded);
        }
    }

    #[test]
    fn a_log_with_its_map_reads_back_the_same_and_carries_the_walls() {
        let log = crate::testutil::sample_log();
        let map = WorldMap {
            segments: vec![[0.0, 0.0, 6.0, 0.0], [6.0, 0.0, 6.0, 5.0]],
            boxes: vec![],
            grid: Some(MapGrid {
                width: 3,
                height: 2,
                resolution_m: 0.05,
                origin: [-1.0, -2.0, 0.0],
                cells: vec![0, 100, 255, 0, 0, 100],
            }),
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.mcap");
        let mut bytes = std::io::Cursor::new(Vec::new());
        crate::write_mcap_with_map(&log, Some(&map), &mut bytes).unwrap();
        std::fs::write(&path, bytes.get_ref()).unwrap();
        // (NaN readings: compared as text.)
        assert_eq!(
            format!("{:?}", crate::read_mcap(&path).unwrap()),
            format!("{log:?}")
        );
        let data = std::fs::read(&path).unwrap();
        let mut topics = Vec::new();
        for m in mcap::MessageStream::new(&data).unwrap() {
            let m = m.unwrap();
            if m.channel.topic.starts_with("/map") {
                let v: Value = serde_json::from_slice(&m.data).unwrap();
                assert_eq!(m.log_time, 0);
                match m.channel.topic.as_str() {
                    "/map" => {
                        let points = &v["entities"][0]["lines"][0]["points"];
                        assert_eq!(points.as_array().unwrap().len(), 4);
                        assert_eq!(
                            m.channel.schema.as_ref().unwrap().name,
                            "foxglove.SceneUpdate"
                        );
                    }
                    _ => {
                        assert_eq!(v["data"], base64(&[0, 100, 255, 0, 0, 100]));
                        assert_eq!(v["column_count"], 3);
                    }
                }
                topics.push(m.channel.topic.clone());
            }
        }
        assert_eq!(topics, ["/map", "/map/grid"]);
    }

    #[test]
    fn walls_become_one_line_list() {
        let map = WorldMap {
            segments: vec![[0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 1.0, 2.0]],
            boxes: vec![[0.2, 0.2, 0.4, 0.6]],
            grid: None,
        };
        let v = scene_update(&map);
        let lines = &v["entities"][0]["lines"][0];
        assert_eq!(lines["type"], 2);
        assert_eq!(lines["points"].as_array().unwrap().len(), 4);
        let cube = &v["entities"][0]["cubes"][0];
        assert!((cube["size"]["y"].as_f64().unwrap() - 0.4).abs() < 1e-12);
    }
}
