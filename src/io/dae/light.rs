//! Lights: `<instance_light>` from the CMU462/CGL technique if the light has one, else
//! `technique_common` — ambient, directional, point, spot and CS184's area lights, placed by
//! the node's world matrix.

use super::Ctx;
use super::scene_graph::project;
use super::xml::{child, cmu_technique, element_children, without_path};
use crate::io::LoadError;
use crate::math::{Mat3, Mat4, Vec3};
use crate::scene::Light;
use roxmltree::Node;

impl<'a, 'i> Ctx<'a, 'i> {
    pub(super) fn instance_light(&mut self, il: Node<'a, 'i>, world: &Mat4) -> Result<(), LoadError> {
        let light = match self.resolve(il, "url", "light") {
            Ok(l) => l,
            Err(e) => {
                self.warnings.push(format!("{}; light skipped", without_path(e)));
                return Ok(());
            }
        };
        let Some(technique) = cmu_technique(light).or(child(light, "technique_common")) else {
            self.warn(light, "no technique_common or CMU462/CGL technique; light skipped");
            return Ok(());
        };
        let Some(kind) = element_children(technique).next() else {
            self.warn(technique, "empty technique; light skipped");
            return Ok(());
        };
        let color_node = self.required(kind, "color")?;
        let color = self.rgb(color_node)?;
        let l = Mat3::from_mat4(*world);
        let position = project(world, Vec3::ZERO);
        let forward = (l * -Vec3::Z).normalize_or(-Vec3::Y);
        let light = match kind.tag_name().name() {
            "ambient" => Light::Environment { radiance: color },
            "directional" => Light::Directional { direction: forward, radiance: color },
            "point" => Light::Point { position, intensity: color },
            "spot" => {
                let angle = child(kind, "falloff_angle").map_or(Ok(180.0), |a| self.number(a))?;
                let half = (angle * 0.5).clamp(0.0, 90.0);
                Light::Spot {
                    position,
                    direction: forward,
                    intensity: color,
                    inner_angle_deg: half,
                    outer_angle_deg: half,
                }
            }
            "area" => Light::Area {
                radiance: color,
                position,
                direction: forward,
                dim_x: l * Vec3::new(-1.0, 0.0, 0.0),
                dim_y: l * Vec3::Y,
            },
            other => {
                self.warn(kind, format!("light type <{other}> is not supported; light skipped"));
                return Ok(());
            }
        };
        light.check().map_err(|m| self.err(color_node, m))?;
        self.builder.add_light(light);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_doc::{doc, load};
    use crate::math::Vec3;
    use crate::scene::Light;

    #[test]
    fn lights_of_every_type_follow_cs184() {
        let lib = r##"<library_lights>
            <light id="p"><technique_common><point><color>1 2 3</color></point></technique_common></light>
            <light id="d"><technique_common><directional><color>4 4 4</color></directional></technique_common></light>
            <light id="a"><technique_common><ambient><color>0.5 0.5 0.5</color></ambient></technique_common></light>
            <light id="sp"><technique_common><spot><color>7 7 7</color><falloff_angle>60</falloff_angle></spot></technique_common></light>
            <light id="q"><technique_common><point><color>1 1 1</color></point></technique_common>
              <extra><technique profile="CGL"><area><color>9 9 9</color></area></technique></extra></light>
            </library_lights>"##;
        let nodes = r##"<node id="np"><translate>1 2 3</translate><instance_light url="#p"/></node>
            <node id="nd"><rotate>1 0 0 -90</rotate><instance_light url="#d"/></node>
            <node id="na"><instance_light url="#a"/></node>
            <node id="ns"><translate>0 5 0</translate><rotate>1 0 0 -90</rotate><instance_light url="#sp"/></node>
            <node id="nq"><translate>0 2 0</translate><rotate>0 1 0 90</rotate><scale>2 3 1</scale><instance_light url="#q"/></node>"##;
        let (b, _) = load(&doc(lib, nodes));
        let l = b.lights();
        assert_eq!(l[0], Light::Point { position: Vec3::new(1.0, 2.0, 3.0), intensity: Vec3::new(1.0, 2.0, 3.0) });
        // -90° about x turns local -z into -y.
        let Light::Directional { direction, radiance } = l[1] else { panic!("{:?}", l[1]) };
        assert!((direction - -Vec3::Y).length() < 1e-6 && radiance == Vec3::splat(4.0));
        assert_eq!(l[2], Light::Environment { radiance: Vec3::splat(0.5) });
        let Light::Spot { position, direction, outer_angle_deg, .. } = l[3] else { panic!("{:?}", l[3]) };
        assert!((position - Vec3::new(0.0, 5.0, 0.0)).length() < 1e-6 && (direction - -Vec3::Y).length() < 1e-6);
        assert_eq!(outer_angle_deg, 30.0);
        // Area: 90° about y maps x -> -z and z -> x; scale (2, 3, 1) first.
        // direction = R·S·(0,0,-1) = R·(0,0,-1) = (-1,0,0); dim_x = R·S·(-1,0,0) = R·(-2,0,0) = (0,0,2);
        // dim_y = R·S·(0,1,0) = (0,3,0).
        let Light::Area { radiance, position, direction, dim_x, dim_y } = l[4] else { panic!("{:?}", l[4]) };
        assert_eq!((radiance, position), (Vec3::splat(9.0), Vec3::new(0.0, 2.0, 0.0)));
        assert!((direction - -Vec3::X).length() < 1e-6, "{direction}");
        assert!((dim_x - Vec3::new(0.0, 0.0, 2.0)).length() < 1e-6, "{dim_x}");
        assert!((dim_y - Vec3::new(0.0, 3.0, 0.0)).length() < 1e-6, "{dim_y}");
    }
}
