// The README's "Use it as a library" example (tests/readme.rs checks the README quotes this
// file verbatim, so the example it shows always compiles).
use raypack::{BuildOptions, Ray, Vec3};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).unwrap_or_else(|| "scenes/cornell.dae".into());
    let loaded = raypack::io::load_scene(path.as_ref())?; // the library never prints:
    for warning in &loaded.warnings {
        eprintln!("warning: {warning}"); // its warnings are returned
    }
    let (scene, _report) = loaded.builder.commit(&BuildOptions::default());
    let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::new(0.0, 0.0, -1.0));
    let hit = scene.intersect1(&ray);
    if hit.is_hit() {
        println!("hit primitive {} at t = {} (barycentrics {}, {})", hit.prim, hit.t, hit.u, hit.v);
    } else {
        println!("missed");
    }
    Ok(())
}
