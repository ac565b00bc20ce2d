//! Windows of an image: the rectangle of pixels a render computes.
//!
//! A pixel's value depends on the scene, the camera, the settings and the pixel's position in
//! the whole image, never on the window it is rendered in (its samples are keyed by that
//! position and the seed, [`super::sample_stream`]). So an image can be rendered in parts,
//! anywhere, and put back together bit for bit ([`super::merge`]).
//!
//! Three ways to name a window, as render farms do:
//! * [`PixelBounds::from_crop_window`]: fractions of the image, as pbrt's `--cropwindow`
//!   (pixels `ceil(w·x0) .. ceil(w·x1)`, so that windows sharing an edge fraction share the
//!   pixel edge);
//! * [`PixelBounds::within`]: pixel bounds, as pbrt's `--pixelbounds` (`x1`, `y1` exclusive);
//! * [`PixelBounds::part`]: the `i`-th of `n` parts of a fixed grid ([`PartGrid`]), so that a
//!   job array passes its task index and count.

use std::fmt;

/// A rectangle of pixels `x0 .. x1` × `y0 .. y1` (ends exclusive) of an image; row 0 is the
/// top row.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelBounds {
    /// First column.
    pub x0: usize,
    /// One past the last column.
    pub x1: usize,
    /// First row.
    pub y0: usize,
    /// One past the last row.
    pub y1: usize,
}

/// Why a window cannot be rendered.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WindowError {
    /// Fractions outside `[0, 1]`, not finite, or not increasing.
    #[error(
        "crop window {x0} {x1} {y0} {y1}: expected fractions of the image with 0 <= x0 < x1 <= 1 and 0 <= y0 < y1 <= 1"
    )]
    BadCrop {
        /// Left edge.
        x0: f64,
        /// Right edge.
        x1: f64,
        /// Top edge.
        y0: f64,
        /// Bottom edge.
        y1: f64,
    },
    /// A crop window so thin that it holds no whole pixel.
    #[error("crop window {x0} {x1} {y0} {y1} holds no pixel of a {width}x{height} image")]
    EmptyCrop {
        /// Left edge.
        x0: f64,
        /// Right edge.
        x1: f64,
        /// Top edge.
        y0: f64,
        /// Bottom edge.
        y1: f64,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
    },
    /// Pixel bounds empty or outside the image.
    #[error(
        "pixel bounds {} {} {} {}: expected 0 <= x0 < x1 <= {width} and 0 <= y0 < y1 <= {height} (x1 and y1 exclusive)",
        bounds.x0, bounds.x1, bounds.y0, bounds.y1
    )]
    BadBounds {
        /// The bounds given.
        bounds: PixelBounds,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
    },
    /// A part index outside `0 .. n`, or no parts.
    #[error("part {index}/{count}: expected an index from 0 to {} of {count} parts", count.saturating_sub(1))]
    BadPart {
        /// The index given.
        index: usize,
        /// The number of parts.
        count: usize,
    },
    /// More parts than the image can be split into.
    #[error("a {width}x{height} image cannot be split into {count} parts of at least one pixel")]
    TooManyParts {
        /// The number of parts.
        count: usize,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
    },
}

impl PixelBounds {
    /// The whole `width × height` image.
    pub fn full(width: usize, height: usize) -> Self {
        Self { x0: 0, x1: width, y0: 0, y1: height }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.x1.saturating_sub(self.x0)
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.y1.saturating_sub(self.y0)
    }

    /// Pixels.
    pub fn area(&self) -> usize {
        self.width() * self.height()
    }

