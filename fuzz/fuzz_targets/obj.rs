//! OBJ loader (with an MTL library) on arbitrary bytes: a typed error naming the file, or a
//! scene that commits and traces. The input is the OBJ text, optionally followed by a line
//! `#MTL` and the text of the material library every `mtllib` statement then reads.
#![no_main]

use libfuzzer_sys::fuzz_target;
use raypack::io::obj::parse_obj;
use std::path::Path;

const SPLIT: &[u8] = b"\n#MTL\n";

fuzz_target!(|data: &[u8]| {
    let (obj, mtl) = match data.windows(SPLIT.len()).position(|w| w == SPLIT) {
        Some(i) => (&data[..i], Some(data[i + SPLIT.len()..].to_vec())),
        None => (data, None),
    };
    match parse_obj(obj, Path::new("fuzz.obj"), &|_| mtl.clone().ok_or_else(|| "no #MTL part".to_string())) {
        Ok((builder, _)) => {
            raypack_fuzz::commit_and_trace(builder);
        }
        Err(e) => raypack_fuzz::check_error(&e, "fuzz.obj"),
    }
});
