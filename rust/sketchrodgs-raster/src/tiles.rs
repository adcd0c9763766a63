//! A subset of the image's tiles to render (docs/rendering.md, "Rendering part of the image"): the
//! sketch needs K and Z only near the stroke. Tiles outside the set are left as background (index
//! -1, alpha 0); tiles inside are exactly what a full render gives, because every tile is blended
//! on its own from the same front-to-back list.

use crate::camera::Camera;
use crate::{RasterError, TILE_SIZE};

/// Half-open tile range `[x0, x1) x [y0, y1)` a Gaussian is binned into; empty for a culled
/// Gaussian. (At most 1024 tiles a side, see `MAX_IMAGE_SIDE`.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Zeroable)]
pub struct TileRect {
    pub x0: u16,
    pub y0: u16,
    pub x1: u16,
    pub y1: u16,
}

impl TileRect {
    pub fn is_empty(&self) -> bool {
        self.x0 >= self.x1 || self.y0 >= self.y1
    }

    pub fn area(&self) -> usize {
        if self.is_empty() { 0 } else { usize::from(self.x1 - self.x0) * usize::from(self.y1 - self.y0) }
    }
}

/// Which tiles of a camera's grid to render, with a summed-area table so that a footprint's
/// rectangle is tested in constant time.
#[derive(Clone, Debug)]
pub struct TileMask {
    grid_x: usize,
    grid_y: usize,
    on: Vec<bool>,
    /// `sums[y * (grid_x + 1) + x]`: tiles on in `[0, x) x [0, y)`.
    sums: Vec<u32>,
}

impl TileMask {
    /// `on` is row-major over the camera's tile grid (`tile_grid()`: ceil(width / 16) columns).
    pub fn new(camera: &Camera, on: Vec<bool>) -> Result<Self, RasterError> {
        let (grid_x, grid_y) = camera.tile_grid();
        let (grid_x, grid_y) = (grid_x as usize, grid_y as usize);
        if on.len() != grid_x * grid_y {
            return Err(RasterError::LengthMismatch { name: "tiles", expected: grid_x * grid_y, got: on.len() });
        }
        let stride = grid_x + 1;
        let mut sums = vec![0u32; stride * (grid_y + 1)];
        for y in 0..grid_y {
            let mut row = 0;
            for x in 0..grid_x {
                row += u32::from(on[y * grid_x + x]);
                sums[(y + 1) * stride + x + 1] = sums[y * stride + x + 1] + row;
            }
        }
        Ok(Self { grid_x, grid_y, on, sums })
    }

    /// Whether tile `tile` (row-major) is rendered.
    #[inline]
    pub fn contains(&self, tile: usize) -> bool {
        self.on.get(tile).copied().unwrap_or(false)
    }

    /// Whether any tile of `rect` is rendered.
    #[inline]
    pub fn touches(&self, rect: &TileRect) -> bool {
        if rect.is_empty() {
            return false;
        }
        let stride = self.grid_x + 1;
        let (x0, x1) = (usize::from(rect.x0).min(self.grid_x), usize::from(rect.x1).min(self.grid_x));
        let (y0, y1) = (usize::from(rect.y0).min(self.grid_y), usize::from(rect.y1).min(self.grid_y));
        let at = |x: usize, y: usize| self.sums[y * stride + x];
        at(x1, y1) + at(x0, y0) > at(x0, y1) + at(x1, y0)
    }

    /// The grid (columns, rows).
    pub fn grid(&self) -> (usize, usize) {
        (self.grid_x, self.grid_y)
    }

    /// Bounding box `[x0, y0, x1, y1)` of the rendered tiles, in tiles (all zero when none is).
    pub fn tile_box(&self) -> [usize; 4] {
        let on = |t: &usize| self.on[*t];
        let (xs, ys) = (
            (0..self.on.len()).filter(on).map(|t| t % self.grid_x),
            (0..self.on.len()).filter(on).map(|t| t / self.grid_x),
        );
        match (xs.clone().min(), xs.max(), ys.clone().min(), ys.max()) {
            (Some(x0), Some(x1), Some(y0), Some(y1)) => [x0, y0, x1 + 1, y1 + 1],
            _ => [0; 4],
        }
    }

    /// Number of tiles rendered.
    pub fn count(&self) -> usize {
        self.on.iter().filter(|&&t| t).count()
    }

    /// Pixels of the image the rendered tiles cover.
    pub fn pixels(&self, camera: &Camera) -> usize {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let tile = TILE_SIZE as usize;
        (0..self.on.len())
            .filter(|&t| self.on[t])
            .map(|t| {
                let (x, y) = (t % self.grid_x * tile, t / self.grid_x * tile);
                tile.min(w - x) * tile.min(h - y)
            })
            .sum()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn camera(width: u32, height: u32) -> Camera {
        let identity = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        Camera {
            width,
            height,
            fx: 50.0,
            fy: 50.0,
            cx: 0.5 * width as f64,
            cy: 0.5 * height as f64,
            world_to_camera: identity,
            near: crate::NEAR_PLANE,
        }
    }

    #[test]
    fn a_rectangle_touches_the_mask_where_a_tile_of_it_is_on() {
        let cam = camera(100, 70); // 7 x 5 tiles
        let mut on = vec![false; 35];
        on[2 * 7 + 3] = true;
        let mask = TileMask::new(&cam, on).unwrap();
        let rect = |x0, y0, x1, y1| TileRect { x0, y0, x1, y1 };
        for (r, expected) in [
            (rect(3, 2, 4, 3), true),
            (rect(0, 0, 7, 5), true),
            (rect(0, 0, 3, 5), false),
            (rect(4, 0, 7, 5), false),
            (rect(0, 3, 7, 5), false),
            (rect(3, 2, 3, 3), false), // empty
        ] {
            assert_eq!(mask.touches(&r), expected, "{r:?}");
        }
        assert_eq!(mask.count(), 1);
        assert_eq!(mask.pixels(&cam), 256);
        assert!(TileMask::new(&cam, vec![true; 34]).is_err());
    }
}
