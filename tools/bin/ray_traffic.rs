//! Where a single ray's memory traffic goes: per ray of each of `raypack bench`'s ray sets,
//! the inner nodes it visits and the leaf blocks it tests (the single-ray kernels' counts),
//! and the bytes those are, split into nodes and blocks, beside the tree's own split. The
//! measure behind the choice of which layout to shrink for incoherent rays in large trees
//! (PERFORMANCE.md, "Where an incoherent ray's bytes go").
//!
//! Usage: ray_traffic SCENE [-r W H]

use raypack::bvh::{Bvh8Node, DefaultTriBlock, TraversalCounts};
use raypack::{BuildOptions, Ray};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).ok_or("usage: ray_traffic SCENE [-r W H]")?;
    let (mut width, mut height) = (512usize, 384usize);
    if args.get(2).map(String::as_str) == Some("-r") {
        width = args.get(3).ok_or("-r W H")?.parse()?;
        height = args.get(4).ok_or("-r W H")?.parse()?;
    }
    let builder = raypack::io::load_scene(std::path::Path::new(path))?.builder;
    let (scene, _) = builder.commit(&BuildOptions::default());
    let (node_bytes, block_bytes) = (size_of::<Bvh8Node>(), size_of::<DefaultTriBlock>());
    let stats = scene.bvh8().stats();
    let prims = (scene.num_triangles() + scene.num_spheres()).max(1) as f64;
    let tree_nodes = stats.nodes * node_bytes;
    let tree_blocks = stats.tri_blocks * block_bytes;
    println!(
        "tree: {} nodes x {node_bytes} B = {:.1} MB ({:.1} B/prim), {} triangle blocks x {block_bytes} B = {:.1} MB \
         ({:.1} B/prim): nodes {:.0} % of the bytes",
        stats.nodes,
        tree_nodes as f64 / 1e6,
        tree_nodes as f64 / prims,
        stats.tri_blocks,
        tree_blocks as f64 / 1e6,
        tree_blocks as f64 / prims,
        100.0 * tree_nodes as f64 / (tree_nodes + tree_blocks) as f64
    );
    println!(
        "{:<8} {:>10} {:>10} {:>11} {:>13} {:>14} {:>8}",
        "set", "rays", "nodes/ray", "blocks/ray", "node B/ray", "block B/ray", "nodes %"
    );
    for set in raypack::raysets::bench_sets(&scene, width, height, 1) {
        let mut counts = TraversalCounts::default();
        let mut q = scene.counting(&mut counts);
        let occlusion = set.kind.is_occlusion();
        for r in &set.rays {
            let r: &Ray = r;
            if occlusion {
                q.occluded1(r);
            } else {
                q.intersect1(r);
            }
        }
        let n = set.rays.len().max(1) as f64;
        let (nodes, blocks) = (counts.nodes as f64 / n, counts.blocks as f64 / n);
        let (nb, bb) = (nodes * node_bytes as f64, blocks * block_bytes as f64);
        println!(
            "{:<8} {:>10} {:>10.1} {:>11.1} {:>13.0} {:>14.0} {:>8.0}",
            set.kind.name(),
            set.rays.len(),
            nodes,
            blocks,
            nb,
            bb,
            100.0 * nb / (nb + bb)
        );
    }
    Ok(())
}
