//! ROS map_server occupancy maps (YAML + PGM/PNG): loading, conversion to
//! wall segments, and the small office map the project draws itself.

use std::path::{Path, PathBuf};

use parry2d_f64::math::Vector;
use parry2d_f64::shape::Segment;
use serde::{Deserialize, Serialize};

use crate::SimError;

/// The map_server YAML fields.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapYaml {
    pub image: PathBuf,
    pub resolution: f64,
    /// [x, y, yaw] of the lower-left pixel in the world.
    pub origin: [f64; 3],
    #[serde(default = "default_occupied")]
    pub occupied_thresh: f64,
    #[serde(default = "default_free")]
    pub free_thresh: f64,
    #[serde(default)]
    pub negate: u8,
    #[serde(default = "default_mode")]
    pub mode: String,
}

fn default_occupied() -> f64 {
    0.65
}
fn default_free() -> f64 {
    0.196
}
fn default_mode() -> String {
    "trinary".into()
}

/// Cell states after thresholding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cell {
    Free,
    Occupied,
    Unknown,
}

/// An occupancy grid; row 0 is the bottom row (lowest y), unlike the image.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    pub width: usize,
    pub height: usize,
    pub resolution_m: f64,
    pub origin_x_m: f64,
    pub origin_y_m: f64,
    pub origin_yaw_rad: f64,
    pub cells: Vec<Cell>,
}

impl OccupancyGrid {
    pub fn cell(&self, col: usize, row: usize) -> Cell {
        self.cells[row * self.width + col]
    }

    /// True for occupied and unknown cells, and outside the map: the robot
    /// must not go where the map does not say it is free.
    fn blocked(&self, col: i64, row: i64) -> bool {
        if col < 0 || row < 0 || col >= self.width as i64 || row >= self.height as i64 {
            return true;
        }
        self.cell(col as usize, row as usize) != Cell::Free
    }

    fn map_from_world(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = self.origin_yaw_rad.sin_cos();
        let (dx, dy) = (x - self.origin_x_m, y - self.origin_y_m);
        (c * dx + s * dy, -s * dx + c * dy)
    }

    fn world_from_map(&self, u: f64, v: f64) -> Vector {
        let (s, c) = self.origin_yaw_rad.sin_cos();
        Vector::new(
            self.origin_x_m + c * u - s * v,
            self.origin_y_m + s * u + c * v,
        )
    }

    /// Whether the world point lies in a blocked cell.
    pub fn blocked_at(&self, x: f64, y: f64) -> bool {
        let (u, v) = self.map_from_world(x, y);
        let col = (u / self.resolution_m).floor() as i64;
        let row = (v / self.resolution_m).floor() as i64;
        self.blocked(col, row)
    }

    /// Edges between blocked and free cells, merged into maximal straight runs.
    pub fn boundary_segments(&self) -> Vec<Segment> {
        let r = self.resolution_m;
        let (w, h) = (self.width as i64, self.height as i64);
        let mut out = Vec::new();
        // Horizontal edges on grid line `row`, between rows row-1 and row.
        let horizontal = |row: i64, col: i64| self.blocked(col, row - 1) != self.blocked(col, row);
        edge_runs(h, w, horizontal, |row, c0, c1| {
            let y = row as f64 * r;
            out.push(Segment::new(
                self.world_from_map(c0 as f64 * r, y),
                self.world_from_map(c1 as f64 * r, y),
            ));
        });
        // Vertical edges on grid line `col`, between columns col-1 and col.
        let vertical = |col: i64, row: i64| self.blocked(col - 1, row) != self.blocked(col, row);
        edge_runs(w, h, vertical, |col, r0, r1| {
            let x = col as f64 * r;
            out.push(Segment::new(
                self.world_from_map(x, r0 as f64 * r),
                self.world_from_map(x, r1 as f64 * r),
            ));
        });
        out
    }
}

/// Calls `emit(line, start, end)` for every maximal run of cells `k` in
/// `start..end` with `edge(line, k)`, on grid lines `0..=lines` of `len` cells.
fn edge_runs(
    lines: i64,
    len: i64,
    edge: impl Fn(i64, i64) -> bool,
    mut emit: impl FnMut(i64, i64, i64),
) {
    for line in 0..=lines {
        let mut start = None;
        for k in 0..=len {
            match (k < len && edge(line, k), start) {
                (true, None) => start = Some(k),
                (false, Some(s0)) => {
                    emit(line, s0, k);
                    start = None;
                }
                _ => {}
            }
        }
    }
}

