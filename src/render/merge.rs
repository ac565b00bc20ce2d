//! Merging image parts ([`super::part::ImagePart`]) into the whole image.
//!
//! Parts are added one at a time into a canvas of the whole image, so that memory holds the
//! image and one part, whatever their number. A part is refused when it comes from another
//! scene or other settings than the first ([`super::part::Provenance`]), or when it overlaps
//! an earlier part with different values (overlaps with equal values, bit for bit, are
//! fine: the same pixel rendered twice). The merge is complete when every pixel came from
//! some part; otherwise the missing pixels are reported as rectangles.
//!
//! Since a pixel's value does not depend on the window it was rendered in, the parts of any
//! split merge into the image a whole render makes, bit for bit, and
//! [`super::part::ImagePart::encode_exr`] turns it into the same file.

use super::part::{ImagePart, Provenance};
use super::{Film, PixelBounds};
use crate::math::Vec3;

/// Why parts cannot be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// A part of another scene than the first part's.
    #[error("{part} renders another scene than {first}: {}", describe(differences))]
    OtherScene {
        /// The part refused.
        part: String,
        /// The first part.
        first: String,
        /// `(field, first's value, part's value)`.
        differences: Vec<(String, Option<String>, Option<String>)>,
    },
    /// A part rendered with other settings than the first part's.
    #[error("{part} was rendered with other settings than {first}: {}", describe(differences))]
    OtherSettings {
        /// The part refused.
        part: String,
        /// The first part.
        first: String,
        /// `(field, first's value, part's value)`.
        differences: Vec<(String, Option<String>, Option<String>)>,
    },
    /// Two parts overlap and disagree on some pixel of the overlap.
    #[error("{0}")]
    Conflict(Box<Conflict>),
    /// Pixels no part holds.
    #[error("{pixels} of the {width}x{height} image's pixels are in no part: {}", describe_regions(regions))]
    Missing {
        /// How many.
        pixels: usize,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
        /// The missing pixels as disjoint rectangles, row by row.
        regions: Vec<PixelBounds>,
    },
    /// No part was given.
    #[error("no parts to merge")]
    Empty,
}

/// Two parts that overlap and disagree on some pixel of the overlap.
#[derive(Debug, thiserror::Error)]
#[error(
    "{part} and {other} overlap in {overlap} and differ in {differing} of its pixels, first at ({x}, {y}): \
     {a:?} in {other}, {b:?} in {part}"
)]
pub struct Conflict {
    /// The part refused.
    pub part: String,
    /// The earlier part it overlaps.
    pub other: String,
    /// The pixels both hold.
    pub overlap: PixelBounds,
    /// How many of them differ.
    pub differing: usize,
    /// The first differing pixel's column.
    pub x: usize,
    /// Its row.
    pub y: usize,
    /// Its value in `other`.
    pub a: [f32; 3],
    /// Its value in `part`.
    pub b: [f32; 3],
}

fn describe(differences: &[(String, Option<String>, Option<String>)]) -> String {
    let show = |v: &Option<String>| v.as_deref().map_or("(none)".to_string(), |v| format!("`{v}`"));
    differences
        .iter()
        .map(|(k, a, b)| format!("{k} {} there, {} here", show(a), show(b)))
        .collect::<Vec<_>>()
        .join("; ")
}

fn describe_regions(regions: &[PixelBounds]) -> String {
    const SHOWN: usize = 8;
    let mut s: Vec<String> = regions.iter().take(SHOWN).map(|r| format!("[{r}]")).collect();
    if regions.len() > SHOWN {
        s.push(format!("and {} more rectangles", regions.len() - SHOWN));
    }
    s.join(", ")
}

/// What a finished merge found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MergeReport {
    /// Parts merged.
    pub parts: usize,
    /// Pixels that more than one part held (with equal values).
    pub overlapping_pixels: usize,
}

/// The whole image, filled part by part.
#[derive(Debug)]
pub struct Merger {
    first: Option<(String, Provenance)>,
    width: usize,
    height: usize,
    pixels: Vec<Vec3>,
    /// `owner[p]`: 1 + the index in `names` of the first part that held pixel `p`; 0 for none.
    owner: Vec<u32>,
    names: Vec<String>,
    overlapping: usize,
}

impl Default for Merger {
    fn default() -> Self {
        Self::new()
    }
}

impl Merger {
    /// An empty merge.
    pub fn new() -> Self {
        Self {
            first: None,
            width: 0,
            height: 0,
            pixels: Vec::new(),
            owner: Vec::new(),
            names: Vec::new(),
            overlapping: 0,
        }
    }

    /// True before the first part.
    pub fn is_empty(&self) -> bool {
        self.first.is_none()
    }

