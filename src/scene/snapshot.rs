//! A committed scene as bytes, and back: its store (geometry, materials, lights, camera) and
//! its acceleration structures in the BVH cache's file layout ([`crate::scene::cache`]), so
//! that another process (a Python worker unpickling a `Scene`) gets the scene without
//! building its BVH again.
//!
//! Bytes may come from anywhere, so reading them checks as much as loading a cache file does,
//! and more: the layout, the checksum and the key (recomputed from the geometry and the build
//! options the bytes carry); every index into the store; every material, light and the camera
//! as a scene file's loader checks them; the geometry as [`crate::SceneBuilder::commit`]
//! filters it (nothing it would drop); and the trees as the cache loader checks them. A
//! snapshot that passes yields the scene the bytes were taken from.
//!
//! Sections, besides the cache's `bounds`, `bvh2.*` and `bvh8.*`:
//!
//! | name | element | content |
//! |---|---|---|
//! | `options` | [`OptionsRecord`] | the [`BuildOptions`] the trees were built with (the key covers them) |
//! | `tri.pos`, `tri.nrm` | `Vec3` | vertex positions, shading normals (empty or one per vertex) |
//! | `tri.idx`, `tri.mat` | `[u32; 3]`, `u32` | each triangle's vertices and material |
//! | `sph.center`, `sph.radius`, `sph.mat` | `Vec3`, `f32`, `u32` | spheres |
//! | `materials`, `mat.names` | [`MaterialRecord`], `u8` | materials; their names, concatenated |
//! | `lights` | [`LightRecord`] | lights |
//! | `camera` | [`CameraRecord`] | none or one |

use super::cache::file::{CacheFile, SectionWriter};
use super::cache::{CacheError, CacheKey, check_accel, push_accel, read_accel};
use super::{Bsdf, Camera, Light, Material, Scene, SceneBuilder, SpheresSoa, TrianglesSoa};
use crate::bvh::{BuildOptions, TreeLayout};
use crate::geometry::TriangleTest;
use crate::math::{Mat3, Vec3};
use std::path::Path;
use std::sync::Arc;

/// What errors name the bytes by.
const NAME: &str = "<scene snapshot>";

/// The [`BuildOptions`], field by field.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct OptionsRecord {
    /// `max_leaf_size`, `bins` (0 for `None`), `quality` (0 fast, 1 medium, 2 high), `split`
    /// (0 SAH, 1 median), `watertight`, `keep_bvh2`, `collapse.method` (0 optimal, 1
    /// greedy), `collapse.max_leaf_prims`.
    pub words: [u64; 8],
    /// `spatial_split_budget`, `traversal_cost`, `collapse.node_cost`, `collapse.block_cost`,
    /// `collapse.prim_cost`, `layout` (0 default, 1 compact: the zero of files written before
    /// the compact layout reads as the default one).
    pub floats: [f32; 6],
}

/// A tree layout as the options record stores it.
fn layout_code(l: TreeLayout) -> f32 {
    match l {
        TreeLayout::Default => 0.0,
        TreeLayout::Compact => 1.0,
    }
}

impl OptionsRecord {
    fn of(o: &BuildOptions) -> Self {
        use crate::bvh::{BuildQuality, CollapseMethod, CollapseOptions, SplitMethod};
        // Every field named: a new one must be recorded here.
        let BuildOptions {
            max_leaf_size,
            bins,
            quality,
            spatial_split_budget,
            split,
            traversal_cost,
            watertight,
            collapse: CollapseOptions { method, node_cost, block_cost, prim_cost, max_leaf_prims },
            keep_bvh2,
            layout,
        } = *o;
        let quality = match quality {
            BuildQuality::Fast => 0,
            BuildQuality::Medium => 1,
            BuildQuality::High => 2,
        };
        let split = match split {
            SplitMethod::Sah => 0,
            SplitMethod::Median => 1,
        };
        let method = match method {
            CollapseMethod::Optimal => 0,
            CollapseMethod::Greedy => 1,
        };
        let w = |x: usize| x as u64;
        Self {
            words: [
                w(max_leaf_size),
                w(bins.unwrap_or(0)),
                quality,
                split,
                watertight.into(),
                keep_bvh2.into(),
                method,
                w(max_leaf_prims),
            ],
            floats: [spatial_split_budget, traversal_cost, node_cost, block_cost, prim_cost, layout_code(layout)],
        }
    }

