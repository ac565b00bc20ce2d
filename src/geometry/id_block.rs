//! Compact leaf blocks: the primitive ids of a [`Tri8`] block and nothing else.
//!
//! The scene store already holds each triangle's vertex indices and the vertex positions, so a
//! block of ids (32 bytes for up to eight triangles, Embree's `Triangle4i` idea at M = 8)
//! stands in for the 320-byte [`Tri8`]: a traversal kernel that reaches one builds the
//! [`Tri8`] block on the stack ([`PrimIds8::tri8`]) with exactly the operations of
//! [`TriBlock::set_for`], so its rows are the stored block's bit for bit and every hit is the
//! same, and then runs the block test it runs on stored blocks.

use crate::geometry::{Tri8, TriBlock, TriangleTest};
use crate::math::Vec3;

/// The scene primitive ids of one [`Tri8`] block, lane by lane; `u32::MAX` in padding lanes.
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PrimIds8 {
    /// Primitive ids (triangle indices into the scene store).
    pub prim: [u32; 8],
}
const _: () = assert!(std::mem::size_of::<PrimIds8>() == 32);

impl PrimIds8 {
    /// The ids of `block`.
    pub fn of(block: &Tri8) -> Self {
        Self { prim: block.prim }
    }

    /// The [`Tri8`] block these ids name, laid out for `test`: lane `l` is
    /// `Tri8::set_for(test, l, v0, v1, v2, prim[l])` with the corners of triangle `prim[l]`
    /// (`indices[prim[l]]` into `positions`); padding lanes stay [`Tri8::EMPTY`]'s.
    ///
    /// # Panics
    /// When an id or a vertex index is out of range (a verified tree's are not).
    #[inline(always)]
    pub fn tri8(&self, positions: &[Vec3], indices: &[[u32; 3]], test: TriangleTest) -> Tri8 {
        let mut b = Tri8::EMPTY;
        for (lane, &p) in self.prim.iter().enumerate() {
            if p != u32::MAX {
                let [i0, i1, i2] = indices[p as usize];
                let (v0, v1, v2) = (positions[i0 as usize], positions[i1 as usize], positions[i2 as usize]);
                b.set_for(test, lane, v0, v1, v2, p);
            }
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blocks built from ids equal the blocks `Tri8::set` and `Tri8::set_vertices` store, bit
    /// for bit, for both triangle tests, with padding lanes anywhere.
    #[test]
    fn built_blocks_equal_stored_blocks_bit_for_bit() {
        let mut rng = crate::rng::Rng::new(68, 1);
        let mut f = move || (rng.next_f32() * 2.0 - 1.0) * 10f32.powi((rng.next_f32() * 12.0) as i32 - 6);
        let positions: Vec<Vec3> = (0..3000).map(|_| Vec3::new(f(), f(), f())).collect();
        let mut pick = {
            let mut rng = crate::rng::Rng::new(68, 2);
            move |n: usize| ((rng.next_f32() * n as f32) as usize).min(n - 1)
        };
        let indices: Vec<[u32; 3]> =
            (0..2000).map(|_| [pick(3000) as u32, pick(3000) as u32, pick(3000) as u32]).collect();
        let bits = |b: &Tri8| bytemuck::bytes_of(b).to_vec();
        for k in 0..500 {
            let (mut mt, mut wt) = (Tri8::EMPTY, Tri8::EMPTY);
            for lane in 0..8 {
                if (k + lane) % 5 == 4 || lane >= 8 - k % 4 {
                    continue; // padding
                }
                let p = pick(indices.len());
                let [a, b, c] = indices[p].map(|i| positions[i as usize]);
                mt.set(lane, a, b, c, p as u32);
                wt.set_vertices(lane, a, b, c, p as u32);
            }
            assert_eq!(PrimIds8::of(&mt), PrimIds8 { prim: mt.prim });
            let ids = PrimIds8::of(&mt);
            assert_eq!(bits(&ids.tri8(&positions, &indices, TriangleTest::MollerTrumbore)), bits(&mt), "block {k}");
            assert_eq!(bits(&ids.tri8(&positions, &indices, TriangleTest::Watertight)), bits(&wt), "block {k}");
        }
    }
}
