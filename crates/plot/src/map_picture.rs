//! A picture of an occupancy map to open and look at (`map.png` beside
//! map_server's `map.pgm`): the map's own greys (occupied dark, free
//! white, unknown grey), each cell a square of pixels, with the drive's
//! path drawn on it, its start marked by a disc with a heading tick and
//! its end by a small square. No legend, no axes.

use plotters::prelude::*;

use crate::PlotError;
use crate::palette;

/// A map's picture is zoomed to about this many pixels on its longer
/// side (whole pixels per cell, at most [`MAX_ZOOM`]).
pub const TARGET_PX: usize = 1200;
/// At most this many pixels per cell.
pub const MAX_ZOOM: usize = 8;
/// A map longer than this many cells is shrunk (whole cells per pixel)
/// to at most this many pixels a side.
pub const MAX_PX: usize = 4000;

/// How a map of `width` x `height` cells is drawn: `zoom` pixels per cell
/// after `shrink` cells per pixel (one of the two is 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PictureScale {
    pub zoom: usize,
    pub shrink: usize,
}

impl PictureScale {
    /// Zoomed by the largest whole number (1 to [`MAX_ZOOM`]) that keeps
    /// the longer side within [`TARGET_PX`], or shrunk by the smallest
    /// whole number that keeps it within [`MAX_PX`].
    pub fn of(width: usize, height: usize) -> Self {
        let longest = width.max(height).max(1);
        if longest > MAX_PX {
            Self {
                zoom: 1,
                shrink: longest.div_ceil(MAX_PX),
            }
        } else {
            Self {
                zoom: (TARGET_PX / longest).clamp(1, MAX_ZOOM),
                shrink: 1,
            }
        }
    }

    /// The picture's size in pixels.
    pub fn size(&self, width: usize, height: usize) -> (usize, usize) {
        (
            width.div_ceil(self.shrink) * self.zoom,
            height.div_ceil(self.shrink) * self.zoom,
        )
    }
}

/// An occupancy map and a drive on it.
#[derive(Debug, Clone, Copy)]
pub struct MapPicture<'a> {
    /// Cells across and up.
    pub width: usize,
    pub height: usize,
    pub resolution_m: f64,
    /// The lower-left corner of the lower-left cell in the world.
    pub origin_m: [f64; 2],
    /// Each cell's grey (0 black to 255 white), the top row first (a PGM's
    /// pixels).
    pub grey: &'a [u8],
    /// The drive's path `(x_m, y_m)` in the map's frame.
    pub path_m: &'a [(f64, f64)],
    /// The drive's start `(x_m, y_m, heading_rad)`.
    pub start: Option<(f64, f64, f64)>,
}

/// The path's colour.
pub const PATH: RGBColor = palette::TRUTH;
/// The start's colour.
pub const START: RGBColor = palette::GOOD;
/// The end's colour.
pub const END: RGBColor = palette::BAD;

