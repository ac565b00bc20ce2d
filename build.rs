//! Build script: with cargo feature `embree`, finds Embree 3 or 4, compiles the C shim in
//! `src/embree/` against it and links it. Without the feature it does nothing.
//!
//! Where Embree is looked for, first found wins:
//! 1. `RAYPACK_EMBREE_DIR`: an install prefix (Intel's release archives, a CMake install)
//!    holding `include/embree4/` or `include/embree3/` and the library in `lib/` or `lib64/`;
//!    the binaries get that directory as their run path.
//! 2. pkg-config: `embree4`, then `embree3`.
//! 3. The system headers: `/usr/include` and `/usr/local/include` (Debian's `libembree-dev`
//!    installs Embree 3 there without a pkg-config file, `libembree4-dev` Embree 4).
//!
//! `RAYPACK_EMBREE_VERSION=3` or `4` restricts the search to one major version (both may be
//! installed side by side); otherwise Embree 4 is preferred where a step finds both.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    git_commit();
    #[cfg(feature = "embree")]
    embree::build();
}

/// `RAYPACK_GIT_COMMIT`: `git rev-parse --short HEAD` when git and a checkout are there, with
/// `-dirty` when the files the build reads differ from that commit (`raypack --version` and the
/// bench report name it); "unknown" in a source archive or without git.
fn git_commit() {
    let git = |args: &[&str]| {
        let out = std::process::Command::new("git").args(args).output().ok().filter(|o| o.status.success())?;
        Some(String::from_utf8(out.stdout).ok()?.trim().to_string())
    };
    let Some(commit) = git(&["rev-parse", "--short", "HEAD"]).filter(|s| !s.is_empty()) else {
        println!("cargo:rustc-env=RAYPACK_GIT_COMMIT=unknown");
        return;
    };
    // Only the files that go into the binaries count: an edited README does not make it dirty.
    let built_from = ["src", "build.rs", "Cargo.toml", "Cargo.lock", "scenes"];
    let status = git(&[&["status", "--porcelain", "--untracked-files=no", "--"][..], &built_from].concat());
    let dirty = if status.is_some_and(|s| !s.is_empty()) { "-dirty" } else { "" };
    println!("cargo:rustc-env=RAYPACK_GIT_COMMIT={commit}{dirty}");
    // Rebuild when HEAD moves (HEAD itself, the branch it names, the packed refs), when the
    // index changes, and when a file the build reads changes (which may make it dirty).
    let refs = ["HEAD", "packed-refs", "index"].map(String::from).into_iter();
    for path in refs.chain(git(&["symbolic-ref", "-q", "HEAD"]).filter(|s| !s.is_empty())) {
        if let Some(p) = git(&["rev-parse", "--git-path", &path]).filter(|p| std::path::Path::new(p).exists()) {
            println!("cargo:rerun-if-changed={p}");
        }
    }
    for path in built_from.into_iter().filter(|p| *p != "build.rs" && std::path::Path::new(p).exists()) {
        println!("cargo:rerun-if-changed={path}");
    }
}

#[cfg(feature = "embree")]
mod embree {
    use std::path::{Path, PathBuf};

    /// An Embree to build against.
    struct Found {
        major: u32,
        include: Vec<PathBuf>,
        /// How it was found, for the build's warning line.
        how: String,
    }

