//! `[[materials]]` of a TOML scene: BSDFs, named metals, textures.

use super::*;

impl Builder<'_> {
    fn texture(&mut self, span: &Range<usize>, file: &str) -> Result<TextureId, SceneError> {
        let p = self.base.join(file);
        if let Some(&id) = self.textures.get(&p) {
            return Ok(id);
        }
        let t =
            crate::texture::load_texture(&p).map_err(|e| self.err(span.clone(), format!("texture: {e}")))?;
        self.scene.textures.push(t);
        let id = (self.scene.textures.len() - 1) as TextureId;
        self.textures.insert(p, id);
        Ok(id)
    }

    pub(super) fn material(&mut self, sm: &Spanned<MaterialDef>) -> Result<(), SceneError> {
        let span = sm.span();
        let m = sm.get_ref();
        let what = format!("material '{}'", m.name);
        if self.by_name.contains_key(&m.name) {
            return Err(self.err(span, format!("{what} defined twice")));
        }
        let set = [
            ("color", m.color.is_some()),
            ("texture", m.texture.is_some()),
            ("metal", m.metal.is_some()),
            ("eta", m.eta.is_some()),
            ("k", m.k.is_some()),
            ("roughness", m.roughness.is_some()),
            ("ior", m.ior.is_some()),
        ];
        let roughness = m.roughness.unwrap_or(0.0);
        if !(0.0..=1.0).contains(&roughness) {
            return Err(self.err(span, format!("{what}: roughness must be in [0, 1]")));
        }
        let diffuse = |b: &mut Self| -> Result<Texturable, SceneError> {
            let c = b.colour(&span, &what, m.color, Rgb::splat(0.5))?;
            Ok(match &m.texture {
                Some(f) => Texturable::Texture {
                    texture: b.texture(&span, f)?,
                    factor: if m.color.is_some() { c } else { Rgb::ONE },
                },
                None => Texturable::Constant(c),
            })
        };
        let bsdf = match m.kind.as_str() {
            "diffuse" => {
                self.only(&span, &what, &set, &["color", "texture"])?;
                Bsdf::Diffuse { reflectance: diffuse(self)? }
            }
            "plastic" => {
                self.only(&span, &what, &set, &["color", "texture", "roughness", "ior"])?;
                let ior = m.ior.unwrap_or(1.5);
                if !(ior > 1.0 && ior < 4.0) {
                    return Err(self.err(span, format!("{what}: ior must be in (1, 4)")));
                }
                Bsdf::Plastic { diffuse: diffuse(self)?, roughness: m.roughness.unwrap_or(0.1), ior }
            }
            "conductor" => {
                self.only(&span, &what, &set, &["metal", "eta", "k", "roughness"])?;
                let (eta, k) = match (&m.metal, m.eta, m.k) {
                    (Some(name), None, None) => named_metal(name).ok_or_else(|| {
                        self.err(
                            span.clone(),
                            format!("{what}: unknown metal '{name}' (known: {})", METAL_NAMES.join(", ")),
                        )
                    })?,
                    (None, Some(eta), Some(k)) => {
                        let (eta, k) = (
                            self.colour(&span, &what, Some(eta), Rgb::ONE)?,
                            self.colour(&span, &what, Some(k), Rgb::ZERO)?,
                        );
                        if eta.min_element() <= 0.0 {
                            return Err(self.err(span, format!("{what}: eta must be positive")));
                        }
                        (eta, k)
                    }
                    _ => {
                        return Err(
                            self.err(span, format!("{what}: give either `metal` or both `eta` and `k`"))
                        )
                    }
                };
                Bsdf::Conductor { eta, k, roughness }
            }
            other => {
                return Err(
                    self.err(span, format!("{what}: unknown type '{other}' (diffuse, conductor, plastic)"))
                )
            }
        };
        let emission = self.colour(&span, &what, m.emission, Rgb::ZERO)?;
        let id = self.scene.add_material(Material {
            name: m.name.clone(),
            bsdf,
            emission,
            two_sided_emission: m.two_sided.unwrap_or(false),
        });
        self.by_name.insert(m.name.clone(), id);
        Ok(())
    }

    pub(super) fn default_material(&mut self) -> MaterialId {
        if let Some(m) = self.default_mat {
            return m;
        }
        let id = self.scene.add_material(Material::default_grey());
        self.default_mat = Some(id);
        id
    }
}