impl MapPicture<'_> {
    pub fn scale(&self) -> PictureScale {
        PictureScale::of(self.width, self.height)
    }

    /// The picture's pixel of a point of the map (fractional).
    fn pixel(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        let s = self.scale();
        let col = (x_m - self.origin_m[0]) / self.resolution_m;
        let row = self.height as f64 - (y_m - self.origin_m[1]) / self.resolution_m;
        let k = s.zoom as f64 / s.shrink as f64;
        (col * k, row * k)
    }

    /// The picture as PNG bytes.
    pub fn png(&self) -> Result<Vec<u8>, PlotError> {
        let data = |message: String| PlotError::Data {
            what: "the map's picture".into(),
            message,
        };
        let (w, h) = (self.width, self.height);
        if w == 0 || h == 0 || self.grey.len() != w * h {
            return Err(data(format!(
                "{} greys for a map of {w} x {h} cells",
                self.grey.len()
            )));
        }
        if !(self.resolution_m.is_finite() && self.resolution_m > 0.0) {
            return Err(data(format!("resolution {} m", self.resolution_m)));
        }
        let scale = self.scale();
        let (pw, ph) = scale.size(w, h);
        let mut rgb = vec![0u8; pw * ph * 3];
        // The map's greys: a shrunk pixel takes its darkest cell (walls
        // stay drawn), a zoomed cell fills its square.
        let (cw, ch) = (w.div_ceil(scale.shrink), h.div_ceil(scale.shrink));
        for cy in 0..ch {
            for cx in 0..cw {
                let mut v = u8::MAX;
                for row in cy * scale.shrink..((cy + 1) * scale.shrink).min(h) {
                    for col in cx * scale.shrink..((cx + 1) * scale.shrink).min(w) {
                        v = v.min(self.grey[row * w + col]);
                    }
                }
                for py in cy * scale.zoom..(cy + 1) * scale.zoom {
                    let line = &mut rgb[(py * pw + cx * scale.zoom) * 3..][..scale.zoom * 3];
                    line.fill(v);
                }
            }
        }
        {
            let root =
                BitMapBackend::with_buffer(&mut rgb, (pw as u32, ph as u32)).into_drawing_area();
            let px = |x: f64, y: f64| {
                let (u, v) = self.pixel(x, y);
                (u.round() as i32, v.round() as i32)
            };
            let line_px = if scale.zoom >= 4 { 3 } else { 2 };
            let points: Vec<(i32, i32)> = self
                .path_m
                .iter()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|&(x, y)| px(x, y))
                .collect();
            let drawn = |e: plotters::drawing::DrawingAreaErrorKind<_>| data(e.to_string());
            if points.len() > 1 {
                root.draw(&PathElement::new(
                    points.clone(),
                    PATH.stroke_width(line_px),
                ))
                .map_err(drawn)?;
            }
            // Markers a robot's size (0.15 m) across, at least 5 pixels.
            let marker = ((0.15 / self.resolution_m * scale.zoom as f64 / scale.shrink as f64)
                .round() as i32)
                .max(5);
            if let Some(&end) = points.last() {
                let r = (marker * 2 / 3).max(3);
                root.draw(&Rectangle::new(
                    [(end.0 - r, end.1 - r), (end.0 + r, end.1 + r)],
                    END.filled(),
                ))
                .map_err(drawn)?;
            }
            if let Some((x, y, heading)) = self.start {
                let c = px(x, y);
                let tip = (
                    c.0 + (2.0 * marker as f64 * heading.cos()).round() as i32,
                    c.1 - (2.0 * marker as f64 * heading.sin()).round() as i32,
                );
                root.draw(&PathElement::new(
                    vec![c, tip],
                    START.stroke_width(line_px + 1),
                ))
                .map_err(drawn)?;
                root.draw(&Circle::new(c, marker, START.filled()))
                    .map_err(drawn)?;
            }
            root.present().map_err(drawn)?;
        }
        let image = image::RgbImage::from_raw(pw as u32, ph as u32, rgb)
            .ok_or_else(|| data("the pixels do not fill the picture".into()))?;
        let mut png = std::io::Cursor::new(Vec::new());
        image
            .write_to(&mut png, image::ImageFormat::Png)
            .map_err(|e| data(e.to_string()))?;
        Ok(png.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A room: free inside, walls around, unknown outside, of random
    /// size; a drive across it.
    fn room(w: usize, h: usize) -> Vec<u8> {
        let mut grey = vec![205u8; w * h];
        for row in 2..h - 2 {
            for col in 2..w - 2 {
                let wall = row == 2 || row == h - 3 || col == 2 || col == w - 3;
                grey[row * w + col] = if wall { 0 } else { 254 };
            }
        }
        grey
    }

    #[test]
    fn scale_keeps_pictures_viewable() {
        assert_eq!(
            PictureScale::of(100, 40),
            PictureScale { zoom: 8, shrink: 1 }
        );
        assert_eq!(
            PictureScale::of(300, 200),
            PictureScale { zoom: 4, shrink: 1 }
        );
        assert_eq!(
            PictureScale::of(2000, 10),
            PictureScale { zoom: 1, shrink: 1 }
        );
        assert_eq!(
            PictureScale::of(10, 9000),
            PictureScale { zoom: 1, shrink: 3 }
        );
        for (w, h) in [(1, 1), (37, 1201), (4001, 17), (12345, 6789)] {
            let (pw, ph) = PictureScale::of(w, h).size(w, h);
            assert!(pw.max(ph) <= MAX_PX.max(MAX_ZOOM), "{w} x {h}: {pw} x {ph}");
            assert!(pw >= 1 && ph >= 1);
        }
    }

    #[test]
    fn the_picture_shows_the_map_the_path_and_its_ends() {
        for (w, h, res) in [(60, 40, 0.05), (301, 150, 0.1), (5000, 30, 0.05)] {
            let grey = room(w, h);
            let origin = [-1.3, 2.1];
            // A drive along the room's middle row, heading +x.
            let y = origin[1] + (h as f64 / 2.0) * res;
            let (x0, x1) = (origin[0] + 5.0 * res, origin[0] + (w as f64 - 6.0) * res);
            let path: Vec<(f64, f64)> = (0..=50)
                .map(|i| (x0 + (x1 - x0) * i as f64 / 50.0, y))
                .collect();
            let picture = MapPicture {
                width: w,
                height: h,
                resolution_m: res,
                origin_m: origin,
                grey: &grey,
                path_m: &path,
                start: Some((x0, y, 0.0)),
            };
            let png = picture.png().unwrap();
            let image = image::load_from_memory_with_format(&png, image::ImageFormat::Png)
                .unwrap()
                .to_rgb8();
            let s = picture.scale();
            let (pw, ph) = s.size(w, h);
            assert_eq!((image.width() as usize, image.height() as usize), (pw, ph));
            // Cells away from the drive keep their grey: a corner's
            // unknown, a wall, the free floor.
            let at = |col: usize, row_from_top: usize| {
                let k = s.zoom as f64 / s.shrink as f64;
                let p = image.get_pixel(
                    ((col as f64 + 0.5) * k) as u32,
                    ((row_from_top as f64 + 0.5) * k) as u32,
                );
                p.0
            };
            if s.shrink == 1 {
                assert_eq!(at(0, 0), [205; 3]);
                assert_eq!(at(2, h / 4), [0; 3]);
                assert_eq!(at(w / 2, h / 4), [254; 3]);
            }
            let count = |c: RGBColor| image.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count();
            // The path runs most of the picture's width.
            assert!(
                count(PATH) >= pw / 2,
                "{w} x {h}: {} path pixels",
                count(PATH)
            );
            assert!(count(START) > 10 && count(END) > 4);
            // The start's disc is where the drive began.
            let (u, v) = picture.pixel(x0, y);
            let p = image.get_pixel(u as u32, v as u32).0;
            assert_eq!(p, [START.0, START.1, START.2]);
        }
    }

    #[test]
    fn a_grid_that_is_not_its_size_is_refused() {
        let picture = MapPicture {
            width: 4,
            height: 3,
            resolution_m: 0.05,
            origin_m: [0.0; 2],
            grey: &[0; 11],
            path_m: &[],
            start: None,
        };
        let e = picture.png().unwrap_err().to_string();
        assert!(e.contains("11 greys for a map of 4 x 3 cells"), "{e}");
    }
}
