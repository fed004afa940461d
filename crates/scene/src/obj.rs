//! Wavefront OBJ + MTL loader (own parser, so that every error names its file and line).
//!
//! Supported OBJ statements: `v`, `vt`, `vn`, `f` (n-gons are fan-triangulated; vertex forms
//! `v`, `v/vt`, `v//vn`, `v/vt/vn`; negative indices count back from the last vertex), `o` and
//! `g` (each starts a new [`Mesh`]), `usemtl`, `mtllib` (relative to the OBJ's folder).
//! `s`, `l`, `p` and other statements are ignored (unknown ones with a warning).
//!
//! MTL: `newmtl`, `Kd`, `Ke`, `Ks`, `Ns`, `map_Kd` (loaded with the `image` crate, sRGB to
//! linear; the texture is multiplied by `Kd` when `Kd` is given, by 1 otherwise).
//! `d`, `Tr`, `illum`, `Ka`, `Ni`, `Tf` and the other `map_*` are ignored without error.
//!
//! Material mapping (documented approximation):
//! - `Ks` = 0 (or absent): [`Bsdf::Diffuse`] with albedo `Kd` (default 0.5 grey).
//! - `Ks` > 0: [`Bsdf::Plastic`] with diffuse `Kd`, `ior` 1.5 and a roughness from the Phong
//!   exponent `Ns` through the usual Phong-to-Beckmann match `alpha = sqrt(2 / (Ns + 2))`
//!   (Walter et al. 2007, sec. 5.2); our roughness is perceptual (`alpha = r^2`), so
//!   `r = sqrt(alpha)`. The `Ks` colour itself is not used (the coating is a dielectric).
//! - `Ke` > 0: emission from the front face.
//!
//! A missing or unreadable MTL library is not an error: its materials become the default grey
//! and a warning goes to [`LoadStats::warnings`]. Degenerate triangles (repeated index, zero
//! area, non-finite coordinates) are skipped and counted in
//! [`LoadStats::degenerate_triangles_skipped`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use filtrace_core::{Rgb, Vec2, Vec3};

use crate::error::SceneError;
use crate::texture::TextureCache;
use crate::types::{Bsdf, Material, MaterialId, Mesh, Scene, Texturable};

/// Loads an OBJ file (and the MTL libraries it names).
pub fn load_obj(path: &Path) -> Result<Scene, SceneError> {
    let src = read_text(path)?;
    parse_obj(&src, path)
}

pub(crate) fn read_text(path: &Path) -> Result<String, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::Io { path: path.to_path_buf(), source: e })?;
    // Some exporters write Latin-1 comments; keep going rather than refusing the file.
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// Parses OBJ text; `path` names the file in errors and is the base for `mtllib`.
pub fn parse_obj(src: &str, path: &Path) -> Result<Scene, SceneError> {
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut p = ObjParser {
        path,
        base,
        scene: Scene {
            name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
            ..Scene::default()
        },
        positions: Vec::new(),
        uvs: Vec::new(),
        normals: Vec::new(),
        materials: HashMap::new(),
        current_material: None,
        default_material: None,
        group: MeshBuilder::new("default"),
        warned: HashMap::new(),
        textures: TextureCache::default(),
    };
    for (i, raw) in src.lines().enumerate() {
        p.line(i + 1, raw)?;
    }
    p.flush_group("");
    let mut scene = p.scene;
    scene.textures = p.textures.into_textures();
    Ok(scene)
}

/// One OBJ vertex reference, indices already made absolute and 0-based.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
struct VertexRef {
    v: u32,
    vt: Option<u32>,
    vn: Option<u32>,
}

struct MeshBuilder {
    name: String,
    map: HashMap<VertexRef, u32>,
    refs: Vec<VertexRef>,
    indices: Vec<[u32; 3]>,
    material_ids: Vec<MaterialId>,
}

impl MeshBuilder {
    fn new(name: &str) -> Self {
        MeshBuilder {
            name: name.to_string(),
            map: HashMap::new(),
            refs: Vec::new(),
            indices: Vec::new(),
            material_ids: Vec::new(),
        }
    }

    fn vertex(&mut self, r: VertexRef) -> u32 {
        let next = self.refs.len() as u32;
        *self.map.entry(r).or_insert_with(|| {
            self.refs.push(r);
            next
        })
    }
}