    /// True when the window holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.area() == 0
    }

    /// True when pixel `(x, y)` lies in the window.
    pub fn contains(&self, x: usize, y: usize) -> bool {
        (self.x0..self.x1).contains(&x) && (self.y0..self.y1).contains(&y)
    }

    /// True when the window is the whole `width × height` image.
    pub fn is_full(&self, width: usize, height: usize) -> bool {
        *self == Self::full(width, height)
    }

    /// The pixels both windows hold, if any.
    pub fn intersection(&self, other: &Self) -> Option<Self> {
        let b = Self {
            x0: self.x0.max(other.x0),
            x1: self.x1.min(other.x1),
            y0: self.y0.max(other.y0),
            y1: self.y1.min(other.y1),
        };
        (b.x0 < b.x1 && b.y0 < b.y1).then_some(b)
    }

    /// `self` checked to be a non-empty window of a `width × height` image (pbrt's
    /// `--pixelbounds`).
    pub fn within(self, width: usize, height: usize) -> Result<Self, WindowError> {
        if self.x0 < self.x1 && self.x1 <= width && self.y0 < self.y1 && self.y1 <= height {
            Ok(self)
        } else {
            Err(WindowError::BadBounds { bounds: self, width, height })
        }
    }

    /// The pixels of the crop window `[x0, x1] × [y0, y1]` (fractions of the image, `y`
    /// downwards) of a `width × height` image: columns `ceil(width·x0) .. ceil(width·x1)`,
    /// rows likewise, as pbrt computes them. Windows that share an edge fraction share the
    /// pixel edge, so crop windows that tile `[0, 1]²` tile the image.
    pub fn from_crop_window(crop: [f64; 4], width: usize, height: usize) -> Result<Self, WindowError> {
        let [x0, x1, y0, y1] = crop;
        let ok = |a: f64, b: f64| (0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b) && a < b;
        if !(ok(x0, x1) && ok(y0, y1)) {
            return Err(WindowError::BadCrop { x0, x1, y0, y1 });
        }
        let edge = |f: f64, n: usize| ((n as f64 * f).ceil() as usize).min(n);
        let b = Self { x0: edge(x0, width), x1: edge(x1, width), y0: edge(y0, height), y1: edge(y1, height) };
        if b.is_empty() {
            return Err(WindowError::EmptyCrop { x0, x1, y0, y1, width, height });
        }
        Ok(b)
    }

    /// Part `index` (from 0) of `count` parts of a `width × height` image: cell
    /// `(index % columns, index / columns)` of [`PartGrid::of`], row by row from the top left.
    pub fn part(index: usize, count: usize, width: usize, height: usize) -> Result<Self, WindowError> {
        if count == 0 || index >= count {
            return Err(WindowError::BadPart { index, count });
        }
        let grid = PartGrid::of(count, width, height)?;
        Ok(grid.cell(index % grid.columns, index / grid.columns, width, height))
    }

    /// Every part of a split into `count` parts ([`PixelBounds::part`]), in order.
    pub fn parts(count: usize, width: usize, height: usize) -> Result<Vec<Self>, WindowError> {
        (0..count).map(|i| Self::part(i, count, width, height)).collect()
    }
}

impl fmt::Display for PixelBounds {
    /// `x0..x1 × y0..y1`, ends exclusive.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "x {}..{}, y {}..{}", self.x0, self.x1, self.y0, self.y1)
    }
}

/// The grid an image is split into for `n` parts: `columns × rows = n`, the factorisation
/// whose cells are closest to square (ties: fewer columns). Cell edges are at
/// `k · width / columns` and `k · height / rows` (rounded down), so the cells tile the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PartGrid {
    /// Cells per row.
    pub columns: usize,
    /// Cells per column.
    pub rows: usize,
}

impl PartGrid {
    /// The grid of `count` parts of a `width × height` image; every cell holds at least one
    /// pixel.
    pub fn of(count: usize, width: usize, height: usize) -> Result<Self, WindowError> {
        let mut best: Option<(f64, Self)> = None;
        for columns in (1..=count).filter(|c| count.is_multiple_of(*c)) {
            let rows = count / columns;
            if columns > width || rows > height {
                continue;
            }
            // How far the cells are from square, as |log(cell aspect)|.
            let skew = ((width as f64 / columns as f64) / (height as f64 / rows as f64)).ln().abs();
            if best.is_none_or(|(s, _)| skew < s) {
                best = Some((skew, Self { columns, rows }));
            }
        }
        best.map(|(_, g)| g).ok_or(WindowError::TooManyParts { count, width, height })
    }

    /// The pixels of cell `(column, row)`.
    pub fn cell(&self, column: usize, row: usize, width: usize, height: usize) -> PixelBounds {
        PixelBounds {
            x0: column * width / self.columns,
            x1: (column + 1) * width / self.columns,
            y0: row * height / self.rows,
            y1: (row + 1) * height / self.rows,
        }
    }
}

