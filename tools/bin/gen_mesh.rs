//! Writes a deterministic large test mesh as binary little-endian PLY: a displaced torus
//! knot, closed, with `2 * n_len * n_around` triangles close to the requested count.
//!
//! ```sh
//! cargo run --release --features tools --bin gen_mesh -- 5000000 /tmp/knot-5m.ply
//! ```
//! (`tools/gen-mesh` wraps this and generates the 1M, 5M and 20M set.)

use raypack::generate::torus_knot;
use raypack::io::ply::{PlyFormat, write_ply};
use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let (Some(count), Some(out)) = (args.get(1).and_then(|s| s.parse::<usize>().ok()), args.get(2)) else {
        eprintln!("usage: gen_mesh TRIANGLES OUT.ply   (TRIANGLES >= 64)");
        return ExitCode::from(2);
    };
    if !(64..=1 << 31).contains(&count) {
        eprintln!("gen_mesh: TRIANGLES must be between 64 and 2^31, not {count}");
        return ExitCode::from(2);
    }
    // Keep quads roughly square: the knot is ~20x longer than the tube's circumference.
    let quads = count / 2;
    let n_around = ((quads as f64 / 20.0).sqrt().round() as usize).max(4);
    let n_len = (quads / n_around).max(4);
    let t = std::time::Instant::now();
    let mesh = torus_knot(n_len, n_around, 2.0, 3.0, 0.45, 0.08);
    let bytes = write_ply(&mesh.positions, &mesh.indices, PlyFormat::BinaryLittleEndian);
    let path = PathBuf::from(out);
    let result = raypack::fs::output::write_file(&path, &bytes);
    if let Err(e) = result {
        eprintln!("gen_mesh: {e}");
        return ExitCode::from(2);
    }
    eprintln!(
        "gen_mesh: {} triangles, {} vertices, {:.1} MB in {:.2} s -> {}",
        mesh.indices.len(),
        mesh.positions.len(),
        bytes.len() as f64 / 1e6,
        t.elapsed().as_secs_f64(),
        path.display()
    );
    ExitCode::SUCCESS
}
