//! Inputs found by fuzzing (`fuzz/`, see fuzz/README.md) and the hostile headers the loaders
//! must cap, each minimised and pinned to the clear error or the correct result it now gets.
//! Every case must finish fast: a test that regresses into a hang or a huge allocation shows
//! up as a timed-out or killed test run, not as a wrong answer.

use raypack::io::obj::parse_obj;

use raypack::{BuildOptions, Material, Ray, SceneBuilder, Vec3};
use std::path::Path;

mod common;
use common::{expect_error, load_named as load};

/// A COLLADA document with the given libraries and visual-scene nodes.
fn dae(libraries: &str, nodes: &str) -> String {
    format!(
        r##"<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
        {libraries}
        <library_visual_scenes><visual_scene id="s">{nodes}</visual_scene></library_visual_scenes>
        <scene><instance_visual_scene url="#s"/></scene></COLLADA>"##
    )
}

/// One triangle geometry `g` whose position source's accessor carries `accessor_attrs`.
fn triangle_geometry(accessor_attrs: &str) -> String {
    format!(
        r##"<library_geometries><geometry id="g"><mesh>
        <source id="p"><float_array id="pa" count="9">0 0 0 1 0 0 0 1 0</float_array>
          <technique_common><accessor source="#pa" {accessor_attrs}/></technique_common></source>
        <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
        <triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>
        </mesh></geometry></library_geometries>"##
    )
}

// ----- COLLADA: instancing, nesting and counts ----------------------------------------------