/// Parses `I/N` (a part index from 0 and a count), as `--tile` takes it.
pub fn parse_part(s: &str) -> Option<(usize, usize)> {
    let (i, n) = s.split_once('/')?;
    Some((i.trim().parse().ok()?, n.trim().parse().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel of the image in exactly one window.
    fn tiles_exactly(windows: &[PixelBounds], w: usize, h: usize) -> bool {
        let mut count = vec![0u32; w * h];
        for b in windows {
            for y in b.y0..b.y1 {
                for x in b.x0..b.x1 {
                    count[y * w + x] += 1;
                }
            }
        }
        count.iter().all(|&c| c == 1)
    }

    #[test]
    fn parts_tile_the_image_for_every_count() {
        for (w, h) in [(1, 1), (7, 3), (16, 12), (480, 360), (31, 200)] {
            for n in 1..=24 {
                match PixelBounds::parts(n, w, h) {
                    Ok(parts) => {
                        assert_eq!(parts.len(), n);
                        assert!(parts.iter().all(|p| !p.is_empty() && p.x1 <= w && p.y1 <= h), "{w}x{h} {n}");
                        assert!(tiles_exactly(&parts, w, h), "{w}x{h} in {n} parts: {parts:?}");
                    }
                    // Only when no factorisation fits: a prime count above both sides.
                    Err(WindowError::TooManyParts { .. }) => {
                        assert!((1..=n).filter(|c| n.is_multiple_of(*c)).all(|c| c > w || n / c > h), "{w}x{h} {n}")
                    }
                    Err(e) => panic!("{e}"),
                }
            }
        }
    }

    #[test]
    fn grids_are_nearly_square_cells() {
        assert_eq!(PartGrid::of(4, 640, 480).unwrap(), PartGrid { columns: 2, rows: 2 });
        assert_eq!(PartGrid::of(2, 640, 480).unwrap(), PartGrid { columns: 2, rows: 1 });
        assert_eq!(PartGrid::of(2, 100, 400).unwrap(), PartGrid { columns: 1, rows: 2 });
        assert_eq!(PartGrid::of(7, 640, 480).unwrap(), PartGrid { columns: 7, rows: 1 });
        assert_eq!(PartGrid::of(6, 640, 480).unwrap(), PartGrid { columns: 3, rows: 2 });
        assert_eq!(PartGrid::of(7, 6, 480).unwrap(), PartGrid { columns: 1, rows: 7 });
        assert!(PartGrid::of(7, 6, 6).is_err());
        assert!(PixelBounds::part(4, 4, 10, 10).is_err());
        assert!(PixelBounds::part(0, 0, 10, 10).is_err());
    }

    #[test]
    fn crop_windows_follow_pbrt_and_share_edges() {
        let b = PixelBounds::from_crop_window([0.25, 0.75, 0.0, 0.5], 480, 360).unwrap();
        assert_eq!(b, PixelBounds { x0: 120, x1: 360, y0: 0, y1: 180 });
        // Thirds: each edge fraction gives one pixel edge, whichever window it bounds.
        let thirds = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];
        let mut windows = Vec::new();
        for i in 0..3 {
            for j in 0..3 {
                let c = [thirds[i], thirds[i + 1], thirds[j], thirds[j + 1]];
                windows.push(PixelBounds::from_crop_window(c, 101, 37).unwrap());
            }
        }
        assert!(tiles_exactly(&windows, 101, 37));
        for bad in [[0.5, 0.5, 0.0, 1.0], [-0.1, 1.0, 0.0, 1.0], [0.0, 1.1, 0.0, 1.0], [0.0, f64::NAN, 0.0, 1.0]] {
            assert!(matches!(PixelBounds::from_crop_window(bad, 10, 10), Err(WindowError::BadCrop { .. })), "{bad:?}");
        }
        assert!(matches!(
            PixelBounds::from_crop_window([0.51, 0.55, 0.0, 1.0], 10, 10),
            Err(WindowError::EmptyCrop { .. })
        ));
    }

    #[test]
    fn pixel_bounds_are_checked_against_the_image() {
        let b = PixelBounds { x0: 0, x1: 10, y0: 5, y1: 6 };
        assert_eq!(b.within(10, 6), Ok(b));
        assert!(b.within(9, 6).is_err());
        assert!(PixelBounds { x0: 3, x1: 3, y0: 0, y1: 1 }.within(10, 10).is_err());
        assert_eq!(parse_part("3/8"), Some((3, 8)));
        assert_eq!(parse_part("3"), None);
        assert_eq!(parse_part("-1/8"), None);
    }
}