/// Loads a map_server YAML and its image. Errors name the file and field.
pub fn load_map(yaml_path: &Path) -> Result<OccupancyGrid, SimError> {
    let text = std::fs::read_to_string(yaml_path).map_err(|e| SimError::Io {
        path: yaml_path.to_path_buf(),
        source: e,
    })?;
    let meta: MapYaml = serde_yaml_ng::from_str(&text).map_err(|e| SimError::Scenario {
        path: yaml_path.to_path_buf(),
        message: e.to_string(),
    })?;
    let field = |name: &str, msg: String| SimError::field(yaml_path, name, msg);
    if !(meta.resolution.is_finite() && meta.resolution > 0.0) {
        return Err(field(
            "resolution",
            format!("must be > 0 metres per pixel, got {}", meta.resolution),
        ));
    }
    if meta.origin.iter().any(|v| !v.is_finite()) {
        return Err(field(
            "origin",
            "must be three finite numbers [x, y, yaw]".into(),
        ));
    }
    if !(0.0..=1.0).contains(&meta.free_thresh)
        || !(0.0..=1.0).contains(&meta.occupied_thresh)
        || meta.free_thresh >= meta.occupied_thresh
    {
        return Err(field(
            "free_thresh",
            format!(
                "need 0 <= free_thresh < occupied_thresh <= 1, got {} and {}",
                meta.free_thresh, meta.occupied_thresh
            ),
        ));
    }
    if !matches!(meta.mode.as_str(), "trinary" | "scale" | "raw") {
        return Err(field(
            "mode",
            format!("expected trinary, scale or raw, got `{}`", meta.mode),
        ));
    }
    let image_path = yaml_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(&meta.image);
    let img = image::open(&image_path)
        .map_err(|e| {
            field(
                "image",
                format!("cannot load `{}`: {e}", image_path.display()),
            )
        })?
        .to_luma8();
    let (width, height) = (img.width() as usize, img.height() as usize);
    let mut cells = vec![Cell::Unknown; width * height];
    for (x, y, p) in img.enumerate_pixels() {
        let value = f64::from(p.0[0]);
        let cell = if meta.mode == "raw" {
            // Raw mode: the pixel value is the occupancy percentage.
            match value {
                v if v >= meta.occupied_thresh * 100.0 => Cell::Occupied,
                v if v <= meta.free_thresh * 100.0 => Cell::Free,
                _ => Cell::Unknown,
            }
        } else {
            let occ = if meta.negate != 0 {
                value / 255.0
            } else {
                (255.0 - value) / 255.0
            };
            if occ > meta.occupied_thresh {
                Cell::Occupied
            } else if occ < meta.free_thresh {
                Cell::Free
            } else {
                Cell::Unknown
            }
        };
        let row = height - 1 - y as usize;
        cells[row * width + x as usize] = cell;
    }
    Ok(OccupancyGrid {
        width,
        height,
        resolution_m: meta.resolution,
        origin_x_m: meta.origin[0],
        origin_y_m: meta.origin[1],
        origin_yaw_rad: meta.origin[2],
        cells,
    })
}

/// A map to write as map_server files: each cell's probability of being
/// occupied, `None` for unknown.
#[derive(Clone, Copy)]
pub struct MapImage<'a> {
    pub width: usize,
    pub height: usize,
    pub resolution_m: f64,
    /// The lower-left corner of the lower-left cell in the world.
    pub origin_m: [f64; 2],
    /// The probability of the cell at (column, row), row 0 at the bottom:
    /// read as the image is written, so that a building's map (tens of
    /// millions of cells) is never held twice.
    pub occupancy: &'a dyn Fn(usize, usize) -> Option<f64>,
}

impl std::fmt::Debug for MapImage<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MapImage")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("resolution_m", &self.resolution_m)
            .field("origin_m", &self.origin_m)
            .finish_non_exhaustive()
    }
}

