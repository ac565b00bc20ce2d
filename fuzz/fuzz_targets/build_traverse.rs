//! Build + traverse on arbitrary floats: the input decodes (see `raypack_fuzz::SceneInput`)
//! into vertices, triangles, spheres, rays and `BuildOptions`; the committed scene's BVH must
//! be valid, and `intersect1` / `occluded1` must answer what the reference BVH2 traversal and
//! brute force answer, with every hit in `[tnear, tfar]`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use raypack_fuzz::SceneInput;

fuzz_target!(|data: &[u8]| {
    SceneInput::decode(data).run();
});