    /// Adds `part` (named `name` in messages); the canvas is unchanged when it is refused.
    pub fn add(&mut self, name: &str, part: &ImagePart) -> Result<(), MergeError> {
        match &self.first {
            None => {
                self.first = Some((name.to_string(), part.provenance.clone()));
                (self.width, self.height) = (part.width, part.height);
                self.pixels = vec![Vec3::ZERO; part.width * part.height];
                self.owner = vec![0; part.width * part.height];
            }
            Some((first, provenance)) => {
                let diff = provenance.differences(&part.provenance);
                if !diff.is_empty() {
                    let scene = diff.iter().any(|(k, _, _)| Provenance::is_scene_key(k));
                    let differences = diff
                        .into_iter()
                        .filter(|(k, _, _)| !scene || Provenance::is_scene_key(k))
                        .map(|(k, a, b)| (k.to_string(), a.map(str::to_string), b.map(str::to_string)))
                        .collect();
                    let (part, first) = (name.to_string(), first.clone());
                    return Err(if scene {
                        MergeError::OtherScene { part, first, differences }
                    } else {
                        MergeError::OtherSettings { part, first, differences }
                    });
                }
            }
        }
        // The provenance records the image size, so the part fits the canvas.
        let (w, win) = (self.width, part.window);
        let at = |x: usize, y: usize| part.film.pixels[(y - win.y0) * win.width() + x - win.x0];
        // Check every overlap first, so that a refused part leaves the canvas as it was.
        let mut overlapping = 0;
        let mut conflict: Option<(u32, usize, usize, usize)> = None;
        for y in win.y0..win.y1 {
            for x in win.x0..win.x1 {
                let o = self.owner[y * w + x];
                if o == 0 {
                    continue;
                }
                overlapping += 1;
                if bits(self.pixels[y * w + x]) != bits(at(x, y)) {
                    match &mut conflict {
                        None => conflict = Some((o, x, y, 1)),
                        Some(c) => c.3 += 1,
                    }
                }
            }
        }
        if let Some((o, x, y, differing)) = conflict {
            let other = self.names[o as usize - 1].clone();
            let overlap = self.bounds_of(o).intersection(&win).unwrap_or(win);
            return Err(MergeError::Conflict(Box::new(Conflict {
                part: name.to_string(),
                other,
                overlap,
                differing,
                x,
                y,
                a: self.pixels[y * w + x].to_array(),
                b: at(x, y).to_array(),
            })));
        }
        self.names.push(name.to_string());
        let id = self.names.len() as u32;
        for y in win.y0..win.y1 {
            for x in win.x0..win.x1 {
                let p = y * w + x;
                if self.owner[p] == 0 {
                    self.owner[p] = id;
                    self.pixels[p] = at(x, y);
                }
            }
        }
        self.overlapping += overlapping;
        Ok(())
    }

    /// The bounding box of the pixels part `id` (1-based) holds.
    fn bounds_of(&self, id: u32) -> PixelBounds {
        let mut b = PixelBounds { x0: usize::MAX, x1: 0, y0: usize::MAX, y1: 0 };
        for (p, _) in self.owner.iter().enumerate().filter(|&(_, &o)| o == id) {
            let (x, y) = (p % self.width, p / self.width);
            b = PixelBounds { x0: b.x0.min(x), x1: b.x1.max(x + 1), y0: b.y0.min(y), y1: b.y1.max(y + 1) };
        }
        b
    }

    /// The whole image, or the pixels no part held.
    pub fn finish(self) -> Result<(ImagePart, MergeReport), MergeError> {
        let Some((_, provenance)) = self.first else { return Err(MergeError::Empty) };
        let regions = missing_regions(&self.owner, self.width, self.height);
        if !regions.is_empty() {
            let pixels = regions.iter().map(PixelBounds::area).sum();
            return Err(MergeError::Missing { pixels, width: self.width, height: self.height, regions });
        }
        let film = Film { width: self.width, height: self.height, pixels: self.pixels };
        let report = MergeReport { parts: self.names.len(), overlapping_pixels: self.overlapping };
        let window = PixelBounds::full(self.width, self.height);
        Ok((ImagePart { width: self.width, height: self.height, window, film, provenance }, report))
    }
}

fn bits(v: Vec3) -> [u32; 3] {
    v.to_array().map(f32::to_bits)
}

/// The pixels with `owner == 0` as disjoint rectangles: runs of each row, joined with the
/// runs of the same columns in the rows below. (A missing part is one rectangle.)
fn missing_regions(owner: &[u32], width: usize, height: usize) -> Vec<PixelBounds> {
    let mut done: Vec<PixelBounds> = Vec::new();
    // Rectangles still growing downwards, as of the previous row.
    let mut open: Vec<PixelBounds> = Vec::new();
    for y in 0..height {
        let row = &owner[y * width..(y + 1) * width];
        let mut runs = Vec::new();
        let mut x = 0;
        while x < width {
            if row[x] != 0 {
                x += 1;
                continue;
            }
            let start = x;
            while x < width && row[x] == 0 {
                x += 1;
            }
            runs.push((start, x));
        }
        let mut next = Vec::with_capacity(runs.len());
        for (x0, x1) in runs {
            match open.iter().position(|r| r.x0 == x0 && r.x1 == x1) {
                Some(i) => {
                    let mut r = open.swap_remove(i);
                    r.y1 = y + 1;
                    next.push(r);
                }
                None => next.push(PixelBounds { x0, x1, y0: y, y1: y + 1 }),
            }
        }
        done.append(&mut open);
        open = next;
    }
    done.append(&mut open);
    done.sort_by_key(|r| (r.y0, r.x0));
    done
}