struct ObjParser<'a> {
    path: &'a Path,
    base: PathBuf,
    scene: Scene,
    positions: Vec<Vec3>,
    uvs: Vec<Vec2>,
    normals: Vec<Vec3>,
    /// Materials by MTL name: `Some(id)` once added to the scene.
    materials: HashMap<String, MaterialId>,
    current_material: Option<MaterialId>,
    default_material: Option<MaterialId>,
    group: MeshBuilder,
    warned: HashMap<String, ()>,
    textures: TextureCache,
}

impl ObjParser<'_> {
    fn err(&self, line: usize, msg: impl Into<String>) -> SceneError {
        SceneError::parse(self.path, Some(line), msg)
    }

    fn warn_once(&mut self, key: &str, msg: String) {
        if self.warned.insert(key.to_string(), ()).is_none() {
            self.scene.stats.warnings.push(msg);
        }
    }

    fn default_material(&mut self) -> MaterialId {
        if let Some(id) = self.default_material {
            return id;
        }
        let id = self.scene.add_material(Material::default_grey());
        self.default_material = Some(id);
        id
    }

    fn line(&mut self, n: usize, raw: &str) -> Result<(), SceneError> {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            return Ok(());
        }
        let mut it = line.split_whitespace();
        let key = it.next().unwrap_or("");
        let rest = line[key.len()..].trim();
        match key {
            "v" => {
                let v = parse_floats::<3>(rest, 3).map_err(|m| self.err(n, format!("vertex: {m}")))?;
                self.positions.push(Vec3::from(v));
            }
            "vt" => {
                let v = parse_floats::<3>(rest, 1)
                    .map_err(|m| self.err(n, format!("texture coordinate: {m}")))?;
                self.uvs.push(Vec2::new(v[0], v[1]));
            }
            "vn" => {
                let v = parse_floats::<3>(rest, 3).map_err(|m| self.err(n, format!("normal: {m}")))?;
                self.normals.push(Vec3::from(v));
            }
            "f" => self.face(n, rest)?,
            "o" | "g" => {
                let name = if rest.is_empty() { "default" } else { rest };
                self.flush_group(name);
            }
            "usemtl" => {
                let id = match self.materials.get(rest) {
                    Some(&id) => id,
                    None => {
                        self.warn_once(
                            &format!("usemtl {rest}"),
                            format!(
                                "{}:{n}: unknown material '{rest}', using default grey",
                                self.path.display()
                            ),
                        );
                        self.default_material()
                    }
                };
                self.current_material = Some(id);
            }
            "mtllib" => {
                if rest.is_empty() {
                    return Err(self.err(n, "mtllib without a file name"));
                }
                // Several libraries may follow `mtllib`; a single name may contain spaces.
                let whole = self.base.join(rest);
                if whole.is_file() || !rest.contains(char::is_whitespace) {
                    self.load_mtl(&whole)?;
                } else {
                    for name in rest.split_whitespace() {
                        self.load_mtl(&self.base.join(name))?;
                    }
                }
            }
            "s" | "l" | "p" | "vp" | "cstype" | "deg" | "bmat" | "step" | "curv" | "curv2" | "surf"
            | "parm" | "trim" | "hole" | "scrv" | "sp" | "end" | "mg" | "lod" | "shadow_obj"
            | "trace_obj" | "bevel" | "c_interp" | "d_interp" | "usemap" | "maplib" => {}
            other => {
                self.warn_once(
                    &format!("key {other}"),
                    format!("{}:{n}: unknown OBJ statement '{other}' ignored", self.path.display()),
                );
            }
        }
        Ok(())
    }

    fn resolve(&self, n: usize, tok: &str, len: usize, what: &str) -> Result<u32, SceneError> {
        let i: i64 = tok.parse().map_err(|_| self.err(n, format!("bad {what} index '{tok}'")))?;
        let abs = if i > 0 {
            i - 1
        } else if i < 0 {
            len as i64 + i
        } else {
            return Err(self.err(n, format!("{what} index 0 (OBJ indices start at 1)")));
        };
        if abs < 0 || abs >= len as i64 {
            return Err(self.err(n, format!("{what} index {i} out of range ({len} defined so far)")));
        }
        Ok(abs as u32)
    }

    fn face(&mut self, n: usize, rest: &str) -> Result<(), SceneError> {
        let mut refs = Vec::with_capacity(4);
        for tok in rest.split_whitespace() {
            let parts: Vec<&str> = tok.split('/').collect();
            if parts.len() > 3 {
                return Err(self.err(n, format!("bad face vertex '{tok}'")));
            }
            let v = self.resolve(n, parts[0], self.positions.len(), "vertex")?;
            let vt = match parts.get(1) {
                None | Some(&"") => None,
                Some(t) => Some(self.resolve(n, t, self.uvs.len(), "texture coordinate")?),
            };
            let vn = match parts.get(2) {
                None | Some(&"") => None,
                Some(t) => Some(self.resolve(n, t, self.normals.len(), "normal")?),
            };
            refs.push(VertexRef { v, vt, vn });
        }
        if refs.len() < 3 {
            return Err(self.err(n, format!("face with {} vertices (at least 3 needed)", refs.len())));
        }
        let material = match self.current_material {
            Some(m) => m,
            None => self.default_material(),
        };
        // Fan triangulation around the first vertex.
        for k in 1..refs.len() - 1 {
            let tri = [refs[0], refs[k], refs[k + 1]];
            if is_degenerate([
                self.positions[tri[0].v as usize],
                self.positions[tri[1].v as usize],
                self.positions[tri[2].v as usize],
            ]) || tri[0].v == tri[1].v
                || tri[1].v == tri[2].v
                || tri[0].v == tri[2].v
            {
                self.scene.stats.degenerate_triangles_skipped += 1;
                continue;
            }
            let idx = tri.map(|r| self.group.vertex(r));
            self.group.indices.push(idx);
            self.group.material_ids.push(material);
        }
        Ok(())
    }

    /// Ends the current group (adding it as a mesh if it has triangles) and starts `next`.
    fn flush_group(&mut self, next: &str) {
        let g = std::mem::replace(&mut self.group, MeshBuilder::new(next));
        if g.indices.is_empty() {
            return;
        }
        let all_n = g.refs.iter().all(|r| r.vn.is_some());
        let any_t = g.refs.iter().any(|r| r.vt.is_some());
        let mut mesh = Mesh {
            name: g.name,
            positions: g.refs.iter().map(|r| self.positions[r.v as usize]).collect(),
            indices: g.indices,
            material_ids: g.material_ids,
            ..Mesh::default()
        };
        if all_n {
            // A zero or non-finite normal would poison shading: fall back to flat shading.
            let normals: Vec<Vec3> =
                g.refs.iter().map(|r| self.normals[r.vn.unwrap_or(0) as usize].normalize_or_zero()).collect();
            if normals.iter().all(|n| n.is_finite() && *n != Vec3::ZERO) {
                mesh.normals = normals;
            }
        }
        if any_t {
            // Vertices without `vt` in a textured group get (0, 0).
            mesh.uvs = g.refs.iter().map(|r| r.vt.map_or(Vec2::ZERO, |t| self.uvs[t as usize])).collect();
        }
        self.scene.add_mesh(mesh);
    }

    fn load_mtl(&mut self, mtl_path: &Path) -> Result<(), SceneError> {
        let src = match std::fs::read(mtl_path) {
            Ok(b) => String::from_utf8_lossy(&b).into_owned(),
            Err(e) => {
                self.scene.stats.warnings.push(format!(
                    "{}: material library {} not readable ({e}); its materials are default grey",
                    self.path.display(),
                    mtl_path.display()
                ));
                return Ok(());
            }
        };
        let mtls = parse_mtl(&src, mtl_path, &mut self.textures, &mut self.scene.stats.warnings)?;
        for m in mtls {
            let name = m.name.clone();
            let id = self.scene.add_material(m);
            self.materials.insert(name, id);
        }
        Ok(())
    }
}

