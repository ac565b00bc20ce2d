//! Compares two linear images (OpenEXR, as `raypack render -f NAME.exr` writes them): the mean
//! of each, the root-mean-square difference between them over all pixels and channels, and
//! how many pixels are the same bit for bit.
//! Two renders of one scene with different seeds give the renderer's noise (RMSE = √2 σ).
//!
//! `cargo run --release --features tools --bin image_rmse -- a.exr b.exr`

use exr::prelude::{ReadChannels, ReadLayers, read};
use std::process::ExitCode;

/// The RGB pixels of `path`, row by row.
fn load(path: &str) -> Result<(usize, usize, Vec<[f32; 3]>), String> {
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |size, _| (size.width(), size.height(), vec![[0.0f32; 3]; size.area()]),
            |(w, _, px), pos, (r, g, b, _a): (f32, f32, f32, f32)| px[pos.y() * *w + pos.x()] = [r, g, b],
        )
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| format!("{path}: {e}"))?;
    Ok(image.layer_data.channel_data.pixels)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [a, b] = args.as_slice() else {
        eprintln!("usage: image_rmse A.exr B.exr");
        return ExitCode::from(2);
    };
    let (a, b) = match (load(a), load(b)) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("image_rmse: {e}");
            return ExitCode::from(2);
        }
    };
    if (a.0, a.1) != (b.0, b.1) {
        eprintln!("image_rmse: sizes differ: {}x{} and {}x{}", a.0, a.1, b.0, b.1);
        return ExitCode::from(2);
    }
    let n = (a.2.len() * 3) as f64;
    let mean = |px: &[[f32; 3]]| px.iter().flatten().map(|&v| v as f64).sum::<f64>() / n;
    let sq: f64 = a.2.iter().flatten().zip(b.2.iter().flatten()).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum();
    if let Some((i, (x, y))) =
        a.2.iter().zip(&b.2).enumerate().find(|(_, (x, y))| x.map(f32::to_bits) != y.map(f32::to_bits))
    {
        eprintln!("first different pixel: ({}, {}): {x:?} and {y:?}", i % a.0, i / a.0);
    }
    let same = a.2.iter().zip(&b.2).filter(|(x, y)| x.map(f32::to_bits) == y.map(f32::to_bits)).count();
    println!(
        "mean_a {:.6} mean_b {:.6} rmse {:.6} bit_identical_pixels {same}/{}",
        mean(&a.2),
        mean(&b.2),
        (sq / n).sqrt(),
        a.2.len()
    );
    ExitCode::SUCCESS
}
