//! Plain-data scene description.

use filtrace_core::{Aabb, Affine3A, Rgb, Vec2, Vec3};

/// Index of a mesh in [`Scene::meshes`].
pub type MeshId = u32;
/// Index of a material in [`Scene::materials`].
pub type MaterialId = u32;
/// Index of a texture in [`Scene::textures`].
pub type TextureId = u32;

/// A triangle mesh in object space. Degenerate triangles are removed by the loaders
/// (and counted in [`LoadStats`]), so every triangle here has non-zero area.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub name: String,
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals; empty means flat shading from the geometric normal.
    pub normals: Vec<Vec3>,
    /// Per-vertex texture coordinates; empty means none.
    pub uvs: Vec<Vec2>,
    /// Vertex indices, counter-clockwise seen from the front (geometric normal
    /// `(p1 - p0) x (p2 - p0)`).
    pub indices: Vec<[u32; 3]>,
    /// Material of each triangle (same length as `indices`).
    pub material_ids: Vec<MaterialId>,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.positions.iter().copied())
    }

    /// The three object-space corners of triangle `i`.
    #[inline]
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }
}

/// A placement of a mesh in the world. Moving objects change only `transform`.
#[derive(Clone, Debug)]
pub struct Instance {
    pub mesh: MeshId,
    /// Object-to-world transform.
    pub transform: Affine3A,
    /// Replaces every triangle's material when set.
    pub material_override: Option<MaterialId>,
}

/// A colour that is either constant or read from a texture (multiplied by `factor`).
#[derive(Clone, Debug, PartialEq)]
pub enum Texturable {
    Constant(Rgb),
    Texture { texture: TextureId, factor: Rgb },
}

impl Default for Texturable {
    fn default() -> Self {
        Texturable::Constant(Rgb::splat(0.5))
    }
}

/// An RGB texture in linear colour, row 0 at the top (v = 1 at the top row).
#[derive(Clone, Debug)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub texels: Vec<Rgb>,
}

/// The surface scattering model of a material.
#[derive(Clone, Debug, PartialEq)]
pub enum Bsdf {
    /// Lambertian reflection with albedo `reflectance`.
    Diffuse { reflectance: Texturable },
    /// Rough metal: GGX microfacets (Trowbridge-Reitz) with the Fresnel term of a
    /// conductor of complex index `eta + i k`. `roughness` is perceptual (alpha = r^2).
    Conductor { eta: Rgb, k: Rgb, roughness: f32 },
    /// A GGX-coated diffuse base ("plastic"): dielectric coating of index `ior` and
    /// perceptual `roughness` over a Lambertian base `diffuse`.
    Plastic { diffuse: Texturable, roughness: f32, ior: f32 },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    pub bsdf: Bsdf,
    /// Emitted radiance from the front face (zero for non-emitters).
    pub emission: Rgb,
    /// Emit from both faces (default: front face only, as the Cornell light).
    pub two_sided_emission: bool,
}

impl Material {
    pub fn diffuse(name: &str, albedo: Rgb) -> Self {
        Material {
            name: name.to_string(),
            bsdf: Bsdf::Diffuse { reflectance: Texturable::Constant(albedo) },
            emission: Rgb::ZERO,
            two_sided_emission: false,
        }
    }

    /// The default for meshes without a material: grey Lambertian, albedo 0.5.
    pub fn default_grey() -> Self {
        Material::diffuse("default", Rgb::splat(0.5))
    }

    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }
}

/// Lights that are not emissive geometry. Emissive triangles (area lights, quads) are
/// found from materials with non-zero `emission`.
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// Isotropic point light of radiant intensity `intensity` (W/sr per channel).
    Point { position: Vec3, intensity: Rgb },
    /// Spot light: intensity falls off smoothly from `cos_falloff_start` to `cos_total_width`.
    Spot { position: Vec3, direction: Vec3, intensity: Rgb, cos_total_width: f32, cos_falloff_start: f32 },
    /// Distant light arriving along `-direction` (`direction` points towards the sun)
    /// with irradiance `irradiance` on a surface facing it.
    Directional { direction: Vec3, irradiance: Rgb },
    /// Environment radiance arriving from every direction.
    Environment(Environment),
}