/// `true` for triangles that cannot be hit or shaded: non-finite corners or zero area.
pub(crate) fn is_degenerate(p: [Vec3; 3]) -> bool {
    if !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite()) {
        return true;
    }
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    n.length_squared() <= 0.0 || !n.is_finite()
}

/// Parses between `min` and `N` floats (missing ones are 0).
fn parse_floats<const N: usize>(s: &str, min: usize) -> Result<[f32; N], String> {
    let mut out = [0.0; N];
    let mut count = 0;
    for tok in s.split_whitespace() {
        if count == N {
            // `v x y z w` and `vt u v w`: the extra coordinate is ignored.
            break;
        }
        out[count] = tok.parse::<f32>().map_err(|_| format!("cannot parse number '{tok}'"))?;
        count += 1;
    }
    if count < min {
        return Err(format!("expected {min} numbers, found {count}"));
    }
    Ok(out)
}

/// The MTL fields filtrace reads, before conversion to a [`Material`].
#[derive(Default)]
struct MtlRecord {
    name: String,
    kd: Option<Rgb>,
    ke: Rgb,
    ks: Rgb,
    ns: Option<f32>,
    map_kd: Option<(String, usize)>,
}

/// Perceptual roughness for a Phong exponent: `alpha = sqrt(2 / (Ns + 2))`, `r = sqrt(alpha)`.
pub fn roughness_from_phong_exponent(ns: f32) -> f32 {
    let alpha = (2.0 / (ns.max(0.0) + 2.0)).sqrt();
    alpha.sqrt().clamp(0.0, 1.0)
}