/// The PGM pixel of a cell for map_server's trinary reading with the
/// default thresholds: `(1 - p) * 255`, nudged so that the loader puts the
/// cell on the same side of `occupied_thresh` and `free_thresh` as `p`;
/// 205 (map_saver's grey) for unknown.
fn pixel(p: Option<f64>) -> u8 {
    let Some(p) = p else { return 205 };
    let v = ((1.0 - p.clamp(0.0, 1.0)) * 255.0).round();
    let v = if p > default_occupied() {
        v.min(89.0)
    } else if p < default_free() {
        v.max(206.0)
    } else {
        v.clamp(90.0, 205.0)
    };
    v as u8
}

/// The map_server files of `map`: `(image bytes, YAML text)`, the image a
/// binary PGM named `image_name` (row 0 of the image is the top of the
/// map), the YAML with the default thresholds and trinary mode. [`load_map`]
/// reads them back to the same free, occupied and unknown cells.
pub fn encode_map(map: &MapImage<'_>, image_name: &str) -> (Vec<u8>, String) {
    let (w, h) = (map.width, map.height);
    let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
    pgm.reserve(w * h);
    for y in 0..h {
        let row = h - 1 - y;
        pgm.extend((0..w).map(|col| pixel((map.occupancy)(col, row))));
    }
    let yaml = format!(
        "image: {image_name}\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: {}\nfree_thresh: {}\nmode: trinary\n",
        map.resolution_m,
        map.origin_m[0],
        map.origin_m[1],
        default_occupied(),
        default_free()
    );
    (pgm, yaml)
}