    pub fn build() {
        println!("cargo:rerun-if-changed=src/embree/shim.c");
        println!("cargo:rerun-if-changed=src/embree/shim.h");
        println!("cargo:rerun-if-env-changed=RAYPACK_EMBREE_DIR");
        println!("cargo:rerun-if-env-changed=RAYPACK_EMBREE_VERSION");
        let majors: Vec<u32> = match std::env::var("RAYPACK_EMBREE_VERSION").ok().as_deref() {
            None | Some("") => vec![4, 3],
            Some("3") => vec![3],
            Some("4") => vec![4],
            Some(other) => fail(&format!("RAYPACK_EMBREE_VERSION={other}: expected 3 or 4")),
        };
        let found = from_dir(&majors).or_else(|| from_pkg_config(&majors)).or_else(|| from_system(&majors));
        let Some(found) = found else {
            fail(&format!(
                "no Embree {} found. Install it (Debian/Ubuntu: `apt-get install libembree-dev` for Embree 3, \
                 `libembree4-dev` for Embree 4), point PKG_CONFIG_PATH at its embree4.pc/embree3.pc, or set \
                 RAYPACK_EMBREE_DIR to an install prefix holding include/embree{{3,4}}/ and lib/",
                majors.iter().map(|m| m.to_string()).collect::<Vec<_>>().join(" or ")
            ))
        };
        println!("cargo:rustc-env=RAYPACK_EMBREE_FOUND=Embree {} ({})", found.major, found.how);
        let mut cc = cc::Build::new();
        cc.file("src/embree/shim.c")
            .std("gnu11")
            .opt_level(2)
            .warnings(true)
            .define("RAYPACK_EMBREE_MAJOR", found.major.to_string().as_str());
        for dir in &found.include {
            cc.include(dir);
            // The shim's struct layouts follow the headers (Embree 4's `rtcore_config.h` adds
            // fields to `RTCHit` with instance arrays): recompile it when they change.
            let headers = dir.join(format!("embree{}", found.major));
            if headers.is_dir() {
                println!("cargo:rerun-if-changed={}", headers.display());
            }
        }
        cc.compile("raypack_embree_shim");
    }

    fn fail(message: &str) -> ! {
        eprintln!("raypack build (feature `embree`): {message}");
        std::process::exit(1);
    }

    /// `RAYPACK_EMBREE_DIR`: an install prefix.
    fn from_dir(majors: &[u32]) -> Option<Found> {
        let dir = PathBuf::from(std::env::var_os("RAYPACK_EMBREE_DIR").filter(|d| !d.is_empty())?);
        let Some(&major) = majors.iter().find(|m| dir.join(format!("include/embree{m}/rtcore.h")).is_file()) else {
            fail(&format!(
                "RAYPACK_EMBREE_DIR={}: no include/embree4/rtcore.h or include/embree3/rtcore.h there",
                dir.display()
            ))
        };
        let Some(lib) = ["lib", "lib64"].iter().map(|l| dir.join(l)).find(|l| has_library(l, major)) else {
            fail(&format!("RAYPACK_EMBREE_DIR={}: no libembree{major}.so in lib/ or lib64/", dir.display()))
        };
        println!("cargo:rustc-link-search=native={}", lib.display());
        println!("cargo:rustc-link-lib=embree{major}");
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
        Some(Found { major, include: vec![dir.join("include")], how: format!("RAYPACK_EMBREE_DIR={}", dir.display()) })
    }

    fn has_library(dir: &Path, major: u32) -> bool {
        ["so", "a", "dylib"].iter().any(|ext| dir.join(format!("libembree{major}.{ext}")).exists())
    }

    /// pkg-config's `embree4` or `embree3` (it prints the link lines itself).
    fn from_pkg_config(majors: &[u32]) -> Option<Found> {
        majors.iter().find_map(|&major| {
            let lib = pkg_config::Config::new().probe(&format!("embree{major}")).ok()?;
            Some(Found { major, include: lib.include_paths, how: format!("pkg-config embree{major} {}", lib.version) })
        })
    }

    /// Headers in the system include directories, the library on the linker's default path.
    fn from_system(majors: &[u32]) -> Option<Found> {
        majors.iter().find_map(|&major| {
            let root = ["/usr/include", "/usr/local/include"]
                .into_iter()
                .find(|r| Path::new(r).join(format!("embree{major}/rtcore.h")).is_file())?;
            println!("cargo:rustc-link-lib=embree{major}");
            if root.starts_with("/usr/local") {
                println!("cargo:rustc-link-search=native=/usr/local/lib");
            }
            Some(Found { major, include: Vec::new(), how: format!("{root}/embree{major}") })
        })
    }
}