    fn options(&self) -> Result<BuildOptions, String> {
        use crate::bvh::{BuildQuality, CollapseMethod, CollapseOptions, SplitMethod};
        let [max_leaf_size, bins, quality, split, watertight, keep_bvh2, method, max_leaf_prims] = self.words;
        let [spatial_split_budget, traversal_cost, node_cost, block_cost, prim_cost, layout] = self.floats;
        let size = |x: u64| usize::try_from(x).map_err(|_| format!("{x} does not fit a usize"));
        let flag = |x: u64| match x {
            0 | 1 => Ok(x == 1),
            _ => Err(format!("{x} is not a flag")),
        };
        let layout = TreeLayout::ALL
            .into_iter()
            .find(|&l| layout_code(l).to_bits() == layout.to_bits())
            .ok_or_else(|| format!("unknown tree layout {layout}"))?;
        Ok(BuildOptions {
            layout,
            max_leaf_size: size(max_leaf_size)?,
            bins: Some(size(bins)?).filter(|&b| b > 0),
            quality: match quality {
                0 => BuildQuality::Fast,
                1 => BuildQuality::Medium,
                2 => BuildQuality::High,
                q => return Err(format!("unknown quality {q}")),
            },
            spatial_split_budget,
            split: match split {
                0 => SplitMethod::Sah,
                1 => SplitMethod::Median,
                m => return Err(format!("unknown split method {m}")),
            },
            traversal_cost,
            watertight: flag(watertight)?,
            collapse: CollapseOptions {
                method: match method {
                    0 => CollapseMethod::Optimal,
                    1 => CollapseMethod::Greedy,
                    m => return Err(format!("unknown collapse method {m}")),
                },
                node_cost,
                block_cost,
                prim_cost,
                max_leaf_prims: size(max_leaf_prims)?,
            },
            keep_bvh2: flag(keep_bvh2)?,
        })
    }
}

/// One material: its BSDF's kind and parameters, emission, and name.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MaterialRecord {
    /// 0 diffuse, 1 mirror, 2 glass, 3 microfacet.
    pub kind: u32,
    /// The BSDF's numbers in the order of its fields, zero after them.
    pub params: [f32; 8],
    /// Emitted radiance.
    pub emission: [f32; 3],
    /// Where the name starts in `mat.names`.
    pub name_start: u32,
    /// Its length in bytes (UTF-8).
    pub name_len: u32,
}

/// One light: its kind and numbers.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LightRecord {
    /// 0 point, 1 directional, 2 spot, 3 area, 4 environment.
    pub kind: u32,
    /// The light's numbers in the order of its fields, zero after them.
    pub params: [f32; 15],
}

/// The camera: position, the columns of `c2w`, fields of view, clip distances.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CameraRecord {
    /// `position`, `c2w` (three columns), `hfov_deg`, `vfov_deg`, `near`, `far`.
    pub params: [f32; 16],
}

fn v3(v: Vec3) -> [f32; 3] {
    v.to_array()
}

fn params<const N: usize>(parts: &[&[f32]]) -> [f32; N] {
    let mut out = [0.0; N];
    for (o, x) in out.iter_mut().zip(parts.iter().flat_map(|p| p.iter())) {
        *o = *x;
    }
    out
}

