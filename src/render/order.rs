//! Ordering secondary rays before they are traced, so that the 16 consecutive rays of a packet
//! travel alike (the packet kernels' frustum test and shared node visits pay off only then).
//!
//! Keys are pure functions of a ray (its direction's octant, its origin's cell along a Morton
//! curve over the scene's bounds), and ties keep the queue's order, so a sorted queue is the
//! same whatever thread sorts it.

use crate::math::{Aabb, Vec3};
use crate::ray::Ray;

/// How a queue of rays is ordered before it is traced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum RayOrder {
    /// As queued: shading order (camera rays of a pixel, then the next pixel's).
    #[default]
    Queued,
    /// Grouped by the octant of the direction (its three signs), as Embree's stream mode.
    Octant,
    /// By octant, then by the origin's cell along a Morton curve over the scene's bounds
    /// (512 cells per axis).
    OctantMorton,
    /// By the origin's Morton cell only.
    Morton,
}

impl RayOrder {
    /// All orders, for measurements.
    pub const ALL: [RayOrder; 4] = [RayOrder::Queued, RayOrder::Octant, RayOrder::OctantMorton, RayOrder::Morton];

    /// Lower-case name, as `--ray-order` takes it.
    pub fn name(self) -> &'static str {
        match self {
            RayOrder::Queued => "queued",
            RayOrder::Octant => "octant",
            RayOrder::OctantMorton => "octant-morton",
            RayOrder::Morton => "morton",
        }
    }
}

/// Bits per axis of the Morton key.
const MORTON_BITS: u32 = 9;

/// Spreads the low 10 bits of `x` to every third bit.
#[inline]
fn spread3(x: u32) -> u32 {
    let mut x = x & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    (x | (x << 2)) & 0x0924_9249
}

/// The octant of `d`: bit `k` set when component `k` is negative.
#[inline]
fn octant(d: Vec3) -> u32 {
    (d.x.is_sign_negative() as u32) | ((d.y.is_sign_negative() as u32) << 1) | ((d.z.is_sign_negative() as u32) << 2)
}

/// Maps points of a box to Morton codes of its cells.
#[derive(Clone, Copy, Debug)]
struct MortonGrid {
    lo: Vec3,
    scale: Vec3,
}

impl MortonGrid {
    fn new(bounds: &Aabb) -> Self {
        let cells = (1u32 << MORTON_BITS) as f32;
        let extent = (bounds.max - bounds.min).max(Vec3::splat(f32::MIN_POSITIVE));
        let scale = Vec3::splat(cells) / extent;
        let ok = bounds.min.is_finite() && scale.is_finite();
        Self { lo: if ok { bounds.min } else { Vec3::ZERO }, scale: if ok { scale } else { Vec3::ZERO } }
    }

    #[inline]
    fn code(&self, p: Vec3) -> u32 {
        let max = ((1u32 << MORTON_BITS) - 1) as f32;
        // `as u32` saturates and sends NaN to 0: any origin gets a cell.
        let c = ((p - self.lo) * self.scale).clamp(Vec3::ZERO, Vec3::splat(max));
        spread3(c.x as u32) | (spread3(c.y as u32) << 1) | (spread3(c.z as u32) << 2)
    }
}

/// Buffers of [`SortScratch::sort`], kept from one sort to the next.
#[derive(Clone, Debug, Default)]
pub struct SortScratch {
    keys: Vec<u64>,
    rays: Vec<Ray>,
    owner: Vec<u32>,
}

impl SortScratch {
    /// Sorts `rays` and `owner` (same length) together by `order`'s key, stably.
    pub fn sort(&mut self, order: RayOrder, bounds: &Aabb, rays: &mut Vec<Ray>, owner: &mut Vec<u32>) {
        debug_assert_eq!(rays.len(), owner.len());
        if order == RayOrder::Queued || rays.len() < 2 {
            return;
        }
        let grid = MortonGrid::new(bounds);
        let key = |r: &Ray| -> u64 {
            match order {
                RayOrder::Queued => 0,
                RayOrder::Octant => octant(r.dir) as u64,
                RayOrder::OctantMorton => ((octant(r.dir) as u64) << 27) | grid.code(r.origin) as u64,
                RayOrder::Morton => grid.code(r.origin) as u64,
            }
        };
        // The index in the low bits makes keys unique: an unstable sort is then stable.
        self.keys.clear();
        self.keys.extend(rays.iter().enumerate().map(|(i, r)| (key(r) << 32) | i as u64));
        self.keys.sort_unstable();
        self.rays.clear();
        self.owner.clear();
        for &k in &self.keys {
            let i = k as u32 as usize;
            self.rays.push(rays[i]);
            self.owner.push(owner[i]);
        }
        std::mem::swap(rays, &mut self.rays);
        std::mem::swap(owner, &mut self.owner);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_by_octant_stably_and_keeps_owners() {
        let dirs = [Vec3::new(1.0, -1.0, 1.0), Vec3::new(-1.0, 1.0, 1.0), Vec3::new(1.0, -1.0, 2.0), Vec3::ONE];
        let mut rays: Vec<Ray> = dirs.iter().map(|&d| Ray::new(Vec3::ZERO, d)).collect();
        let mut owner = vec![10, 11, 12, 13];
        let bounds = Aabb { min: Vec3::splat(-1.0), max: Vec3::ONE };
        SortScratch::default().sort(RayOrder::Octant, &bounds, &mut rays, &mut owner);
        // Octants: 2, 1, 2, 0.
        assert_eq!(owner, vec![13, 11, 10, 12]);
        assert_eq!(rays[0].dir, Vec3::ONE);
        assert_eq!(rays[3].dir, Vec3::new(1.0, -1.0, 2.0));
    }

    #[test]
    fn morton_cells_follow_the_curve() {
        let grid = MortonGrid::new(&Aabb { min: Vec3::ZERO, max: Vec3::splat(512.0) });
        assert_eq!(grid.code(Vec3::new(0.5, 0.5, 0.5)), 0);
        assert_eq!(grid.code(Vec3::new(1.5, 0.5, 0.5)), 1);
        assert_eq!(grid.code(Vec3::new(0.5, 1.5, 0.5)), 2);
        assert_eq!(grid.code(Vec3::new(0.5, 0.5, 1.5)), 4);
        assert_eq!(grid.code(Vec3::splat(1e9)), (1 << 27) - 1, "outside: clamped");
        assert_eq!(grid.code(Vec3::splat(f32::NAN)), 0);
        // A degenerate box still gives every point a cell.
        let flat = MortonGrid::new(&Aabb { min: Vec3::ZERO, max: Vec3::new(1.0, 1.0, 0.0) });
        assert!(flat.code(Vec3::new(0.5, 0.5, 0.0)) < 1 << 27);
    }
}
