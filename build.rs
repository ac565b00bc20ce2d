//! Build script: with cargo feature `embree`, compiles the C shim in `tests/embree/` and links
//! the system Embree 3 (`libembree-dev`). Without the feature it does nothing.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "embree")]
    {
        println!("cargo:rerun-if-changed=tests/embree/shim.c");
        println!("cargo:rerun-if-changed=tests/embree/shim.h");
        cc::Build::new()
            .file("tests/embree/shim.c")
            .std("gnu11")
            .opt_level(2)
            .warnings(true)
            .compile("raypack_embree_shim");
        println!("cargo:rustc-link-lib=embree3");
    }
}
