//! PLY loader on arbitrary bytes: the parser's mesh has every index in range; loading gives a
//! typed error naming the file or a scene that commits and traces.
#![no_main]

use libfuzzer_sys::fuzz_target;
use raypack::io::SceneFormat;
use raypack::io::ply::parse_ply;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    match parse_ply(data, Path::new("fuzz.ply")) {
        Ok(mesh) => {
            let n = mesh.positions.len();
            assert!(mesh.triangles.iter().flatten().all(|&i| (i as usize) < n), "index out of range");
            // Nothing is allocated beyond what the bytes can describe.
            assert!(mesh.positions.len() <= data.len() && mesh.triangles.len() <= data.len() * 2);
        }
        Err(e) => raypack_fuzz::check_error(&e, "fuzz.ply"),
    }
    raypack_fuzz::load_and_check(data, SceneFormat::Ply, "fuzz.ply");
});
