//! `raypack --version`: which binary this is. The version, the commit it was built from
//! (`-dirty` when its sources differed from that commit), the cargo features compiled in, the
//! Embree it was built against and the one it runs with, and the kernels' ISA tier on this
//! CPU (after `RAYPACK_ISA`).

use raypack::Isa;

/// The commit `build.rs` recorded: `git rev-parse --short HEAD`, "-dirty" appended when the
/// build's sources differed from it; "unknown" without git or a checkout.
pub(crate) fn commit() -> &'static str {
    option_env!("RAYPACK_GIT_COMMIT").unwrap_or("unknown")
}

/// The cargo features this binary was built with.
fn features() -> Vec<&'static str> {
    let mut f = vec!["cli"];
    if cfg!(feature = "image") {
        f.push("image");
    }
    if cfg!(feature = "embree") {
        f.push("embree");
    }
    f
}

/// The Embree line: what `build.rs` found, and the version of the library loaded at run time
/// (a device made on a one-triangle scene, which is how a version is asked of Embree).
#[cfg(feature = "embree")]
fn embree() -> String {
    use raypack::embree::{EmbreeOptions, EmbreeScene};
    use raypack::math::Vec3;
    let triangle = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let linked =
        match EmbreeScene::from_mesh(&triangle, &[[0, 1, 2]], EmbreeOptions { threads: 1, ..Default::default() }) {
            Ok(e) => format!("Embree {} linked", e.version()),
            Err(e) => format!("the linked Embree fails: {e}"),
        };
    format!("{linked}; built against {}", raypack::embree::EMBREE_FOUND)
}

#[cfg(not(feature = "embree"))]
fn embree() -> String {
    "not built in (cargo install --path . --features embree)".into()
}

/// The kernels' tier and why: RAYPACK_ISA's when it names a tier this CPU has, else the best.
fn isa() -> String {
    let (used, best) = (Isa::default_for_process(), Isa::detected());
    let why = match Isa::from_env() {
        Ok(Some(asked)) if asked <= best => format!("RAYPACK_ISA={asked}; this CPU's best is {best}"),
        Ok(Some(asked)) => format!("RAYPACK_ISA={asked} is above this CPU's best"),
        Err(_) => "RAYPACK_ISA is not a tier name; this CPU's best".into(),
        Ok(None) => "this CPU's best; RAYPACK_ISA or --isa lower it".into(),
    };
    format!("{used} ({why})")
}

/// The text `raypack --version` prints.
pub(crate) fn text() -> String {
    format!(
        "raypack {}\ncommit: {}\nfeatures: {}\nembree: {}\nkernels: {}\n",
        env!("CARGO_PKG_VERSION"),
        commit(),
        features().join(", "),
        embree(),
        isa()
    )
}
