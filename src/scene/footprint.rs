//! What a scene takes in memory: the bytes of a committed store ([`store_bytes`]; the BVHs
//! count their own, [`crate::bvh::Bvh8::bytes`] and [`crate::bvh::Bvh2::bytes`]), and the
//! budget a scene file may fill without the user asking for more ([`default_max_primitives`]).

use super::Scene;
use crate::system::available;

/// Bytes per primitive (triangle or sphere) a scene needs at its peak while it is loaded and
/// built: the parsed file's vertices and indices, the committed store and the builder's
/// temporaries: the peak resident memory per triangle that `raypack info FILE --quality
/// medium` reports, rounded up (PERFORMANCE.md, "Smaller measured choices").
pub const SCENE_BYTES_PER_PRIMITIVE: u64 = 128;

/// The memory a scene may need without the user asking for more (`--max-primitives`): 512 MiB
/// (4 M primitives), or [`DEFAULT_SCENE_BYTES_PER_FILE_BYTE`] per byte of its file when that is
/// more. A file that is not instanced holds at most about one primitive per byte (an OBJ
/// face line or a PLY polygon costs a byte or more per triangle), so only COLLADA instancing
/// meets this cap: a small file that instances its geometry millions of times must ask.
pub const DEFAULT_SCENE_BYTES: u64 = 512 << 20;
/// See [`DEFAULT_SCENE_BYTES`]: four primitives per byte of the file.
pub const DEFAULT_SCENE_BYTES_PER_FILE_BYTE: u64 = 4 * SCENE_BYTES_PER_PRIMITIVE;

/// The most primitives a scene file of `file_bytes` bytes may make without `--max-primitives`
/// (the CLI's default cap): what [`DEFAULT_SCENE_BYTES`] allows for its size, and never more
/// than fits in the memory this process may allocate ([`available`]), as `-r` is refused
/// when its buffers cannot fit.
pub fn default_max_primitives(file_bytes: u64) -> u64 {
    let budget = DEFAULT_SCENE_BYTES.max(file_bytes.saturating_mul(DEFAULT_SCENE_BYTES_PER_FILE_BYTE));
    let budget = available().map_or(budget, |a| budget.min(a.bytes));
    budget / SCENE_BYTES_PER_PRIMITIVE
}

/// Bytes of a committed scene's geometry store: vertex positions and normals, indices,
/// per-triangle materials and spheres (materials, lights and camera excluded).
pub fn store_bytes(scene: &Scene) -> usize {
    let t = &scene.triangles;
    let s = &scene.spheres;
    std::mem::size_of_val(t.positions.as_slice())
        + std::mem::size_of_val(t.normals.as_slice())
        + std::mem::size_of_val(t.indices.as_slice())
        + std::mem::size_of_val(t.material.as_slice())
        + std::mem::size_of_val(s.center.as_slice())
        + std::mem::size_of_val(s.radius.as_slice())
        + std::mem::size_of_val(s.material.as_slice())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_primitive_cap_grows_with_the_file_within_the_memory_available() {
        let fits = available().map_or(u64::MAX, |a| a.bytes / SCENE_BYTES_PER_PRIMITIVE);
        let floor = DEFAULT_SCENE_BYTES / SCENE_BYTES_PER_PRIMITIVE;
        assert_eq!(default_max_primitives(0), floor.min(fits));
        assert_eq!(default_max_primitives(1000), floor.min(fits));
        assert_eq!(default_max_primitives(10 << 20), (40u64 << 20).min(fits));
        assert_eq!(default_max_primitives(u64::MAX / 2), (u64::MAX / SCENE_BYTES_PER_PRIMITIVE).min(fits));
    }
}