impl Camera {
    /// This camera placed by `m` (eye and target moved, up turned).
    pub fn transformed(&self, m: &Affine3A) -> Camera {
        Camera {
            eye: m.transform_point3(self.eye),
            target: m.transform_point3(self.target),
            up: m.transform_vector3(self.up).normalize_or(self.up),
            vfov_deg: self.vfov_deg,
        }
    }
}

impl Light {
    /// This light placed by `m` (positions moved, directions turned; environments stay).
    pub fn transformed(&self, m: &Affine3A) -> Light {
        let d = |v: Vec3| m.transform_vector3(v).normalize_or(v);
        match self.clone() {
            Light::Point { position, intensity } => {
                Light::Point { position: m.transform_point3(position), intensity }
            }
            Light::Spot { position, direction, intensity, cos_total_width, cos_falloff_start } => {
                Light::Spot {
                    position: m.transform_point3(position),
                    direction: d(direction),
                    intensity,
                    cos_total_width,
                    cos_falloff_start,
                }
            }
            Light::Directional { direction, irradiance } => {
                Light::Directional { direction: d(direction), irradiance }
            }
            env @ Light::Environment(_) => env,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// The same radiance from every direction (the white-furnace light).
    Constant { radiance: Rgb },
    /// A simple analytic sky: `horizon` to `zenith` gradient over the upper hemisphere,
    /// `ground` below the horizon.
    Sky { zenith: Rgb, horizon: Rgb, ground: Rgb },
}

/// Pinhole camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov_deg: f32,
}

impl Camera {
    /// The classic Cornell box camera.
    pub fn cornell() -> Self {
        Camera {
            eye: Vec3::new(278.0, 273.0, -800.0),
            target: Vec3::new(278.0, 273.0, -799.0),
            up: Vec3::Y,
            vfov_deg: 39.3077,
        }
    }
}

/// What loading a scene skipped or defaulted, for a summary line and for tests.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LoadStats {
    pub degenerate_triangles_skipped: usize,
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub name: String,
    pub meshes: Vec<Mesh>,
    pub instances: Vec<Instance>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub lights: Vec<Light>,
    /// `None` when the file had no camera; callers frame the bounds then.
    pub camera: Option<Camera>,
    pub stats: LoadStats,
    /// What moves over time; `None` for a still scene.
    pub animation: Option<crate::animation::SceneAnimation>,
}

impl Scene {
    /// Total number of triangles over all instances.
    pub fn triangle_count(&self) -> usize {
        self.instances.iter().map(|i| self.meshes[i.mesh as usize].triangle_count()).sum()
    }

    /// World-space bounds over all instances.
    pub fn bounds(&self) -> Aabb {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh as usize].bounds().transformed(&i.transform))
            .fold(Aabb::EMPTY, Aabb::union)
    }

    /// Material of triangle `prim` of instance `inst`, honouring overrides.
    #[inline]
    pub fn material_of(&self, inst: u32, prim: u32) -> MaterialId {
        let i = &self.instances[inst as usize];
        i.material_override.unwrap_or_else(|| self.meshes[i.mesh as usize].material_ids[prim as usize])
    }

    /// Adds a mesh placed once with the identity transform; returns its mesh id.
    pub fn add_mesh(&mut self, mesh: Mesh) -> MeshId {
        let id = self.meshes.len() as MeshId;
        self.meshes.push(mesh);
        self.instances.push(Instance { mesh: id, transform: Affine3A::IDENTITY, material_override: None });
        id
    }

    /// Adds a material; returns its id.
    pub fn add_material(&mut self, m: Material) -> MaterialId {
        self.materials.push(m);
        (self.materials.len() - 1) as MaterialId
    }
}