impl MaterialRecord {
    fn of(m: &Material, name_start: usize) -> Self {
        let (kind, params) = match m.bsdf {
            Bsdf::Diffuse { albedo } => (0, params(&[&v3(albedo)])),
            Bsdf::Mirror { reflectance } => (1, params(&[&v3(reflectance)])),
            Bsdf::Glass { reflectance, transmittance, ior, roughness } => {
                (2, params(&[&v3(reflectance), &v3(transmittance), &[ior, roughness]]))
            }
            Bsdf::Microfacet { eta, k, alpha } => (3, params(&[&v3(eta), &v3(k), &[alpha]])),
        };
        let (name_start, name_len) = (name_start as u32, m.name.len() as u32);
        Self { kind, params, emission: v3(m.emission), name_start, name_len }
    }

    fn material(&self, names: &[u8]) -> Result<Material, String> {
        let p = &self.params;
        let v = |i: usize| Vec3::new(p[i], p[i + 1], p[i + 2]);
        let bsdf = match self.kind {
            0 => Bsdf::Diffuse { albedo: v(0) },
            1 => Bsdf::Mirror { reflectance: v(0) },
            2 => Bsdf::Glass { reflectance: v(0), transmittance: v(3), ior: p[6], roughness: p[7] },
            3 => Bsdf::Microfacet { eta: v(0), k: v(3), alpha: p[6] },
            k => return Err(format!("unknown BSDF kind {k}")),
        };
        let (start, len) = (self.name_start as usize, self.name_len as usize);
        let name = names
            .get(start..start.saturating_add(len))
            .and_then(|b| std::str::from_utf8(b).ok())
            .ok_or("its name is not UTF-8 inside mat.names")?;
        let m = Material { name: name.to_string(), bsdf, emission: Vec3::from_array(self.emission) };
        m.check()?;
        Ok(m)
    }
}

impl LightRecord {
    fn of(l: &Light) -> Self {
        let (kind, params) = match *l {
            Light::Point { position, intensity } => (0, params(&[&v3(position), &v3(intensity)])),
            Light::Directional { direction, radiance } => (1, params(&[&v3(direction), &v3(radiance)])),
            Light::Spot { position, direction, intensity, inner_angle_deg, outer_angle_deg } => {
                (2, params(&[&v3(position), &v3(direction), &v3(intensity), &[inner_angle_deg, outer_angle_deg]]))
            }
            Light::Area { radiance, position, direction, dim_x, dim_y } => {
                (3, params(&[&v3(radiance), &v3(position), &v3(direction), &v3(dim_x), &v3(dim_y)]))
            }
            Light::Environment { radiance } => (4, params(&[&v3(radiance)])),
        };
        Self { kind, params }
    }

    fn light(&self) -> Result<Light, String> {
        let p = &self.params;
        let v = |i: usize| Vec3::new(p[i], p[i + 1], p[i + 2]);
        let l = match self.kind {
            0 => Light::Point { position: v(0), intensity: v(3) },
            1 => Light::Directional { direction: v(0), radiance: v(3) },
            2 => Light::Spot {
                position: v(0),
                direction: v(3),
                intensity: v(6),
                inner_angle_deg: p[9],
                outer_angle_deg: p[10],
            },
            3 => Light::Area { radiance: v(0), position: v(3), direction: v(6), dim_x: v(9), dim_y: v(12) },
            4 => Light::Environment { radiance: v(0) },
            k => return Err(format!("unknown light kind {k}")),
        };
        l.check()?;
        Ok(l)
    }
}

impl CameraRecord {
    fn of(c: &Camera) -> Self {
        let m = c.c2w;
        let rest = [c.hfov_deg, c.vfov_deg, c.near, c.far];
        Self { params: params(&[&v3(c.position), &v3(m.x_axis), &v3(m.y_axis), &v3(m.z_axis), &rest]) }
    }

