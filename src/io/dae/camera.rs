//! Cameras: `<instance_camera>` with a `<perspective>` (CS184's defaults for what is
//! missing), and where the scene camera goes ([`CameraPlacement`]): CS184's placement around
//! the bounding box, or the file's own eye.

use super::Ctx;
use super::scene_graph::project;
use super::xml::{child, without_path};
use crate::io::LoadError;
use crate::math::{Aabb, Mat3, Mat4, Vec3, Vec4};
use crate::scene::Camera;
use roxmltree::Node;

/// How the COLLADA camera becomes the scene camera.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CameraPlacement {
    /// As CS184 does: aimed at the bounding-box centre from the file camera's direction, at
    /// 1.5 × the box diagonal (see the module docs).
    #[default]
    Cs184,
    /// The file's camera position and orientation, unchanged.
    AsAuthored,
}

/// A COLLADA camera and the world matrix of its node.
#[derive(Clone, Copy, Debug)]
pub(super) struct CameraInfo {
    hfov: f32,
    vfov: f32,
    near: f32,
    far: f32,
    world: Mat4,
}

impl CameraInfo {
    pub(super) fn as_authored(&self) -> Camera {
        let position = project(&self.world, Vec3::ZERO);
        let l = Mat3::from_mat4(self.world);
        let forward = (l * -Vec3::Z).normalize_or(-Vec3::Z);
        let up = l * Vec3::Y;
        let mut cam = Camera::look_at(position, position + forward, up, self.vfov, 1.0, self.near, self.far);
        cam.hfov_deg = self.hfov;
        cam
    }

    /// `Application::load` + `Camera::place` + `compute_position`.
    pub(super) fn cs184(&self, bounds: &Aabb) -> Option<Camera> {
        // `(transform * Vector4D(view_dir, 1)).to3D().unit()`: a point transform, no divide.
        let c_dir = (self.world * Vec4::new(0.0, 0.0, -1.0, 1.0)).truncate().try_normalize()?;
        let target = bounds.center();
        let r = 1.5 * bounds.extent().length() as f64;
        let mut phi = (c_dir.y as f64).clamp(-1.0, 1.0).acos();
        if phi.sin() == 0.0 {
            phi += 1e-5; // CS184's EPS_F
        }
        let theta = (c_dir.x as f64).atan2(c_dir.z as f64);
        let to_camera = Vec3::new(
            (r * phi.sin() * theta.sin()) as f32,
            (r * phi.cos()) as f32,
            (r * phi.sin() * theta.cos()) as f32,
        );
        if r == 0.0 || !to_camera.is_finite() {
            return None;
        }
        let up = Vec3::new(0.0, if phi.sin() > 0.0 { 1.0 } else { -1.0 }, 0.0);
        let x = up.cross(to_camera).try_normalize()?;
        let y = to_camera.cross(x).try_normalize()?;
        Some(Camera {
            position: target + to_camera,
            c2w: Mat3::from_cols(x, y, to_camera.normalize()),
            hfov_deg: self.hfov,
            vfov_deg: self.vfov,
            near: self.near,
            far: self.far,
        })
    }
}

