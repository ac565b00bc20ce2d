//! Every file raypack reads because a user named it goes through `raypack::fs::input`
//! (`open_regular` / `read_regular`: regular files only, never blocking, size-capped), and
//! every file it writes through `raypack::fs::output` (`stage` / `write_file`: whole or not at
//! all, never through a link, never over an input). This test reads the sources of the
//! library, the CLI and the Python module and fails when a file is opened, read or written
//! anywhere else, so that the next new input or output cannot skip the rules.

mod common;
use common::rust_sources;
use std::path::Path;

/// Calls that open, read or write a file by name.
const FILE_CALLS: [&str; 8] = [
    "fs::read(",
    "fs::read_to_string(",
    "fs::write(",
    "fs::copy(",
    "File::open(",
    "File::create(",
    "OpenOptions::new(",
    "BitMapBackend::new(",
];

/// The files allowed to make them, and why.
const ALLOWED: [(&str, &str); 4] = [
    ("src/fs/input.rs", "the one reader"),
    ("src/fs/output.rs", "the one writer"),
    ("src/system.rs", "the kernel's own files: /proc and /sys"),
    ("src/bench/machine.rs", "the kernel's own files: /proc"),
];

#[test]
fn files_are_read_and_written_in_one_place_each() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = rust_sources(&[&root.join("src"), &root.join("python/src")]);
    assert!(files.len() > 50, "the sources were not found: {files:?}");
    let mut offences = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
        if ALLOWED.iter().any(|(a, _)| *a == rel) {
            continue;
        }
        let text = std::fs::read_to_string(f).unwrap();
        // Unit tests (the `#[cfg(test)] mod tests` at the end of a file) make their own files.
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap();
        for (i, line) in code.lines().enumerate() {
            let line = line.trim_start();
            if line.starts_with("//") {
                continue;
            }
            if let Some(call) = FILE_CALLS.iter().find(|c| line.contains(*c)) {
                offences.push(format!("{rel}:{}: {call}", i + 1));
            }
        }
    }
    assert!(
        offences.is_empty(),
        "files opened outside raypack::fs::input (reads) and raypack::fs::output (writes): {offences:#?}"
    );
}