    fn camera(&self) -> Result<Camera, String> {
        let p = &self.params;
        let v = |i: usize| Vec3::new(p[i], p[i + 1], p[i + 2]);
        let c = Camera {
            position: v(0),
            c2w: Mat3::from_cols(v(3), v(6), v(9)),
            hfov_deg: p[12],
            vfov_deg: p[13],
            near: p[14],
            far: p[15],
        };
        let fov = |f: f32| f > 0.0 && f < 180.0;
        if !(p.iter().all(|x| x.is_finite()) && fov(c.hfov_deg) && fov(c.vfov_deg) && c.near >= 0.0 && c.near < c.far) {
            return Err(format!(
                "camera {c:?} is not a camera (finite numbers, fields of view in (0, 180), 0 <= near < far)"
            ));
        }
        Ok(c)
    }
}

impl Scene {
    /// The scene as bytes (see the module docs); `opts` are the options it was built with.
    pub fn to_snapshot(&self, opts: &BuildOptions) -> Vec<u8> {
        let key = CacheKey::of(&self.triangles, &self.spheres, opts);
        let options = [OptionsRecord::of(opts)];
        let mut names = Vec::new();
        let materials: Vec<MaterialRecord> = self
            .materials
            .iter()
            .map(|m| {
                let r = MaterialRecord::of(m, names.len());
                names.extend_from_slice(m.name.as_bytes());
                r
            })
            .collect();
        let lights: Vec<LightRecord> = self.lights.iter().map(LightRecord::of).collect();
        let camera: Vec<CameraRecord> = self.camera.iter().map(CameraRecord::of).collect();
        let bounds = [self.bounds];
        let (t, s) = (&self.triangles, &self.spheres);
        let mut w = SectionWriter::new();
        w.push("options", &options);
        w.push("tri.pos", &t.positions);
        w.push("tri.nrm", &t.normals);
        w.push("tri.idx", &t.indices);
        w.push("tri.mat", &t.material);
        w.push("sph.center", &s.center);
        w.push("sph.radius", &s.radius);
        w.push("sph.mat", &s.material);
        w.push("materials", &materials);
        w.push("mat.names", &names);
        w.push("lights", &lights);
        w.push("camera", &camera);
        let tris = super::cache::stored_blocks(self);
        push_accel(&mut w, self, &bounds, &tris);
        let mut out = Vec::new();
        w.write_to(key, &mut out).expect("writing to memory does not fail");
        out
    }