#[test]
fn dae_instance_node_cycle_is_an_error_naming_the_instance() {
    // A node that instances itself, and two that instance each other.
    let lib = r##"<library_nodes><node id="a"><instance_node url="#a"/></node>
        <node id="b"><node id="b-child"><instance_node url="#c"/></node></node>
        <node id="c"><instance_node url="#b"/></node></library_nodes>"##;
    for root in ["#a", "#b"] {
        let text = dae(lib, &format!(r#"<node id="top"><instance_node url="{root}"/></node>"#));
        let e = expect_error(text.as_bytes(), "cycle.dae", "<instance_node url=");
        assert!(e.contains("instance_node cycle"), "{e}");
    }
}

#[test]
fn dae_exponential_instancing_hits_the_budget() {
    // Node k instances node k+1 twice, 40 levels deep: 2^40 copies of one triangle from a
    // 5 kB file. Before the instancing budget this ran (practically) forever.
    let mut lib = String::from("<library_nodes>");
    for k in 0..40 {
        lib += &format!(
            r##"<node id="n{k}"><instance_node url="#n{}"/><instance_node url="#n{}"/></node>"##,
            k + 1,
            k + 1
        );
    }
    lib += r##"<node id="n40"><instance_geometry url="#g"/></node></library_nodes>"##;
    let text = dae(&(triangle_geometry("") + &lib), r##"<node id="top"><instance_node url="#n0"/></node>"##);
    let e = expect_error(text.as_bytes(), "bomb.dae", "<");
    assert!(e.contains("instancing expands the scene past 1048576"), "{e}");

    // The same structure 10 levels deep (1024 copies) is fine and yields 1024 triangles.
    let mut lib = String::from("<library_nodes>");
    for k in 0..10 {
        lib += &format!(
            r##"<node id="n{k}"><instance_node url="#n{}"/><instance_node url="#n{}"/></node>"##,
            k + 1,
            k + 1
        );
    }
    lib += r##"<node id="n10"><instance_geometry url="#g"/></node></library_nodes>"##;
    let text = dae(&(triangle_geometry("") + &lib), r##"<node id="top"><instance_node url="#n0"/></node>"##);
    let (b, _) = load(text.as_bytes(), "ok.dae").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(b.num_triangles(), 1024);
}

#[test]
fn dae_deep_nesting_is_an_error_not_a_stack_overflow() {
    let depth = 20_000;
    let nodes = "<node>".repeat(depth) + &"</node>".repeat(depth);
    let e = expect_error(dae("", &nodes).as_bytes(), "deep.dae", "<node>");
    assert!(e.contains("nested deeper than 256"), "{e}");
}

#[test]
fn dae_accessor_offsets_and_counts_from_the_file_cannot_overflow() {
    let node = r##"<node id="n"><instance_geometry url="#g"/></node>"##;
    // usize::MAX offset: `offset + width` used to wrap around and `drain(..offset)` panic.
    let text = dae(&triangle_geometry(r#"count="1" stride="3" offset="18446744073709551615""#), node);
    let e = expect_error(text.as_bytes(), "offset.dae", "<accessor source=\"#pa\">");
    assert!(e.contains("need more than the 9 values"), "{e}");
    // count 0 with an offset past the end: an empty source, not a panic.
    let text = dae(&triangle_geometry(r#"count="0" offset="100""#), node);
    let e = expect_error(text.as_bytes(), "empty.dae", "<p>");
    assert!(e.contains("vertex index 0 out of range (only 0)"), "{e}");
    // A huge count is an error about the array, before any allocation; a huge stride leaves
    // room for one element only.
    let text = dae(&triangle_geometry(r#"count="4000000000""#), node);
    let e = expect_error(text.as_bytes(), "count.dae", "<accessor source=\"#pa\">");
    assert!(e.contains("4000000000 elements of stride 3 need more than the 9 values in the array"), "{e}");
    let text = dae(&triangle_geometry(r#"stride="18446744073709551615""#), node);
    let e = expect_error(text.as_bytes(), "stride.dae", "<p>");
    assert!(e.contains("vertex index 1 out of range (only 1)"), "{e}");
}

#[test]
fn dae_primitive_counts_larger_than_their_index_lists_fail_fast() {
    let node = r##"<node id="n"><instance_geometry url="#g"/></node>"##;
    let geometry = triangle_geometry("");
    // <triangles count="4e9"> over three indices.
    let text = dae(&geometry.replace(r#"<triangles count="1">"#, r#"<triangles count="4000000000">"#), node);
    let e = expect_error(text.as_bytes(), "tris.dae", "<p>");
    assert!(e.contains("has 3 indices but the polygons need 6"), "{e}");
    // A polylist whose one polygon claims 4e9 corners.
    let polylist = geometry.replace(
        r##"<triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>"##,
        r##"<polylist count="1"><input semantic="VERTEX" source="#v" offset="0"/><vcount>4000000000</vcount><p>0 1 2</p></polylist>"##,
    );
    let e = expect_error(dae(&polylist, node).as_bytes(), "poly.dae", "<p>");
    assert!(e.contains("has 3 indices but the polygons need 4000000000"), "{e}");
}

#[test]
fn dae_entity_expansion_is_refused() {
    // "Billion laughs": nested entities that would expand to gigabytes.
    let mut dtd = String::from(r#"<!DOCTYPE COLLADA [<!ENTITY l0 "lol">"#);
    for k in 1..10 {
        let prev = format!("&l{};", k - 1);
        dtd += &format!(r#"<!ENTITY l{k} "{}">"#, prev.repeat(10));
    }
    dtd += "]>";
    let text = format!(r#"<?xml version="1.0"?>{dtd}<COLLADA><asset><title>&l9;</title></asset></COLLADA>"#);
    let e = expect_error(text.as_bytes(), "laughs.dae", "line ");
    assert!(e.contains("malformed XML"), "{e}");
}

// ----- OBJ ----------------------------------------------------------------------------------

#[test]
fn obj_material_library_with_a_short_colour_is_a_warning_not_a_panic() {
    // Found by fuzzing: tobj 4.0.5 unwraps three values for Ka/Kd/Ks/Ke and panicked on `Kd 4`.
    let obj = b"mtllib m.mtl\nusemtl lamp\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let mtl = b"newmtl lamp\nKe 4 4 4\nKd 4\n".to_vec();
    let (b, warnings) = parse_obj(obj, Path::new("short.obj"), &|_| Ok(mtl.clone())).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(b.num_triangles(), 1);
    assert!(
        warnings.iter().any(|w| w.contains("material library m.mtl: line 3: Kd needs 3 values, found 1")),
        "{warnings:?}"
    );
    // The default material, not a half-read lamp: nothing emits.
    let (scene, _) = b.commit(&BuildOptions { keep_bvh2: true, ..BuildOptions::default() });
    assert!(scene.materials.iter().all(|m| m.emission == Vec3::ZERO));
}

#[test]
fn obj_enormous_polygon_and_huge_indices() {
    // One polygon with 100 000 corners fan-triangulates; an index past the vertices is an
    // error naming the line, even when it does not fit in 64 bits.
    let n = 100_000;
    let mut text = String::new();
    for i in 0..n {
        let a = i as f32 / n as f32 * std::f32::consts::TAU;
        text += &format!("v {} {} 0\n", a.cos(), a.sin());
    }
    text += "f";
    for i in 1..=n {
        text += &format!(" {i}");
    }
    text += "\n";
    let (b, _) = load(text.as_bytes(), "big.obj").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(b.num_triangles(), n - 2);
    for index in ["4", "99999999999999999999999", "-4", "0"] {
        let text = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {index}\n");
        expect_error(text.as_bytes(), "index.obj", "line 4");
    }
}

#[test]
fn obj_relative_and_zero_texture_and_normal_indices_are_errors_not_overflows() {
    // Found by fuzzing: tobj 4.0.5 makes `-9` with 3 texture coordinates into 2^64 - 6 and
    // multiplies it by 2 unchecked (a panic with overflow checks on, garbage without).
    let base = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n";
    for (face, what) in [
        ("f 1/-9 2/1 3/1", "texture coordinate index -9 out of range: the file has 3 before this line"),
        ("f 1/0 2/1 3/1", "texture coordinate index 0 out of range"),
        ("f 1//-2 2//1 3//1", "normal index -2 out of range: the file has 1 before this line"),
        ("f 1/1/9223372036854775807 2/1/1 3/1/1", "normal index 9223372036854775807 out of range: the file has 1"),
        ("l 1 -5", "vertex index -5 out of range"),
    ] {
        let text = format!("{base}{face}\n");
        let e = expect_error(text.as_bytes(), "rel.obj", "line 8");
        assert!(e.contains(what), "{face}: {e}");
    }
    // In range, relative indices load.
    let (b, _) = load(format!("{base}f -3/-3/-1 -2/-2/-1 -1/-1/-1\n").as_bytes(), "ok.obj").unwrap();
    assert_eq!(b.num_triangles(), 1);
}

// ----- PLY ----------------------------------------------------------------------------------

#[test]
fn ply_headers_claiming_billions_fail_fast_with_a_clear_error() {
    let header = |format: &str, vertices: &str, faces: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {faces}\nproperty list uchar int vertex_indices\nend_header\n"
        )
    };
    for format in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let text = header(format, "4000000000", "1") + "0 0 0\n";
        let e = expect_error(text.as_bytes(), "v.ply", "line 3");
        assert!(e.contains("claims 4000000000 vertex elements"), "{e}");
        let text = header(format, "3", "4000000000") + &"0 ".repeat(40) + "\n";
        let e = expect_error(text.as_bytes(), "f.ply", "line 7");
        assert!(e.contains("claims 4000000000 face elements"), "{e}");
        // Counts beyond u64 are not numbers.
        let text = header(format, "99999999999999999999999", "1");
        let e = expect_error(text.as_bytes(), "u64.ply", "line 3");
        assert!(e.contains("not a whole number"), "{e}");
    }
    // A list claiming 4e9 items in a small binary body ends at the end of the data.
    let mut bytes = header("binary_little_endian", "3", "1").replace("list uchar int", "list uint int").into_bytes();
    bytes.extend_from_slice(&[0; 36]);
    bytes.extend_from_slice(&4_000_000_000u32.to_le_bytes());
    bytes.extend_from_slice(&[0; 8]);
    let e = expect_error(&bytes, "list.ply", "byte ");
    assert!(e.contains("face 0: unexpected end of file"), "{e}");
}

// ----- build + traverse ---------------------------------------------------------------------

#[test]
fn sphere_hit_whose_point_rounds_onto_the_centre_has_finite_coordinates() {
    // Found by fuzzing: a ray from the centre of a sphere at y = 1.844e18 along a direction with
    // |y| = 1e18 hits at t = 2.125e-18, where `o + t d` rounds back onto the centre; the
    // surface coordinates were atan2/acos of a normalised zero vector, NaN.
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::default());
    let center = Vec3::new(3.875, 1.844e18, 2.25);
    b.add_sphere(center, 2.125, m).unwrap();
    let (scene, report) = b.commit(&BuildOptions { keep_bvh2: true, ..BuildOptions::default() });
    assert_eq!(report.spheres, 1);
    let ray = Ray::new(center, Vec3::new(2.125, 1e18, 0.0));
    let hit = scene.intersect1(&ray);
    assert!(hit.is_hit(), "{hit:?}");
    assert!(hit.t > 0.0 && hit.t.is_finite(), "{hit:?}");
    assert!(hit.u.is_finite() && hit.v.is_finite(), "{hit:?}");
    assert!((0.0..=1.0).contains(&hit.u) && (0.0..=1.0).contains(&hit.v), "{hit:?}");
    let reference = scene.intersect1_reference(&ray);
    assert!(reference.u.is_finite() && reference.v.is_finite(), "{reference:?}");
}

#[test]
fn obj_material_library_that_is_a_device_or_fifo_is_not_read() {
    // `mtllib /dev/zero` used to be read with `fs::read` until memory ran out, and a FIFO
    // blocked the loader forever; now only regular files of at most 64 MiB are read.
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe.mtl");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
    let mut libraries = vec!["/dev/zero".to_string()];
    if made {
        libraries.push("pipe.mtl".to_string());
    } else {
        println!("mkfifo unavailable: the FIFO case is not checked");
    }
    for lib in libraries {
        let obj = dir.path().join("dev.obj");
        std::fs::write(&obj, format!("mtllib {lib}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")).unwrap();
        let raypack::io::LoadedScene { builder: b, warnings, .. } =
            raypack::io::load_scene(&obj).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(b.num_triangles(), 1);
        assert!(warnings.iter().any(|w| w.contains(&lib) && w.contains("not a regular file")), "{warnings:?}");
    }
}
