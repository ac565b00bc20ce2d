//! Scene files that are well-formed but say something meaningless or costly (issue 19):
//! negative light, impossible materials, polylines, missing materials, polygon counts that
//! disagree, and instancing that multiplies a small file. Each is an error naming the file and
//! the element or line, or a warning that says what was substituted; the expansion of
//! instancing is reported and capped by `--max-primitives`.

use raypack::io::load_scene;

mod common;
use common::{expect_error, load_named};

const CORNELL: &str = include_str!("../scenes/cornell.dae");

/// `CORNELL` with `from` (which must occur) replaced by `to`.
fn cornell_with(from: &str, to: &str) -> String {
    assert!(CORNELL.contains(from), "{from:?} is not in cornell.dae");
    CORNELL.replacen(from, to, 1)
}

#[test]
fn negative_light_is_an_error_naming_the_element() {
    // The ceiling lamp's area light and its emissive surface.
    let doc = cornell_with("<area>\n            <color sid=\"color\">3 3 3</color>", "<area><color>-12 12 12</color>");
    let e = expect_error(doc.as_bytes(), "area.dae", "<light id=\"Lamp-light\">/<extra>");
    assert!(e.contains("<area>/<color>") && e.contains("radiance -12 12 12 must be finite and non-negative"), "{e}");
    let doc = cornell_with("<radiance>3 3 3</radiance>", "<radiance>12 -1 12</radiance>");
    let e = expect_error(doc.as_bytes(), "emission.dae", "<effect id=\"lamp-effect\">");
    assert!(e.contains("<emission>") && e.contains("emission 12 -1 12 must be finite and non-negative"), "{e}");
    let doc = cornell_with("<emission><color sid=\"emission\">0 0 0 1</color>", "<emission><color>0 0 -0.5 1</color>");
    let e = expect_error(doc.as_bytes(), "phong.dae", "<effect id=\"white-effect\">");
    assert!(e.contains("emission 0 0 -0.5"), "{e}");
    // Point and ambient lights.
    for (kind, what) in [("point", "intensity"), ("ambient", "radiance"), ("directional", "radiance")] {
        let light = format!(
            "<light id=\"L\"><technique_common><{kind}><color>-1 -1 -1</color></{kind}></technique_common></light>"
        );
        let doc = cornell_with("</library_lights>", &format!("{light}</library_lights>")).replacen(
            "<instance_light url=\"#Lamp-light\"/>",
            "<instance_light url=\"#L\"/>",
            1,
        );
        let e = expect_error(doc.as_bytes(), "light.dae", &format!("<light id=\"L\">/<technique_common>/<{kind}>"));
        assert!(e.contains(&format!("{what} -1 -1 -1 must be finite and non-negative")), "{kind}: {e}");
    }
}

#[test]
fn impossible_materials_are_errors_naming_the_element() {
    let mirror = "<mirror>\n            <reflectance>0.95 0.95 0.95</reflectance>\n          </mirror>";
    let microfacet = |alpha: &str, eta: &str, k: &str| {
        format!("<microfacet><alpha>{alpha}</alpha><eta>{eta}</eta><k>{k}</k></microfacet>")
    };
    for (what, replacement, message) in [
        ("alpha 0", microfacet("0", "0.2 0.9 1.1", "3.9 2.4 2.2"), "alpha 0 must be in (0, 1]"),
        ("alpha -1", microfacet("-1", "0.2 0.9 1.1", "3.9 2.4 2.2"), "alpha -1 must be in (0, 1]"),
        ("alpha 1e30", microfacet("1e30", "0.2 0.9 1.1", "3.9 2.4 2.2"), "must be in (0, 1]"),
        (
            "negative eta",
            microfacet("0.3", "-0.2 0.9 1.1", "3.9 2.4 2.2"),
            "eta -0.2 0.9 1.1 must be finite and positive",
        ),
        (
            "negative k",
            microfacet("0.3", "0.2 0.9 1.1", "3.9 -2.4 2.2"),
            "k 3.9 -2.4 2.2 must be finite and non-negative",
        ),
        (
            "mirror reflectance 1e30",
            "<mirror><reflectance>1e30 1e30 1e30</reflectance></mirror>".to_string(),
            "reflectance 1000000000000000000000000000000 1000000000000000000000000000000 1000000000000000000000000000000 \
             must be finite and in [0, 1]",
        ),
    ] {
        let doc = cornell_with(mirror, &replacement);
        let e = expect_error(
            doc.as_bytes(),
            "m.dae",
            "<effect id=\"mirror-effect\">/<extra>/<technique profile=\"CMU462\">/<",
        );
        assert!(e.contains(message), "{what}: {e}");
    }
    // A valid microfacet still loads, and glass with ior <= 0 is still refused.
    let doc = cornell_with(mirror, &microfacet("0.3", "0.2 0.9 1.1", "3.9 2.4 2.2"));
    load_named(doc.as_bytes(), "ok.dae").unwrap();
    let doc = cornell_with("<ior>1.5</ior>", "<ior>0</ior>");
    let e = expect_error(doc.as_bytes(), "g.dae", "<glass>");
    assert!(e.contains("index of refraction 0 must be positive"), "{e}");
    // A diffuse colour beyond 1 creates energy.
    let doc = cornell_with("0.63 0.065 0.05 1", "63 0.065 0.05 1");
    let e = expect_error(doc.as_bytes(), "d.dae", "<effect id=\"red-effect\">");
    assert!(e.contains("albedo 63 0.065 0.05 must be finite and in [0, 1]"), "{e}");
}

