//! `raypack merge`: reads image parts (OpenEXR files of `raypack render` with a window),
//! checks that they come from one render and cover the image, and writes the whole image,
//! whole or not at all.

use crate::say;
use crate::{CliError, MergeArgs};
use raypack::render::merge::{MergeError, Merger};
use raypack::render::part::{ImagePart, PartError, PartHeader};
use raypack::render::{Encoding, ImageFormat, IntegratorKind};
use std::path::{Path, PathBuf};

/// Largest part file read: a 32768 × 32768 image of uncompressed 32-bit RGB and its headers.
const MAX_PART_BYTES: u64 = (1 << 30) * 12 + (1 << 26);

/// Bytes per pixel of the merge: the canvas's radiance and owner, and the encoded image.
const CANVAS_BYTES_PER_PIXEL: u64 = 12 + 4 + 12;

/// Why parts were not merged.
#[derive(Debug, thiserror::Error)]
pub(crate) enum MergeFailure {
    /// A part could not be read.
    #[error("cannot read {}: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },
    /// A part is not an image part raypack wrote.
    #[error("{}: {source}", path.display())]
    NotAPart { path: PathBuf, source: PartError },
    /// The parts do not make one image.
    #[error("{0}; nothing written{hint}", hint = hint(.0))]
    Parts(MergeError),
}

/// What to do about the parts that do not make one image.
fn hint(e: &MergeError) -> String {
    match e {
        MergeError::Missing { regions, .. } => {
            let cmds: Vec<String> =
                regions.iter().take(4).map(|r| format!("--pixel-bounds {} {} {} {}", r.x0, r.x1, r.y0, r.y1)).collect();
            format!(" (render the missing pixels with the same flags and {})", cmds.join(", "))
        }
        _ => String::new(),
    }
}

/// Refuses to allocate `bytes` for `what` when the process cannot.
fn check_memory(bytes: u64, what: &str) -> Result<(), CliError> {
    use raypack::system::{available, human};
    match available() {
        Some(avail) if bytes > avail.bytes => Err(CliError::Usage(format!(
            "{what} needs about {}, but only {} can be allocated ({})",
            human(bytes),
            human(avail.bytes),
            avail.source
        ))),
        _ => Ok(()),
    }
}

/// `raypack merge PARTS... -o IMAGE`.
pub(crate) fn cmd_merge(a: MergeArgs) -> Result<(), CliError> {
    let format = match ImageFormat::for_path(&a.output) {
        Some(f) if a.output.extension().is_some() && a.output != Path::new("-") => f,
        _ => {
            return Err(CliError::Usage(format!(
                "-o {}: name the whole image .exr (linear radiance, the file a whole render writes) or .png (8-bit sRGB)",
                a.output.display()
            )));
        }
    };
    let inputs: Vec<&Path> = a.parts.iter().map(PathBuf::as_path).collect();
    let out_opts = raypack::fs::output::OutputOptions::protecting(&inputs);
    raypack::fs::output::check_target(&a.output, &out_opts)?;
    let mut merger = Merger::new();
    for path in &a.parts {
        let bytes = raypack::fs::input::read_regular(path, MAX_PART_BYTES, "image parts")
            .map_err(|source| MergeFailure::Read { path: path.clone(), source })?;
        let not_part = |source| MergeFailure::NotAPart { path: path.clone(), source };
        let header = PartHeader::read(&bytes).map_err(not_part)?;
        if merger.is_empty() {
            // The whole image (its pixels and who holds each), then its encoding.
            let (w, h) = (header.width, header.height);
            check_memory((w * h) as u64 * CANVAS_BYTES_PER_PIXEL, &format!("the whole {w}x{h} image"))?;
        }
        check_memory(header.window.area() as u64 * 12, &format!("the pixels of {}", path.display()))?;
        let part = ImagePart::decode_exr(&bytes).map_err(not_part)?;
        drop(bytes);
        merger.add(&path.display().to_string(), &part).map_err(MergeFailure::Parts)?;
    }
    let (whole, report) = merger.finish().map_err(MergeFailure::Parts)?;
    let encode_error = |message| raypack::render::ImageError::Encode { path: a.output.clone(), message };
    let bytes = match format {
        ImageFormat::Exr => whole.encode_exr().map_err(encode_error)?,
        ImageFormat::Png => {
            // As `raypack render` encodes its integrator's film.
            let kind = whole.provenance.get("integrator").and_then(IntegratorKind::from_name);
            let encoding = kind.map_or(Encoding::Srgb, |k| k.encoding());
            whole.film.encode(ImageFormat::Png, encoding).map_err(encode_error)?
        }
    };
    raypack::fs::output::write_file_with(&a.output, &bytes, &out_opts)?;
    if !a.quiet {
        say::line(format_args!(
            "Merged {} parts into {} ({}x{}){}.",
            report.parts,
            a.output.display(),
            whole.width,
            whole.height,
            if report.overlapping_pixels > 0 {
                format!("; {} pixels were in more than one part, with equal values", report.overlapping_pixels)
            } else {
                String::new()
            }
        ));
    }
    Ok(())
}
