//! `[[lights]]` of a TOML scene: point, spot, directional (sun), environment, sky and quad
//! lights.

use super::*;

/// One `[[lights]]` entry being read: where it stands, how errors name it
/// (`light '<type>'`), and which keys it sets (for [`Builder::only`]).
struct Entry<'l> {
    def: &'l LightDef,
    span: Range<usize>,
    what: String,
    set: [(&'static str, bool); 15],
}

impl<'l> Entry<'l> {
    fn new(sl: &'l Spanned<LightDef>) -> Self {
        let l = sl.get_ref();
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
        Entry { def: l, span: sl.span(), what: format!("light '{}'", l.kind), set }
    }
}

impl Builder<'_> {
    pub(super) fn light(&mut self, sl: &Spanned<LightDef>) -> Result<(), SceneError> {
        let e = Entry::new(sl);
        let l = e.def;
        let light = match l.kind.as_str() {
            "point" => {
                self.only(&e.span, &e.what, &e.set, &["position", "intensity"])?;
                Light::Point {
                    position: self.need(&e, l.position, "position")?,
                    intensity: self.need_colour(&e, l.intensity, "intensity")?,
                }
            }
            "spot" => self.spot_light(&e)?,
            "directional" | "sun" => {
                self.only(&e.span, &e.what, &e.set, &["direction", "irradiance"])?;
                Light::Directional {
                    direction: self.unit(&e, self.need(&e, l.direction, "direction")?, "direction")?,
                    irradiance: self.need_colour(&e, l.irradiance, "irradiance")?,
                }
            }
            "environment" => {
                self.only(&e.span, &e.what, &e.set, &["radiance"])?;
                let radiance = self.need_colour(&e, l.radiance, "radiance")?;
                Light::Environment(Environment::Constant { radiance })
            }
            "sky" => {
                self.only(&e.span, &e.what, &e.set, &["zenith", "horizon", "ground"])?;
                Light::Environment(Environment::Sky {
                    zenith: self.colour(&e.span, &e.what, l.zenith, Rgb::new(0.25, 0.45, 1.0))?,
                    horizon: self.colour(&e.span, &e.what, l.horizon, Rgb::new(0.9, 0.95, 1.0))?,
                    ground: self.colour(&e.span, &e.what, l.ground, Rgb::splat(0.2))?,
                })
            }
            "quad" => return self.quad_light(&e),
            other => {
                return Err(self.err(
                    e.span,
                    format!(
                        "unknown light type '{other}' (point, spot, directional, sun, environment, sky, quad)"
                    ),
                ))
            }
        };
        if let Some(name) = &l.name {
            self.check_name_is_new(&e.span, name)?;
            self.anim_lights.insert(name.clone(), self.scene.lights.len() as u32);
        }
        self.scene.lights.push(light);
        Ok(())
    }

    /// A spot light: `direction` or `target` (exactly one), cone and falloff angles in
    /// degrees, `0 < falloff_start <= cone_angle <= 90`.
    fn spot_light(&self, e: &Entry) -> Result<Light, SceneError> {
        let l = e.def;
        self.only(
            &e.span,
            &e.what,
            &e.set,
            &["position", "direction", "target", "intensity", "cone_angle", "falloff_start"],
        )?;
        let position = self.need(e, l.position, "position")?;
        let direction = match (l.direction, l.target) {
            (Some(_), None) => self.unit(e, self.need(e, l.direction, "direction")?, "direction")?,
            (None, Some(_)) => {
                self.unit(e, self.need(e, l.target, "target")? - position, "target - position")?
            }
            _ => {
                return Err(self
                    .err(e.span.clone(), format!("{}: give exactly one of `direction` or `target`", e.what)))
            }
        };
        let cone = l.cone_angle.unwrap_or(30.0);
        let start = l.falloff_start.unwrap_or(0.75 * cone);
        if !(cone > 0.0 && cone <= 90.0 && start >= 0.0 && start <= cone) {
            return Err(self.err(
                e.span.clone(),
                format!("{}: need 0 < falloff_start <= cone_angle <= 90 degrees", e.what),
            ));
        }
        Ok(Light::Spot {
            position,
            direction,
            intensity: self.need_colour(e, l.intensity, "intensity")?,
            cos_total_width: cone.to_radians().cos(),
            cos_falloff_start: start.to_radians().cos(),
        })
    }

    /// A quad light: an emissive parallelogram mesh, named like an object.
    fn quad_light(&mut self, e: &Entry) -> Result<(), SceneError> {
        let l = e.def;
        self.only(&e.span, &e.what, &e.set, &["corner", "edge1", "edge2", "radiance", "two_sided"])?;
        let (c, e1, e2) = (
            self.need(e, l.corner, "corner")?,
            self.need(e, l.edge1, "edge1")?,
            self.need(e, l.edge2, "edge2")?,
        );
        if e1.cross(e2).length_squared() == 0.0 {
            return Err(self.err(e.span.clone(), format!("{}: edges must not be parallel", e.what)));
        }
        let radiance = self.need_colour(e, l.radiance, "radiance")?;
        let mut mat = Material::diffuse(&format!("light{}", self.scene.lights.len()), Rgb::ZERO);
        mat.emission = radiance;
        mat.two_sided_emission = l.two_sided.unwrap_or(false);
        let mat = self.scene.add_material(mat);
        let mut mesh = shapes::parallelogram(c, e1, e2, mat);
        mesh.name = "quad_light".into();
        let first = (self.scene.instances.len(), self.scene.lights.len());
        self.scene.add_mesh(mesh);
        self.name_object(&e.span, l.name.as_deref(), Affine3A::IDENTITY, first)
    }

    /// The value of `key`: present and finite.
    fn need(&self, e: &Entry, v: Option<V3>, key: &str) -> Result<Vec3, SceneError> {
        match v {
            Some(v) if finite3(v) => Ok(Vec3::from(v)),
            Some(_) => Err(self.err(e.span.clone(), format!("{}: '{key}' must be finite", e.what))),
            None => Err(self.err(e.span.clone(), format!("{}: missing '{key}'", e.what))),
        }
    }

    /// `v` normalised: a direction must not be zero.
    fn unit(&self, e: &Entry, v: Vec3, key: &str) -> Result<Vec3, SceneError> {
        v.try_normalize()
            .ok_or_else(|| self.err(e.span.clone(), format!("{}: '{key}' must be non-zero", e.what)))
    }

    /// The colour `key`: present, finite and non-negative.
    fn need_colour(&self, e: &Entry, v: Option<V3>, key: &str) -> Result<Rgb, SceneError> {
        self.colour(&e.span, &e.what, Some(self.need(e, v, key)?.into()), Rgb::ZERO)
    }
}