impl<'a, 'i> Ctx<'a, 'i> {
    pub(super) fn instance_camera(&mut self, ic: Node<'a, 'i>, world: &Mat4) -> Result<(), LoadError> {
        let cam = match self.resolve(ic, "url", "camera") {
            Ok(c) => c,
            Err(e) => {
                self.warnings.push(format!("{}; camera skipped", without_path(e)));
                return Ok(());
            }
        };
        let persp =
            child(cam, "optics").and_then(|o| child(o, "technique_common")).and_then(|t| child(t, "perspective"));
        let Some(p) = persp else {
            self.warn(
                cam,
                "no <optics>/<technique_common>/<perspective> (only perspective cameras are supported); camera skipped",
            );
            return Ok(());
        };
        let get = |tag: &'static str| child(p, tag).map(|n| self.number(n)).transpose();
        let (xfov, yfov, aspect) = (get("xfov")?, get("yfov")?, get("aspect_ratio")?);
        let half_tan = |deg: f32| (deg.to_radians() * 0.5).tan();
        let to_deg = |t: f32| (2.0 * t.atan()).to_degrees();
        let (hfov, vfov) = match (xfov, yfov, aspect) {
            (Some(x), Some(y), _) => (x, y),
            (Some(x), None, Some(a)) if a > 0.0 => (x, to_deg(half_tan(x) / a)),
            (None, Some(y), Some(a)) if a > 0.0 => (to_deg(half_tan(y) * a), y),
            (None, Some(y), _) => (50.0, y),
            _ => {
                return Err(
                    self.err(p, "incomplete perspective: needs <yfov>, or <xfov> with a positive <aspect_ratio>")
                );
            }
        };
        let near = get("znear")?.unwrap_or(0.001);
        let far = get("zfar")?.unwrap_or(1000.0);
        if !(hfov > 0.0 && hfov < 180.0 && vfov > 0.0 && vfov < 180.0) {
            return Err(self.err(p, format!("fields of view must be in (0, 180) degrees, found {hfov} and {vfov}")));
        }
        if !(near >= 0.0 && far > near) {
            return Err(self.err(p, format!("clip planes must satisfy 0 <= znear < zfar, found {near} and {far}")));
        }
        if self.camera.is_some() {
            self.warn(ic, "more than one camera: the last one is used, as in CS184");
        }
        self.camera = Some(CameraInfo { hfov, vfov, near, far, world: *world });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_doc::{doc, load};
    use super::super::{DaeOptions, parse_dae};
    use super::CameraPlacement;
    use crate::math::Vec3;
    use std::path::Path;

    #[test]
    fn camera_fields_of_view_and_placements() {
        let lib = |persp: &str| {
            format!(
                r##"<library_cameras><camera id="c"><optics><technique_common><perspective>{persp}</perspective></technique_common></optics></camera></library_cameras>
              <library_geometries><geometry id="g"><mesh><source id="p"><float_array id="pa" count="9">-1 -1 0 1 -1 0 0 1 0</float_array></source>
              <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
              <triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles></mesh></geometry></library_geometries>"##
            )
        };
        let nodes = r##"<node id="cam"><translate>0 0 10</translate><instance_camera url="#c"/></node><node id="m"><instance_geometry url="#g"/></node>"##;
        // yfov and aspect without xfov: hFov from the aspect.
        let (b, _) =
            load(&doc(&lib("<yfov>40</yfov><aspect_ratio>2</aspect_ratio><znear>1</znear><zfar>50</zfar>"), nodes));
        let c = b.camera().unwrap();
        let want_h = (2.0 * ((20f32).to_radians().tan() * 2.0).atan()).to_degrees();
        assert!((c.vfov_deg - 40.0).abs() < 1e-5 && (c.hfov_deg - want_h).abs() < 1e-4);
        assert_eq!((c.near, c.far), (1.0, 50.0));
        // CS184 placement: c_dir = unit((0,0,10) + (0,0,-1)) = +z; bounds [-1,1]x[-1,1]x[0,0]:
        // centre 0, distance 1.5 |(2,2,0)|.
        assert!((c.position - Vec3::new(0.0, 0.0, 1.5 * 8f32.sqrt())).length() < 1e-5, "{}", c.position);
        // As authored: the file's eye.
        let text = doc(&lib("<xfov>50</xfov><yfov>40</yfov>"), nodes);
        let opts = DaeOptions { camera: CameraPlacement::AsAuthored, ..DaeOptions::default() };
        let (b, _) = parse_dae(&text, Path::new("t.dae"), &opts).unwrap();
        assert_eq!(b.camera().unwrap().position, Vec3::new(0.0, 0.0, 10.0));
        // Neither yfov nor aspect: CS184 rejects it too.
        let e = parse_dae(&doc(&lib("<xfov>50</xfov>"), nodes), Path::new("t.dae"), &opts).unwrap_err();
        assert!(e.to_string().contains("<camera id=\"c\">/<optics>/<technique_common>/<perspective>"), "{e}");
    }
}