#[test]
fn polylist_whose_vcount_disagrees_with_p_is_an_error() {
    // The ceiling: one quad of 4 corners, 2 inputs per corner (8 indices).
    let doc = cornell_with(
        "<vcount>4</vcount>\n          <p>4 1 7 1 6 1 5 1</p>",
        "<vcount>3</vcount><p>4 1 7 1 6 1 5 1</p>",
    );
    let e = expect_error(doc.as_bytes(), "v.dae", "<polylist material=\"white-symbol\">/<p>");
    assert!(e.contains("has 8 indices but the polygons use only 6 (3 corners, 2 inputs per corner)"), "{e}");
    // More polygon sizes than the count says.
    let doc = cornell_with(
        "<vcount>4</vcount>\n          <p>4 1 7 1 6 1 5 1</p>",
        "<vcount>4 4</vcount><p>4 1 7 1 6 1 5 1</p>",
    );
    let e = expect_error(doc.as_bytes(), "c.dae", "<polylist material=\"white-symbol\">/<vcount>");
    assert!(e.contains("2 polygon sizes for count 1"), "{e}");
    // The same for <triangles>: more indices than its count uses.
    let doc = cornell_with("<p>0 0 1 0 2 0  0 0 2 0 3 0</p>", "<p>0 0 1 0 2 0  0 0 2 0 3 0  0 0</p>");
    let e = expect_error(doc.as_bytes(), "t.dae", "<triangles material=\"white-symbol\">/<p>");
    assert!(e.contains("has 14 indices but the polygons use only 12"), "{e}");
}

#[test]
fn obj_polylines_missing_materials_and_bad_colours_are_said_out_loud() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("scene.obj");
    std::fs::write(
        &obj,
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nusemtl hot\nf 1 2 3\nl 1 2 3 4\nusemtl nosuch\nf 2 4 3\n\
         l 4 1\nusemtl nosuch\nf 1 3 4\n",
    )
    .unwrap();
    std::fs::write(dir.path().join("m.mtl"), "newmtl hot\nKd 2 0.5 0.5\nKe 1 -1 1\n").unwrap();
    let raypack::io::LoadedScene { builder: b, warnings, .. } = load_scene(&obj).unwrap();
    // Polylines are not faces: three triangles, not five.
    assert_eq!(b.num_triangles(), 3, "{warnings:?}");
    let has = |s: &str| warnings.iter().any(|w| w.contains(s));
    assert!(has("2 polylines (`l` statements, the first at line 8) skipped"), "{warnings:?}");
    assert!(has("line 9: usemtl \"nosuch\": no material of that name"), "{warnings:?}");
    assert_eq!(warnings.iter().filter(|w| w.contains("nosuch")).count(), 1, "reported once: {warnings:?}");
    assert!(has("material \"hot\": Kd 2 0.5 0.5 outside [0, 1]; clamped to 1 0.5 0.5"), "{warnings:?}");
    assert!(has("material \"hot\": Ke 1 -1 1 is negative; clamped to 1 0 1"), "{warnings:?}");
    assert!(warnings.iter().all(|w| w.starts_with(obj.to_str().unwrap())), "every warning names the file");

    // NaN colours: the library is not used, and the warning names its line.
    std::fs::write(dir.path().join("m.mtl"), "newmtl hot\nKd 0.5 0.5 0.5\nKe nan 1 1\n").unwrap();
    let raypack::io::LoadedScene { builder: b, warnings, .. } = load_scene(&obj).unwrap();
    assert!(
        warnings.iter().any(|w| w.contains("material library m.mtl: line 3: Ke value nan is not a finite number")
            && w.contains("using the default material")),
        "{warnings:?}"
    );
    let (scene, _) = b.commit(&raypack::BuildOptions::default());
    assert!(scene.materials.iter().all(|m| m.emission.is_finite() && !m.is_emissive()));
    std::fs::write(dir.path().join("m.mtl"), "newmtl hot\nKd inf 0.5 0.5\n").unwrap();
    let warnings = load_scene(&obj).unwrap().warnings;
    assert!(warnings.iter().any(|w| w.contains("line 2: Kd value inf is not a finite number")), "{warnings:?}");
}