/// The small office floor plan shipped in `scenarios/maps/office.{pgm,yaml}`:
/// 8 m x 6 m at 5 cm, two rooms joined by a door, a corridor and a table.
/// Returns (PGM bytes, YAML text).
pub fn draw_office_map() -> (Vec<u8>, String) {
    const RES: f64 = 0.05;
    let (w, h) = (160usize, 120usize);
    // Drawn in map cells (col, row) with row 0 at the bottom.
    let mut occupied = vec![false; w * h];
    let mut fill = |c0: usize, r0: usize, c1: usize, r1: usize| {
        for r in r0..r1 {
            for c in c0..c1 {
                occupied[r * w + c] = true;
            }
        }
    };
    // Outer walls, 10 cm thick.
    fill(0, 0, w, 2);
    fill(0, h - 2, w, h);
    fill(0, 0, 2, h);
    fill(w - 2, 0, w, h);
    // Interior wall at x = 4.5 m with a 1 m door from y = 2.0 to 3.0 m.
    fill(89, 0, 91, 40);
    fill(89, 60, 91, h);
    // Corridor wall at y = 4.5 m in the right room, open for its last 1.2 m.
    fill(91, 89, 136, 91);
    // A table in the left room.
    fill(30, 70, 50, 84);
    // A pillar in the right room.
    fill(120, 30, 126, 36);

    let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
    for y in 0..h {
        let row = h - 1 - y;
        for c in 0..w {
            pgm.push(if occupied[row * w + c] { 0 } else { 254 });
        }
    }
    let yaml = format!(
        "image: office.pgm\nresolution: {RES}\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    );
    (pgm, yaml)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_office_map_is_the_drawn_one() {
        let (pgm, yaml) = draw_office_map();
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/maps");
        assert_eq!(
            std::fs::read(dir.join("office.pgm")).unwrap(),
            pgm,
            "run `cargo run -- draw-map scenarios/maps` to regenerate"
        );
        assert_eq!(
            std::fs::read_to_string(dir.join("office.yaml")).unwrap(),
            yaml
        );
    }

    #[test]
    fn image_row_zero_is_the_top_of_the_map() {
        // 3 x 2 pixels, one black pixel in the top-left corner of the image.
        let dir = tempfile::tempdir().unwrap();
        let mut pgm = b"P5\n3 2\n255\n".to_vec();
        pgm.extend_from_slice(&[0, 254, 254, 254, 254, 254]);
        std::fs::write(dir.path().join("m.pgm"), pgm).unwrap();
        std::fs::write(
            dir.path().join("m.yaml"),
            "image: m.pgm\nresolution: 1.0\norigin: [10.0, 20.0, 0.0]\n",
        )
        .unwrap();
        let grid = load_map(&dir.path().join("m.yaml")).unwrap();
        assert!(grid.blocked_at(10.5, 21.5), "top-left cell");
        assert!(!grid.blocked_at(10.5, 20.5), "bottom-left cell");
        assert!(!grid.blocked_at(12.5, 21.5), "top-right cell");
        // With a yaw of 90° the map's x axis points along world +y.
        std::fs::write(
            dir.path().join("r.yaml"),
            "image: m.pgm\nresolution: 1.0\norigin: [0.0, 0.0, 1.5707963267948966]\n",
        )
        .unwrap();
        let grid = load_map(&dir.path().join("r.yaml")).unwrap();
        assert!(grid.blocked_at(-1.5, 0.5), "map (0.5, 1.5) rotated by 90°");
        assert!(!grid.blocked_at(-0.5, 2.5), "map (2.5, 0.5), a free cell");
    }

    #[test]
    fn bad_map_files_name_the_field() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("a.yaml"),
            "image: none.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n",
        )
        .unwrap();
        let err = load_map(&dir.path().join("a.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("a.yaml: field `image`") && err.contains("none.pgm"),
            "{err}"
        );
        std::fs::write(
            dir.path().join("b.yaml"),
            "image: x.pgm\nresolution: -1\norigin: [0.0, 0.0, 0.0]\n",
        )
        .unwrap();
        let err = load_map(&dir.path().join("b.yaml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("field `resolution`"), "{err}");
        std::fs::write(
            dir.path().join("c.yaml"),
            "image: x.pgm\nresolution: 1\norigin: [0.0, 0.0, 0.0]\ncolour: 3\n",
        )
        .unwrap();
        let err = load_map(&dir.path().join("c.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("c.yaml") && err.contains("unknown field `colour`"),
            "{err}"
        );
    }

    #[test]
    fn an_encoded_map_loads_back_to_the_same_cells() {
        // Probabilities across the whole range, either side of both
        // thresholds, and unknown cells.
        let (w, h) = (7usize, 5usize);
        let occupancy: Vec<Option<f64>> = (0..w * h)
            .map(|k| (k % 6 != 5).then(|| k as f64 / (w * h - 1) as f64))
            .collect();
        let map = MapImage {
            width: w,
            height: h,
            resolution_m: 0.05,
            origin_m: [-1.25, 2.5],
            occupancy: &|col, row| occupancy[row * w + col],
        };
        let (pgm, yaml) = encode_map(&map, "m.pgm");
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("m.pgm"), pgm).unwrap();
        std::fs::write(dir.path().join("m.yaml"), yaml).unwrap();
        let grid = load_map(&dir.path().join("m.yaml")).unwrap();
        assert_eq!((grid.width, grid.height), (w, h));
        assert_eq!((grid.origin_x_m, grid.origin_y_m), (-1.25, 2.5));
        for (k, p) in occupancy.iter().enumerate() {
            let want = match p {
                None => Cell::Unknown,
                Some(p) if *p > 0.65 => Cell::Occupied,
                Some(p) if *p < 0.196 => Cell::Free,
                Some(_) => Cell::Unknown,
            };
            assert_eq!(grid.cells[k], want, "cell {k}: p {p:?}");
        }
    }

    #[test]
    fn office_map_loads_with_expected_cells() {
        let dir = tempfile::tempdir().unwrap();
        let (pgm, yaml) = draw_office_map();
        std::fs::write(dir.path().join("office.pgm"), pgm).unwrap();
        std::fs::write(dir.path().join("office.yaml"), yaml).unwrap();
        let grid = load_map(&dir.path().join("office.yaml")).unwrap();
        assert_eq!((grid.width, grid.height), (160, 120));
        assert!(grid.blocked_at(0.02, 0.02)); // outer wall corner
        assert!(!grid.blocked_at(1.0, 1.0));
        assert!(grid.blocked_at(4.5, 1.0)); // interior wall
        assert!(!grid.blocked_at(4.5, 2.5)); // the door
        assert!(grid.blocked_at(2.0, 3.9)); // table
        assert!(grid.blocked_at(-1.0, 1.0)); // outside the map
        let segs = grid.boundary_segments();
        // Every boundary segment has blocked on one side and free on the other.
        for s in &segs {
            let mid = (s.a + s.b) * 0.5;
            let d = (s.b - s.a).normalize();
            let n = Vector::new(-d.y, d.x) * 0.01;
            assert_ne!(
                grid.blocked_at(mid.x + n.x, mid.y + n.y),
                grid.blocked_at(mid.x - n.x, mid.y - n.y)
            );
        }
        // Runs are merged: far fewer segments than boundary cell edges.
        assert!(segs.len() < 40, "{} segments", segs.len());
    }
}
