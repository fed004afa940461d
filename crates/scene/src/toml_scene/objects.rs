//! `[[objects]]` of a TOML scene: built-in shapes and mesh files (loaded once, instanced).

use super::*;

impl Builder<'_> {
    pub(super) fn object(&mut self, so: &Spanned<ObjectDef>) -> Result<(), SceneError> {
        let span = so.span();
        let o = so.get_ref();
        let transform = self.transform(&span, o.transform.as_ref())?;
        let material = match &o.material {
            Some(name) => Some(
                *self
                    .by_name
                    .get(name)
                    .ok_or_else(|| self.err(span.clone(), format!("unknown material '{name}'")))?,
            ),
            None => None,
        };
        if o.segments.is_some() && o.shape.as_deref() != Some("sphere") {
            return Err(self.err(span, "`segments` applies only to shape = \"sphere\""));
        }
        match (&o.mesh, &o.shape) {
            (Some(file), None) => {
                let first = (self.scene.instances.len(), self.scene.lights.len());
                self.mesh_file(&span, file, transform, material)?;
                self.name_object(&span, o.name.as_deref(), transform, first)
            }
            (None, Some(shape)) => {
                let mat = match material {
                    Some(m) => m,
                    None => self.default_material(),
                };
                let mut mesh = match shape.as_str() {
                    "quad" => shapes::quad(mat),
                    "cube" => shapes::cube(mat),
                    "sphere" => {
                        let seg = o.segments.unwrap_or(48);
                        if !(3..=4096).contains(&seg) {
                            return Err(self.err(span, "sphere segments must be in [3, 4096]"));
                        }
                        shapes::sphere(seg, mat)
                    }
                    other => {
                        return Err(self.err(span, format!("unknown shape '{other}' (quad, cube, sphere)")));
                    }
                };
                if let Some(n) = &o.name {
                    mesh.name = n.clone();
                }
                let first = (self.scene.instances.len(), self.scene.lights.len());
                let id = self.scene.meshes.len() as MeshId;
                self.scene.meshes.push(mesh);
                self.scene.instances.push(Instance { mesh: id, transform, material_override: None });
                self.name_object(&span, o.name.as_deref(), transform, first)
            }
            _ => Err(self.err(span, "an object needs exactly one of `mesh` (a file) or `shape`")),
        }
    }

    /// Records a named object (its instances and lights from index `first` on) so that
    /// animation tracks can move it.
    pub(super) fn name_object(
        &mut self,
        span: &Range<usize>,
        name: Option<&str>,
        transform: Affine3A,
        first: (usize, usize),
    ) -> Result<(), SceneError> {
        let Some(name) = name else { return Ok(()) };
        self.check_name_is_new(span, name)?;
        let to_object = transform.inverse();
        let instances = (first.0..self.scene.instances.len())
            .map(|i| (i as u32, to_object * self.scene.instances[i].transform))
            .collect();
        let lights = (first.1..self.scene.lights.len())
            .map(|i| (i as u32, self.scene.lights[i].transformed(&to_object)))
            .collect();
        self.anim_objects.insert(name.to_string(), ObjectTarget { transform, instances, lights });
        Ok(())
    }

    fn mesh_file(
        &mut self,
        span: &Range<usize>,
        file: &str,
        transform: Affine3A,
        material: Option<MaterialId>,
    ) -> Result<(), SceneError> {
        let p = self.base.join(file);
        if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml")) {
            return Err(self.err(span.clone(), "a mesh file cannot be another TOML scene"));
        }
        if !self.files.contains_key(&p) {
            let sub = crate::mesh_file::load_mesh_file(&p)
                .map_err(|e| self.err(span.clone(), format!("cannot load mesh '{file}': {e}")))?;
            let loaded = self.merge(sub);
            self.files.insert(p.clone(), loaded);
        }
        let f = &self.files[&p];
        let insts: Vec<Instance> = f
            .instances
            .iter()
            .map(|i| Instance {
                mesh: i.mesh,
                transform: transform * i.transform,
                material_override: material.or(i.material_override),
            })
            .collect();
        let lights: Vec<Light> = f.lights.iter().map(|l| l.transformed(&transform)).collect();
        self.scene.instances.extend(insts);
        self.scene.lights.extend(lights);
        Ok(())
    }

    /// Appends a loaded file's meshes, materials and textures; returns its instances and
    /// lights with ids remapped to this scene (transforms still in the file's space).
    fn merge(&mut self, sub: Scene) -> LoadedFile {
        let mesh_off = self.scene.meshes.len() as u32;
        let mat_off = self.scene.materials.len() as u32;
        let tex_off = self.scene.textures.len() as u32;
        let shift = |t: &mut Texturable| {
            if let Texturable::Texture { texture, .. } = t {
                *texture += tex_off;
            }
        };
        for mut m in sub.materials {
            match &mut m.bsdf {
                Bsdf::Diffuse { reflectance } => shift(reflectance),
                Bsdf::Plastic { diffuse, .. } => shift(diffuse),
                Bsdf::Conductor { .. } => {}
            }
            self.scene.materials.push(m);
        }
        self.scene.textures.extend(sub.textures);
        for mut m in sub.meshes {
            m.material_ids.iter_mut().for_each(|id| *id += mat_off);
            self.scene.meshes.push(m);
        }
        self.scene.stats.degenerate_triangles_skipped += sub.stats.degenerate_triangles_skipped;
        self.scene.stats.warnings.extend(sub.stats.warnings);
        if sub.animation.is_some() {
            let w = format!(
                "{}: the mesh file's animation is ignored (animate the object with [[tracks]])",
                sub.name
            );
            self.scene.stats.warnings.push(w);
        }
        let instances = sub
            .instances
            .into_iter()
            .map(|i| Instance {
                mesh: i.mesh + mesh_off,
                transform: i.transform,
                material_override: i.material_override.map(|m| m + mat_off),
            })
            .collect();
        LoadedFile { instances, lights: sub.lights }
    }
}
