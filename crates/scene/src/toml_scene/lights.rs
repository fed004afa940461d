//! `[[lights]]` of a TOML scene: point, spot, directional (sun), environment, sky and quad
//! lights.

use super::*;

impl Builder<'_> {
    pub(super) fn light(&mut self, sl: &Spanned<LightDef>) -> Result<(), SceneError> {
        let span = sl.span();
        let l = sl.get_ref();
        let what = format!("light '{}'", l.kind);
        let set = [
            ("position", l.position.is_some()),
            ("direction", l.direction.is_some()),
            ("target", l.target.is_some()),
            ("intensity", l.intensity.is_some()),
            ("irradiance", l.irradiance.is_some()),
            ("radiance", l.radiance.is_some()),
            ("cone_angle", l.cone_angle.is_some()),
            ("falloff_start", l.falloff_start.is_some()),
            ("zenith", l.zenith.is_some()),
            ("horizon", l.horizon.is_some()),
            ("ground", l.ground.is_some()),
            ("corner", l.corner.is_some()),
            ("edge1", l.edge1.is_some()),
            ("edge2", l.edge2.is_some()),
            ("two_sided", l.two_sided.is_some()),
        ];
        let need = |v: Option<V3>, key: &str| -> Result<Vec3, SceneError> {
            match v {
                Some(v) if finite3(v) => Ok(Vec3::from(v)),
                Some(_) => Err(self.err(span.clone(), format!("{what}: '{key}' must be finite"))),
                None => Err(self.err(span.clone(), format!("{what}: missing '{key}'"))),
            }
        };
        let dir = |v: Vec3, key: &str| -> Result<Vec3, SceneError> {
            v.try_normalize()
                .ok_or_else(|| self.err(span.clone(), format!("{what}: '{key}' must be non-zero")))
        };
        let light = match l.kind.as_str() {
            "point" => {
                self.only(&span, &what, &set, &["position", "intensity"])?;
                Light::Point {
                    position: need(l.position, "position")?,
                    intensity: self.colour(
                        &span,
                        &what,
                        Some(need(l.intensity, "intensity")?.into()),
                        Rgb::ZERO,
                    )?,
                }
            }
            "spot" => {
                self.only(
                    &span,
                    &what,
                    &set,
                    &["position", "direction", "target", "intensity", "cone_angle", "falloff_start"],
                )?;
                let position = need(l.position, "position")?;
                let direction = match (l.direction, l.target) {
                    (Some(_), None) => dir(need(l.direction, "direction")?, "direction")?,
                    (None, Some(_)) => dir(need(l.target, "target")? - position, "target - position")?,
                    _ => {
                        return Err(
                            self.err(span, format!("{what}: give exactly one of `direction` or `target`"))
                        )
                    }
                };
                let cone = l.cone_angle.unwrap_or(30.0);
                let start = l.falloff_start.unwrap_or(0.75 * cone);
                if !(cone > 0.0 && cone <= 90.0 && start >= 0.0 && start <= cone) {
                    return Err(
                        self.err(span, format!("{what}: need 0 < falloff_start <= cone_angle <= 90 degrees"))
                    );
                }
                Light::Spot {
                    position,
                    direction,
                    intensity: self.colour(
                        &span,
                        &what,
                        Some(need(l.intensity, "intensity")?.into()),
                        Rgb::ZERO,
                    )?,
                    cos_total_width: cone.to_radians().cos(),
                    cos_falloff_start: start.to_radians().cos(),
                }
            }
            "directional" | "sun" => {
                self.only(&span, &what, &set, &["direction", "irradiance"])?;
                Light::Directional {
                    direction: dir(need(l.direction, "direction")?, "direction")?,
                    irradiance: self.colour(
                        &span,
                        &what,
                        Some(need(l.irradiance, "irradiance")?.into()),
                        Rgb::ZERO,
                    )?,
                }
            }
            "environment" => {
                self.only(&span, &what, &set, &["radiance"])?;
                let radiance =
                    self.colour(&span, &what, Some(need(l.radiance, "radiance")?.into()), Rgb::ZERO)?;
                Light::Environment(Environment::Constant { radiance })
            }
            "sky" => {
                self.only(&span, &what, &set, &["zenith", "horizon", "ground"])?;
                Light::Environment(Environment::Sky {
                    zenith: self.colour(&span, &what, l.zenith, Rgb::new(0.25, 0.45, 1.0))?,
                    horizon: self.colour(&span, &what, l.horizon, Rgb::new(0.9, 0.95, 1.0))?,
                    ground: self.colour(&span, &what, l.ground, Rgb::splat(0.2))?,
                })
            }
            "quad" => {
                self.only(&span, &what, &set, &["corner", "edge1", "edge2", "radiance", "two_sided"])?;
                let (c, e1, e2) =
                    (need(l.corner, "corner")?, need(l.edge1, "edge1")?, need(l.edge2, "edge2")?);
                if e1.cross(e2).length_squared() == 0.0 {
                    return Err(self.err(span, format!("{what}: edges must not be parallel")));
                }
                let radiance =
                    self.colour(&span, &what, Some(need(l.radiance, "radiance")?.into()), Rgb::ZERO)?;
                let mut mat = Material::diffuse(&format!("light{}", self.scene.lights.len()), Rgb::ZERO);
                mat.emission = radiance;
                mat.two_sided_emission = l.two_sided.unwrap_or(false);
                let mat = self.scene.add_material(mat);
                let mut mesh = shapes::parallelogram(c, e1, e2, mat);
                mesh.name = "quad_light".into();
                let first = (self.scene.instances.len(), self.scene.lights.len());
                self.scene.add_mesh(mesh);
                return self.name_object(&span, l.name.as_deref(), Affine3A::IDENTITY, first);
            }
            other => {
                return Err(self.err(
                    span,
                    format!(
                    "unknown light type '{other}' (point, spot, directional, sun, environment, sky, quad)"
                ),
                ))
            }
        };
        if let Some(name) = &l.name {
            if self.anim_objects.contains_key(name) || self.anim_lights.contains_key(name) || name == "camera"
            {
                return Err(self.err(span, format!("the name '{name}' is used twice")));
            }
            self.anim_lights.insert(name.clone(), self.scene.lights.len() as u32);
        }
        self.scene.lights.push(light);
        Ok(())
    }
}
