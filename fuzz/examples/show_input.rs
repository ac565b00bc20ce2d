//! Prints what a `build_traverse` input decodes to, and each ray's answers, for turning a
//! crash artifact into a regression test:
//!
//! ```sh
//! cargo run --manifest-path fuzz/Cargo.toml --example show_input -- fuzz/artifacts/build_traverse/crash-…
//! ```

use raypack::SceneBuilder;
use raypack_fuzz::SceneInput;

fn main() {
    let path = std::env::args().nth(1).expect("usage: show_input FILE");
    let data = std::fs::read(&path).expect("readable input");
    let input = SceneInput::decode(&data);
    println!("options {:?}", input.options);
    println!("positions {:?}", input.positions);
    println!("triangles {:?}", input.triangles);
    println!("spheres {:?}", input.spheres);
    let mut b = SceneBuilder::new();
    let m = b.add_material(raypack::Material::default());
    if let Err(e) = b.add_mesh(&input.positions, &input.triangles, m) {
        println!("add_mesh: {e}");
    }
    for &(c, r) in &input.spheres {
        b.add_sphere(c, r, m).unwrap();
    }
    let (scene, report) = b.commit(&input.options);
    println!("commit: {report}");
    for (i, spec) in input.rays.iter().enumerate() {
        let ray = input.ray(spec);
        println!("ray {i}: {ray:?}");
        println!("  intersect1           {:?}", scene.intersect1(&ray));
        println!("  intersect1_reference {:?}", scene.intersect1_reference(&ray));
        println!("  brute force          {:?}", scene.intersect1_brute_force(&ray));
        println!("  occluded1 {} reference {}", scene.occluded1(&ray), scene.occluded1_reference(&ray));
    }
}