#[cfg(test)]
mod tests {
    use super::*;

    fn provenance(seed: &str, scene: &str) -> Provenance {
        let f = |k: &str, v: &str| (k.to_string(), v.to_string());
        Provenance { fields: vec![f("raypack", "1"), f("scene", scene), f("scene-digest", scene), f("seed", seed)] }
    }

    /// The part of `window` of an image whose pixel `(x, y)` is `(x, y, 1)`.
    fn part(window: PixelBounds, seed: &str, scene: &str) -> ImagePart {
        let mut film = Film::new(window.width(), window.height());
        for (i, p) in film.pixels.iter_mut().enumerate() {
            *p = Vec3::new((window.x0 + i % window.width()) as f32, (window.y0 + i / window.width()) as f32, 1.0);
        }
        ImagePart { width: 10, height: 6, window, film, provenance: provenance(seed, scene) }
    }

    fn b(x0: usize, x1: usize, y0: usize, y1: usize) -> PixelBounds {
        PixelBounds { x0, x1, y0, y1 }
    }

    #[test]
    fn parts_of_any_split_merge_into_the_whole() {
        let whole = part(PixelBounds::full(10, 6), "1", "s");
        for n in [1, 2, 3, 7] {
            let mut m = Merger::new();
            for (i, w) in PixelBounds::parts(n, 10, 6).unwrap().into_iter().enumerate() {
                m.add(&format!("p{i}"), &part(w, "1", "s")).unwrap();
            }
            let (merged, report) = m.finish().unwrap();
            assert_eq!(merged, whole);
            assert_eq!(report, MergeReport { parts: n, overlapping_pixels: 0 });
        }
        // The same pixels twice are fine.
        let mut m = Merger::new();
        m.add("a", &part(b(0, 10, 0, 4), "1", "s")).unwrap();
        m.add("b", &part(b(0, 10, 2, 6), "1", "s")).unwrap();
        assert_eq!(m.finish().unwrap().1.overlapping_pixels, 20);
    }

    #[test]
    fn refuses_other_renders_and_conflicts_and_reports_holes() {
        let mut m = Merger::new();
        m.add("a", &part(b(0, 5, 0, 6), "1", "s")).unwrap();
        let e = m.add("b", &part(b(5, 10, 0, 6), "2", "s")).unwrap_err();
        assert!(matches!(&e, MergeError::OtherSettings { differences, .. } if differences[0].0 == "seed"), "{e}");
        assert!(e.to_string().contains("seed `1` there, `2` here"), "{e}");
        let e = m.add("c", &part(b(5, 10, 0, 6), "2", "t")).unwrap_err();
        assert!(matches!(&e, MergeError::OtherScene { differences, .. } if differences.len() == 2), "{e}");
        let mut other = part(b(4, 6, 1, 3), "1", "s");
        other.film.pixels[1].z = 2.0; // pixel (5, 1): not in `a`
        other.film.pixels[2].z = 2.0; // pixel (4, 2): in `a`
        let e = m.add("d", &other).unwrap_err();
        let MergeError::Conflict(c) = &e else { panic!("{e}") };
        assert_eq!((c.overlap, c.differing, c.x, c.y), (b(4, 5, 1, 3), 1, 4, 2), "{e}");
        // Nothing of a refused part was kept.
        m.add("e", &part(b(8, 10, 0, 6), "1", "s")).unwrap();
        match m.finish().unwrap_err() {
            MergeError::Missing { pixels, regions, .. } => {
                assert_eq!(pixels, 18);
                assert_eq!(regions, vec![b(5, 8, 0, 6)]);
            }
            e => panic!("{e}"),
        }
        assert!(matches!(Merger::new().finish(), Err(MergeError::Empty)));
    }

    #[test]
    fn missing_pixels_come_out_as_disjoint_rectangles() {
        let (w, h) = (9, 7);
        let mut owner = vec![1u32; w * h];
        let holes = [b(0, 3, 0, 2), b(5, 9, 1, 7), b(1, 2, 4, 6)];
        for r in holes {
            for y in r.y0..r.y1 {
                for x in r.x0..r.x1 {
                    owner[y * w + x] = 0;
                }
            }
        }
        assert_eq!(missing_regions(&owner, w, h), vec![b(0, 3, 0, 2), b(5, 9, 1, 7), b(1, 2, 4, 6)]);
        assert!(missing_regions(&[1; 6], 3, 2).is_empty());
        assert_eq!(missing_regions(&[0; 6], 3, 2), vec![b(0, 3, 0, 2)]);
    }
}
