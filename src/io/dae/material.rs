//! Materials: `<instance_material>` → `<material>` → `<effect>`, the `profile_COMMON`
//! diffuse and emission colours, then the effect's CMU462/CGL extras (emission, mirror,
//! glass, refraction, microfacet, diffuse), checked before they reach the scene.

use super::Ctx;
use super::xml::{child, children, cmu_technique, elem_path, element_children};
use crate::io::LoadError;
use crate::math::Vec3;
use crate::scene::{Bsdf, Material, MaterialId};
use roxmltree::Node;

impl<'a, 'i> Ctx<'a, 'i> {
    pub(super) fn material(&mut self, m: Node<'a, 'i>) -> Result<MaterialId, LoadError> {
        let key = m.attribute("id").unwrap_or("").to_string();
        if let Some(&id) = self.materials.get(&key) {
            return Ok(id);
        }
        let ie = self.required(m, "instance_effect")?;
        let effect = self.resolve(ie, "url", "effect")?;
        let name = m.attribute("name").or(m.attribute("id")).unwrap_or("");
        let mut albedo = Vec3::splat(0.5);
        let mut emission = Vec3::ZERO;
        // The elements that set the BSDF and the emission, for errors about their values.
        let (mut bsdf_at, mut emission_at) = (effect, effect);
        if let Some(profile) = child(effect, "profile_COMMON") {
            let technique = children(profile, "technique")
                .find(|t| t.attribute("sid") == Some("common"))
                .or(child(profile, "technique"));
            let shading = technique.and_then(|t| {
                element_children(t).find(|s| matches!(s.tag_name().name(), "phong" | "lambert" | "blinn" | "constant"))
            });
            if let Some(s) = shading {
                if let Some(c) = child(s, "diffuse").and_then(|d| child(d, "color")) {
                    albedo = self.rgb(c)?;
                    bsdf_at = c;
                }
                if let Some(c) = child(s, "emission").and_then(|d| child(d, "color")) {
                    emission = self.rgb(c)?;
                    emission_at = c;
                }
            }
        }
        let mut bsdf = Bsdf::Diffuse { albedo };
        if let Some(t) = cmu_technique(effect) {
            for e in element_children(t) {
                let rgb_of = |tag: &'static str| -> Result<Vec3, LoadError> { self.rgb(self.required(e, tag)?) };
                let opt_rgb = |tag: &'static str, d: Vec3| child(e, tag).map_or(Ok(d), |c| self.rgb(c));
                let opt_num = |tag: &'static str, d: f32| child(e, tag).map_or(Ok(d), |c| self.number(c));
                let model = e.tag_name().name();
                if matches!(model, "emission" | "mirror" | "glass" | "refraction" | "microfacet" | "diffuse") {
                    bsdf_at = e;
                }
                match model {
                    "emission" => {
                        emission = rgb_of("radiance")?;
                        emission_at = e;
                        bsdf = Bsdf::Diffuse { albedo: Vec3::ZERO };
                    }
                    "mirror" => bsdf = Bsdf::Mirror { reflectance: rgb_of("reflectance")? },
                    "glass" => {
                        bsdf = Bsdf::Glass {
                            reflectance: opt_rgb("reflectance", Vec3::ONE)?,
                            transmittance: opt_rgb("transmittance", Vec3::ONE)?,
                            ior: self.number(self.required(e, "ior")?)?,
                            roughness: opt_num("roughness", 0.0)?,
                        }
                    }
                    "refraction" => {
                        bsdf = Bsdf::Glass {
                            reflectance: Vec3::ZERO,
                            transmittance: opt_rgb("transmittance", Vec3::ONE)?,
                            ior: self.number(self.required(e, "ior")?)?,
                            roughness: opt_num("roughness", 0.0)?,
                        }
                    }
                    "microfacet" => {
                        bsdf = Bsdf::Microfacet {
                            eta: rgb_of("eta")?,
                            k: rgb_of("k")?,
                            alpha: self.number(self.required(e, "alpha")?)?,
                        }
                    }
                    "diffuse" => {
                        let c = child(e, "albedo")
                            .or(child(e, "reflectance"))
                            .ok_or_else(|| self.err(e, "missing <albedo>"))?;
                        bsdf = Bsdf::Diffuse { albedo: self.rgb(c)? };
                    }
                    other => {
                        let msg = format!("material model <{other}> is not supported; ignored");
                        self.warnings.push(format!("{}: {msg}", elem_path(e)));
                    }
                }
            }
        }
        bsdf.check().map_err(|m| self.err(bsdf_at, m))?;
        crate::scene::material::check_radiance("emission", emission).map_err(|m| self.err(emission_at, m))?;
        let id = self.builder.add_material(Material { name: name.to_string(), bsdf, emission });
        self.materials.insert(key, id);
        Ok(id)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_doc::{doc, load};
    use crate::math::Vec3;
    use crate::scene::Bsdf;

    #[test]
    fn cgl_materials_and_sphere_scale() {
        let lib = r##"<library_effects>
            <effect id="e-mf"><extra><technique profile="CGL"><microfacet><alpha>0.25</alpha><eta>0.2 0.3 0.4</eta><k>3 2 1</k></microfacet></technique></extra></effect>
            <effect id="e-d"><profile_COMMON><technique sid="common"><blinn><diffuse><color>0.1 0.2 0.3 1</color></diffuse></blinn></technique></profile_COMMON>
              <extra><technique profile="CGL"><refraction><transmittance>1 1 1</transmittance><roughness>0</roughness><ior>1.33</ior></refraction></technique></extra></effect>
            </library_effects>
            <library_materials><material id="mf"><instance_effect url="#e-mf"/></material><material id="d"><instance_effect url="#e-d"/></material></library_materials>
            <library_geometries><geometry id="ball"><extra><technique profile="CGL"><sphere><radius>0.5</radius></sphere></technique></extra></geometry></library_geometries>"##;
        let nodes = r##"<node id="a"><translate>1 0 0</translate><scale>4 4 4</scale><instance_geometry url="#ball">
              <bind_material><technique_common><instance_material symbol="x" target="#mf"/></technique_common></bind_material></instance_geometry></node>
            <node id="b"><instance_geometry url="#ball">
              <bind_material><technique_common><instance_material symbol="y" target="#d"/></technique_common></bind_material></instance_geometry></node>"##;
        let (b, _) = load(&doc(lib, nodes));
        let (scene, _) = b.commit(&crate::BuildOptions::default());
        assert_eq!(scene.spheres.center, vec![Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO]);
        assert_eq!(scene.spheres.radius, vec![2.0, 0.5]);
        let m0 = &scene.materials[scene.spheres.material[0] as usize];
        assert_eq!(
            m0.bsdf,
            Bsdf::Microfacet { eta: Vec3::new(0.2, 0.3, 0.4), k: Vec3::new(3.0, 2.0, 1.0), alpha: 0.25 }
        );
        let m1 = &scene.materials[scene.spheres.material[1] as usize];
        assert!(matches!(m1.bsdf, Bsdf::Glass { ior, reflectance, .. } if ior == 1.33 && reflectance == Vec3::ZERO));
    }
}