fn parse_mtl(
    src: &str,
    path: &Path,
    textures: &mut TextureCache,
    warnings: &mut Vec<String>,
) -> Result<Vec<Material>, SceneError> {
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut records: Vec<MtlRecord> = Vec::new();
    let err = |n: usize, m: String| SceneError::parse(path, Some(n), m);
    for (i, raw) in src.lines().enumerate() {
        let n = i + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let key = line.split_whitespace().next().unwrap_or("");
        let rest = line[key.len()..].trim();
        if key == "newmtl" {
            if rest.is_empty() {
                return Err(err(n, "newmtl without a name".into()));
            }
            records.push(MtlRecord { name: rest.to_string(), ..MtlRecord::default() });
            continue;
        }
        let Some(cur) = records.last_mut() else {
            return Err(err(n, format!("'{key}' before any newmtl")));
        };
        let rgb = |rest: &str| -> Result<Rgb, SceneError> {
            // `Kd r` alone means grey; `Kd spectral ...`/`xyz` are not supported.
            let v = parse_floats::<3>(rest, 1).map_err(|m| err(n, format!("{key}: {m}")))?;
            let c = if rest.split_whitespace().count() == 1 { Rgb::splat(v[0]) } else { Rgb::from(v) };
            if !c.is_finite() || c.min_element() < 0.0 {
                return Err(err(n, format!("{key}: colour must be finite and non-negative")));
            }
            Ok(c)
        };
        match key {
            "Kd" => cur.kd = Some(rgb(rest)?),
            "Ke" => cur.ke = rgb(rest)?,
            "Ks" => cur.ks = rgb(rest)?,
            "Ns" => {
                let v = parse_floats::<1>(rest, 1).map_err(|m| err(n, format!("Ns: {m}")))?;
                cur.ns = Some(v[0]);
            }
            "map_Kd" => {
                // Options such as `-s 1 1 1` are skipped: the file name is the last token.
                let file = rest.split_whitespace().last().unwrap_or("");
                if file.is_empty() {
                    return Err(err(n, "map_Kd without a file name".into()));
                }
                cur.map_kd = Some((file.to_string(), n));
            }
            "d" | "Tr" | "illum" | "Ka" | "Ni" | "Tf" | "Pr" | "Pm" | "Ps" | "Pc" | "Pcr" | "aniso"
            | "anisor" | "sharpness" => {}
            k if k.starts_with("map_") || k == "bump" || k == "disp" || k == "decal" || k == "refl" => {}
            other => {
                warnings.push(format!("{}:{n}: unknown MTL statement '{other}' ignored", path.display()))
            }
        }
    }
    let mut out = Vec::with_capacity(records.len());
    for r in records {
        let kd = r.kd.unwrap_or(Rgb::splat(0.5));
        let diffuse = match &r.map_kd {
            Some((file, line)) => match textures.load(&base.join(file)) {
                Ok(t) => Texturable::Texture { texture: t, factor: r.kd.unwrap_or(Rgb::ONE) },
                Err(e) => {
                    warnings.push(format!("{}:{line}: texture not loaded ({e}); using Kd", path.display()));
                    Texturable::Constant(kd)
                }
            },
            None => Texturable::Constant(kd),
        };
        let bsdf = if r.ks.max_element() > 0.0 {
            Bsdf::Plastic { diffuse, roughness: roughness_from_phong_exponent(r.ns.unwrap_or(0.0)), ior: 1.5 }
        } else {
            Bsdf::Diffuse { reflectance: diffuse }
        };
        out.push(Material { name: r.name, bsdf, emission: r.ke, two_sided_emission: false });
    }
    Ok(out)
}
