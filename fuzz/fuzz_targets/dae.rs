//! COLLADA loader on arbitrary bytes: a typed error naming the file, or a scene that commits
//! and traces — never a panic, a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use raypack::io::SceneFormat;

fuzz_target!(|data: &[u8]| {
    raypack_fuzz::load_and_check(data, SceneFormat::Dae, "fuzz.dae");
});
