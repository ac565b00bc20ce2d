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
    /// (16 cells per axis).
    OctantMorton,
    /// By the origin's cell along a Morton curve over the scene's bounds (32 cells per axis).
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

/// Bits per axis of the Morton key: 32 cells per axis, 15 bits, so that octant and cell fit
/// the 16-bit key of two 8-bit radix passes.
const MORTON_BITS: u32 = 5;

/// Bits per axis under [`RayOrder::OctantMorton`] (3 bits are the octant's).
const OCTANT_MORTON_BITS: u32 = 4;

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

/// Maps points of a box to the Morton codes of its `2^bits` cells per axis.
#[derive(Clone, Copy, Debug)]
struct MortonGrid {
    lo: Vec3,
    scale: Vec3,
    max: f32,
}

impl MortonGrid {
    fn new(bounds: &Aabb, bits: u32) -> Self {
        let cells = (1u32 << bits) as f32;
        let extent = (bounds.max - bounds.min).max(Vec3::splat(f32::MIN_POSITIVE));
        let scale = Vec3::splat(cells) / extent;
        let ok = bounds.min.is_finite() && scale.is_finite();
        let (lo, scale) = if ok { (bounds.min, scale) } else { (Vec3::ZERO, Vec3::ZERO) };
        Self { lo, scale, max: cells - 1.0 }
    }

    #[inline]
    fn code(&self, p: Vec3) -> u32 {
        // `as u32` saturates and sends NaN to 0: any origin gets a cell.
        let c = ((p - self.lo) * self.scale).clamp(Vec3::ZERO, Vec3::splat(self.max));
        spread3(c.x as u32) | (spread3(c.y as u32) << 1) | (spread3(c.z as u32) << 2)
    }
}

/// Buffers of [`SortScratch::sort`], kept from one sort to the next.
#[derive(Clone, Debug, Default)]
pub struct SortScratch {
    keys: [Vec<u16>; 2],
    index: [Vec<u32>; 2],
    rays: Vec<Ray>,
    owner: Vec<u32>,
}

impl SortScratch {
    /// Makes room for sorting `n` rays.
    pub fn reserve(&mut self, n: usize) {
        for v in self.keys.iter_mut() {
            v.reserve(n.saturating_sub(v.len()));
        }
        for v in self.index.iter_mut().chain([&mut self.owner]) {
            v.reserve(n.saturating_sub(v.len()));
        }
        self.rays.reserve(n.saturating_sub(self.rays.len()));
    }

    /// Bytes [`SortScratch::reserve`] takes per ray.
    pub fn bytes_per_ray() -> usize {
        2 * std::mem::size_of::<u16>() + 2 * std::mem::size_of::<u32>() + std::mem::size_of::<Ray>() + 4
    }

    /// Sorts `rays` and `owner` (same length) together by `order`'s key, stably (an LSD radix
    /// sort on 16-bit keys: one or two counting passes).
    pub fn sort(&mut self, order: RayOrder, bounds: &Aabb, rays: &mut Vec<Ray>, owner: &mut Vec<u32>) {
        debug_assert_eq!(rays.len(), owner.len());
        if order == RayOrder::Queued || rays.len() < 2 {
            return;
        }
        let grid =
            MortonGrid::new(bounds, if order == RayOrder::OctantMorton { OCTANT_MORTON_BITS } else { MORTON_BITS });
        let key = |r: &Ray| -> u16 {
            (match order {
                RayOrder::Queued => 0,
                RayOrder::Octant => octant(r.dir),
                RayOrder::OctantMorton => (octant(r.dir) << (3 * OCTANT_MORTON_BITS)) | grid.code(r.origin),
                RayOrder::Morton => grid.code(r.origin),
            }) as u16
        };
        let [k0, k1] = &mut self.keys;
        let [i0, i1] = &mut self.index;
        k0.clear();
        k0.extend(rays.iter().map(key));
        i0.clear();
        i0.extend(0..rays.len() as u32);
        let passes = if order == RayOrder::Octant { 1 } else { 2 };
        for pass in 0..passes {
            let shift = 8 * pass;
            let mut start = [0u32; 256];
            for &k in k0.iter() {
                start[(k >> shift) as usize & 0xff] += 1;
            }
            let mut sum = 0;
            for s in start.iter_mut() {
                (*s, sum) = (sum, sum + *s);
            }
            k1.clear();
            k1.resize(k0.len(), 0);
            i1.clear();
            i1.resize(i0.len(), 0);
            for (&k, &i) in k0.iter().zip(i0.iter()) {
                let b = &mut start[(k >> shift) as usize & 0xff];
                k1[*b as usize] = k;
                i1[*b as usize] = i;
                *b += 1;
            }
            std::mem::swap(k0, k1);
            std::mem::swap(i0, i1);
        }
        self.rays.clear();
        self.rays.extend(i0.iter().map(|&i| rays[i as usize]));
        self.owner.clear();
        self.owner.extend(i0.iter().map(|&i| owner[i as usize]));
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
        let grid = MortonGrid::new(&Aabb { min: Vec3::ZERO, max: Vec3::splat(32.0) }, MORTON_BITS);
        assert_eq!(grid.code(Vec3::new(0.5, 0.5, 0.5)), 0);
        assert_eq!(grid.code(Vec3::new(1.5, 0.5, 0.5)), 1);
        assert_eq!(grid.code(Vec3::new(0.5, 1.5, 0.5)), 2);
        assert_eq!(grid.code(Vec3::new(0.5, 0.5, 1.5)), 4);
        assert_eq!(grid.code(Vec3::splat(1e9)), (1 << 15) - 1, "outside: clamped");
        assert_eq!(grid.code(Vec3::splat(f32::NAN)), 0);
        // A degenerate box still gives every point a cell.
        let flat = MortonGrid::new(&Aabb { min: Vec3::ZERO, max: Vec3::new(1.0, 1.0, 0.0) }, MORTON_BITS);
        assert!(flat.code(Vec3::new(0.5, 0.5, 0.0)) < 1 << 15);
    }

    #[test]
    fn radix_order_is_the_key_order_and_stable() {
        // Rays on a line through the box in a scrambled order: Morton order sorts them by x
        // (cells along x alone are Morton codes 0, 1, 8, 9, ...), equal cells keep their order.
        let bounds = Aabb { min: Vec3::ZERO, max: Vec3::splat(32.0) };
        let xs: Vec<f32> = (0..200).map(|i| ((i * 37) % 64) as f32 * 0.5).collect();
        let mut rays: Vec<Ray> = xs.iter().map(|&x| Ray::new(Vec3::new(x, 0.0, 0.0), Vec3::X)).collect();
        let mut owner: Vec<u32> = (0..200).collect();
        SortScratch::default().sort(RayOrder::Morton, &bounds, &mut rays, &mut owner);
        for w in owner.windows(2) {
            let (a, b) = (xs[w[0] as usize].floor(), xs[w[1] as usize].floor());
            assert!(a < b || (a == b && w[0] < w[1]), "{w:?}");
        }
        assert!(rays.iter().zip(&owner).all(|(r, &o)| r.origin.x == xs[o as usize]));
    }
}