    /// The scene [`Scene::to_snapshot`] made `bytes` of, and the options it was built with,
    /// after checking them (see the module docs). The acceleration structures are used in
    /// place in a private copy of the bytes.
    pub fn from_snapshot(bytes: &[u8]) -> Result<(Scene, BuildOptions), CacheError> {
        let path = Path::new(NAME);
        let malformed = |what: String| CacheError::Malformed { path: path.to_path_buf(), what };
        // A private page-aligned copy, whose sections the trees then use in place.
        let map = {
            let mut copy = memmap2::MmapMut::map_anon(bytes.len().max(1))
                .map_err(|source| CacheError::Io { path: path.to_path_buf(), source })?;
            copy[..bytes.len()].copy_from_slice(bytes);
            Arc::new(copy.make_read_only().map_err(|source| CacheError::Io { path: path.to_path_buf(), source })?)
        };
        let bytes = &map[..bytes.len()];
        // The key is checked below, against the geometry and options the bytes hold.
        let claimed = bytes.get(16..32).map_or(CacheKey(0), |k| CacheKey(u128::from_le_bytes(k.try_into().unwrap())));
        let file = CacheFile::check_mapped(path, &map, claimed)?;
        let opts = match file.section::<OptionsRecord>("options")?[..] {
            [r] => r.options().map_err(|e| malformed(format!("build options: {e}")))?,
            _ => return Err(malformed("options is not one record".into())),
        };
        let triangles = TrianglesSoa {
            positions: file.section("tri.pos")?,
            normals: file.section("tri.nrm")?,
            indices: file.section("tri.idx")?,
            material: file.section("tri.mat")?,
        };
        let spheres = SpheresSoa {
            center: file.section("sph.center")?,
            radius: file.section("sph.radius")?,
            material: file.section("sph.mat")?,
        };
        let key = CacheKey::of(&triangles, &spheres, &opts);
        if key != claimed {
            return Err(CacheError::Stale { path: path.to_path_buf(), found: claimed, expected: key });
        }
        let names = file.section::<u8>("mat.names")?;
        let materials = file
            .section::<MaterialRecord>("materials")?
            .iter()
            .enumerate()
            .map(|(i, r)| r.material(&names).map_err(|e| malformed(format!("material {i}: {e}"))))
            .collect::<Result<Vec<_>, _>>()?;
        let lights = file
            .section::<LightRecord>("lights")?
            .iter()
            .enumerate()
            .map(|(i, r)| r.light().map_err(|e| malformed(format!("light {i}: {e}"))))
            .collect::<Result<Vec<_>, _>>()?;
        let camera = match file.section::<CameraRecord>("camera")?[..] {
            [] => None,
            [c] => Some(c.camera().map_err(malformed)?),
            _ => return Err(malformed("more than one camera".into())),
        };
        check_indices(&triangles, &spheres, materials.len()).map_err(malformed)?;
        let (kept, report) = SceneBuilder::from_parts(triangles, spheres, materials, lights, camera).filter();
        if report.dropped() > 0 {
            return Err(malformed(format!("holds primitives a commit drops: {report}")));
        }
        let mut accel = read_accel(&file)?;
        // The key covers the options, so the blocks are laid out for this triangle test.
        accel.bvh8.test = TriangleTest::from_watertight(opts.watertight);
        // The trees verified against the geometry they index (`scene::verify`).
        check_accel(&accel, (&kept.triangles, &kept.spheres)).map_err(malformed)?;
        let accel = accel.into_layout(opts.layout);
        Ok((kept.with_accel(accel.bounds, accel.bvh2, accel.bvh8), opts))
    }
}

