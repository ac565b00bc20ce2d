//! `raypack bench --rays FILE` and `--dump-rays DIR`: the ray sets a benchmark times, read
//! from or written to ray files ([`raypack::io::rays`]).

use crate::say;
use crate::{BenchArgs, CliError};
use raypack::Scene;
use raypack::bench::BenchSettings;
use raypack::io::rays::{read_rays, write_rays};
use raypack::raysets::{self, RaySet, RaySetKind};

/// The sets `a` asks for: the file's rays (`--rays`), the built-in sets after writing them
/// to `--dump-rays DIR`, or `None` (the built-in sets, made by the benchmark).
pub(crate) fn ray_sets(
    a: &BenchArgs,
    scene: &Scene,
    settings: &BenchSettings,
) -> Result<Option<Vec<RaySet>>, CliError> {
    if let Some(file) = &a.rays {
        let rays = read_rays(file)?;
        if rays.is_empty() {
            return Err(CliError::Usage(format!("--rays {}: the file holds no rays", file.display())));
        }
        say::line(format_args!("{} rays from {}", rays.len(), file.display()));
        return Ok(Some(vec![RaySet { kind: RaySetKind::File, rays }]));
    }
    let Some(dir) = &a.dump_rays else { return Ok(None) };
    std::fs::create_dir_all(dir)
        .map_err(|e| CliError::Usage(format!("--dump-rays {}: cannot create the directory: {e}", dir.display())))?;
    let sets = raysets::bench_sets(scene, settings.width, settings.height, settings.seed).to_vec();
    for set in &sets {
        for ext in ["rays", "npy"] {
            let path = dir.join(format!("{}.{ext}", set.kind.name()));
            write_rays(&path, &set.rays)?;
            say::line(format_args!("wrote {} {} rays to {}", set.rays.len(), set.kind.name(), path.display()));
        }
    }
    Ok(Some(sets))
}