/// A COLLADA document whose one geometry (a grid of `2 n²` triangles) is instanced
/// `2^levels` times through nested `instance_node`s.
/// `raypack info PATH --quality fast EXTRA`: its exit code and stderr.
fn info_fast(path: &std::path::Path, extra: &[&str]) -> (Option<i32>, String) {
    let args = [&["info", path.to_str().unwrap(), "--quality", "fast"][..], extra].concat();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_raypack")).args(&args).output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn instanced_grid(n: usize, levels: usize) -> String {
    let g = raypack::generate::grid(n, n);
    let floats: Vec<String> = g.positions.iter().flat_map(|p| [p.x, p.y, p.z]).map(|v| v.to_string()).collect();
    let idx: Vec<String> = g.indices.iter().flatten().map(|i| i.to_string()).collect();
    let mut nodes = String::from("<node id=\"n0\"><instance_geometry url=\"#g\"/></node>");
    for l in 1..=levels {
        nodes += &format!(
            "<node id=\"n{l}\"><node id=\"a{l}\"><instance_node url=\"#n{p}\"/></node>\
             <node id=\"b{l}\"><translate>0 0 {l}</translate><instance_node url=\"#n{p}\"/></node></node>",
            p = l - 1
        );
    }
    format!(
        r##"<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
        <library_geometries><geometry id="g"><mesh>
          <source id="p"><float_array id="pa" count="{nf}">{floats}</float_array></source>
          <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
          <triangles count="{nt}"><input semantic="VERTEX" source="#v" offset="0"/><p>{idx}</p></triangles>
        </mesh></geometry></library_geometries>
        <library_nodes>{nodes}</library_nodes>
        <library_visual_scenes><visual_scene id="s"><node id="root"><instance_node url="#n{levels}"/></node></visual_scene></library_visual_scenes>
        <scene><instance_visual_scene url="#s"/></scene></COLLADA>"##,
        nf = floats.len(),
        floats = floats.join(" "),
        nt = g.indices.len(),
        idx = idx.join(" "),
    )
}

#[test]
fn instancing_expansion_is_reported_and_capped_by_max_primitives() {
    let dir = tempfile::tempdir().unwrap();
    // 512 triangles instanced 2^12 times: 2.1 M triangles from a 15 kB file, past the default
    // budget of 2^20 (64 per byte would be 1 M).
    let doc = instanced_grid(16, 12);
    let path = dir.path().join("inst.dae");
    std::fs::write(&path, &doc).unwrap();
    let info = |extra: &[&str]| info_fast(&path, extra);
    // The default budget refuses it, naming the instance and the option.
    let (code, err) = info(&[]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("inst.dae:<node id=") && err.contains("--max-primitives"), "{err}");
    // A service's own cap: refused once the count passes it.
    let (code, err) = info(&["--max-primitives", "1000000"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("more than --max-primitives 1000000"), "{err}");
    // A cap above it: loaded, and the expansion reported.
    let (code, err) = info(&["--max-primitives", "3000000"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains(
            "instancing expands the 512 primitives of 1 instanced geometries to 2097152 triangles and spheres"
        ),
        "{err}"
    );
    // Every format honours the cap.
    let obj = dir.path().join("quad.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\nf 1 2 3 4\n").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_raypack"))
        .args(["info", obj.to_str().unwrap(), "--max-primitives", "3"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("quad.obj:line 7: the faces so far make 4 triangles, more than --max-primitives 3"), "{err}");
    let ply = dir.path().join("two.ply");
    let bytes = raypack::io::ply::write_ply(
        &[raypack::Vec3::ZERO, raypack::Vec3::X, raypack::Vec3::Y],
        &[[0, 1, 2], [0, 2, 1]],
        raypack::io::ply::PlyFormat::Ascii,
    );
    std::fs::write(&ply, bytes).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_raypack"))
        .args(["info", ply.to_str().unwrap(), "--max-primitives", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("two.ply:element face: 2 triangles, more than --max-primitives 1"), "{err}");
}

#[test]
fn a_small_file_cannot_need_gigabytes_unless_asked() {
    let dir = tempfile::tempdir().unwrap();
    // 9,800 triangles instanced 2^9 times: 5.0 M triangles, hundreds of megabytes to build,
    // from a file of a few hundred kilobytes, within the instancing budget.
    let doc = instanced_grid(70, 9);
    let path = dir.path().join("inst.dae");
    std::fs::write(&path, &doc).unwrap();
    let cap = raypack::scene::footprint::default_max_primitives(doc.len() as u64);
    assert!(cap < 5_017_600, "the default cap {cap} does not refuse this file");
    let info = |extra: &[&str]| info_fast(&path, extra);
    let (code, err) = info(&[]);
    assert_eq!(code, Some(2), "{err}");
    let want = format!("more than the {cap} raypack allows a file of {} bytes without --max-primitives", doc.len());
    assert!(err.contains("inst.dae:<node id=") && err.contains(&want), "{err}");
    assert!(err.contains("give --max-primitives N to allow more"), "{err}");
    // Asked for, it loads.
    let (code, err) = info(&["--max-primitives", "5017600"]);
    assert_eq!(code, Some(0), "{err}");
}