/// Every vertex, normal and material reference of the store in range.
fn check_indices(t: &TrianglesSoa, s: &SpheresSoa, materials: usize) -> Result<(), String> {
    let nv = t.positions.len();
    if !(t.normals.is_empty() || t.normals.len() == nv) {
        return Err(format!("{} normals for {nv} vertices", t.normals.len()));
    }
    if t.material.len() != t.indices.len() {
        return Err(format!("{} material ids for {} triangles", t.material.len(), t.indices.len()));
    }
    if let Some(i) = t.indices.iter().position(|tri| tri.iter().any(|&v| v as usize >= nv)) {
        return Err(format!("triangle {i} has a vertex index out of range ({nv} vertices)"));
    }
    if s.radius.len() != s.center.len() || s.material.len() != s.center.len() {
        return Err("the sphere arrays differ in length".into());
    }
    if let Some(i) = t.material.iter().chain(&s.material).position(|&m| m as usize >= materials) {
        return Err(format!("primitive {i} has a material id out of range ({materials} materials)"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Hit, Ray};

    fn scene(watertight: bool) -> (Scene, BuildOptions) {
        let mut b = crate::testing::cornell_box();
        let m = b.add_material(Material {
            name: "gold é".into(),
            bsdf: Bsdf::Microfacet { eta: Vec3::ONE, k: Vec3::ONE, alpha: 0.3 },
            emission: Vec3::ZERO,
        });
        let g = crate::generate::grid(3, 2);
        b.add_mesh(&g.positions, &g.indices, m).unwrap();
        b.add_light(Light::Spot {
            position: Vec3::Y,
            direction: -Vec3::Y,
            intensity: Vec3::ONE,
            inner_angle_deg: 10.0,
            outer_angle_deg: 20.0,
        });
        let opts = BuildOptions {
            watertight,
            keep_bvh2: watertight,
            quality: if watertight { crate::BuildQuality::High } else { crate::BuildQuality::Fast },
            bins: watertight.then_some(32),
            layout: if watertight { TreeLayout::Compact } else { TreeLayout::Default },
            ..BuildOptions::default()
        };
        (b.commit(&opts).0, opts)
    }

    #[test]
    fn snapshots_give_back_the_scene_and_its_hits() {
        for watertight in [false, true] {
            let (s, opts) = scene(watertight);
            let bytes = s.to_snapshot(&opts);
            let (back, back_opts) = Scene::from_snapshot(&bytes).unwrap();
            assert_eq!(back_opts, opts);
            assert_eq!(back.materials, s.materials);
            assert_eq!(back.lights, s.lights);
            assert_eq!(back.camera, s.camera);
            assert_eq!(back.triangles.positions, s.triangles.positions);
            assert_eq!(back.bvh8.test, s.bvh8.test);
            assert_eq!((back.layout(), s.layout()), (opts.layout, opts.layout));
            assert_eq!(back.bvh8.ids, s.bvh8.ids);
            assert_eq!(back.bvh2.is_some(), watertight);
            let rays = crate::raysets::primary_for_scene(&s, 32, 24);
            let (mut a, mut b) = (vec![Hit::MISS; rays.len()], vec![Hit::MISS; rays.len()]);
            s.intersect_stream(&rays, &mut a, &crate::StreamOptions::POOL);
            back.intersect_stream(&rays, &mut b, &crate::StreamOptions::POOL);
            assert!(a.iter().zip(&b).all(|(x, y)| x.t.to_bits() == y.t.to_bits() && x.prim == y.prim));
            assert!(a.iter().any(Hit::is_hit));
            let _ = Ray::new(Vec3::ZERO, Vec3::X);
        }
    }

    #[test]
    fn damaged_snapshots_are_refused() {
        let (s, opts) = scene(false);
        let bytes = s.to_snapshot(&opts);
        // Every byte matters: the checksum covers them all.
        for i in (0..bytes.len()).step_by(97) {
            let mut bad = bytes.clone();
            bad[i] ^= 0x04;
            assert!(Scene::from_snapshot(&bad).is_err(), "flipped byte {i} accepted");
        }
        assert!(Scene::from_snapshot(&bytes[..bytes.len() - 1]).is_err());
        assert!(Scene::from_snapshot(&[]).is_err());
    }

    /// Snapshots of scenes no commit makes, with a valid checksum and key: refused, naming
    /// what is wrong.
    #[test]
    fn forged_snapshots_are_refused() {
        let forge = |edit: &dyn Fn(&mut Scene), says: &str| {
            let (mut s, opts) = scene(false);
            edit(&mut s);
            let e = Scene::from_snapshot(&s.to_snapshot(&opts)).map(|_| ()).unwrap_err().to_string();
            assert!(e.contains(says), "{says}: {e}");
        };
        forge(&|s| s.triangles.indices[3][1] = 1 << 30, "triangle 3 has a vertex index out of range");
        forge(&|s| s.triangles.material[0] = 99, "material id out of range");
        forge(&|s| s.triangles.normals.push(Vec3::Z), "normals for");
        forge(&|s| s.materials[0].bsdf = Bsdf::Diffuse { albedo: Vec3::splat(2.0) }, "material 0: albedo");
        forge(&|s| s.lights.push(Light::Point { position: Vec3::ZERO, intensity: -Vec3::ONE }), "light");
        forge(&|s| s.triangles.positions[0] = Vec3::NAN, "a commit drops");
        forge(&|s| s.camera = Some(Camera { near: 5.0, far: 1.0, ..s.camera.unwrap() }), "not a camera");
        forge(&|s| s.bvh8.tris.to_mut().clear(), "8-wide BVH");
    }
}
