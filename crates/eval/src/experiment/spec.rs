//! The experiment spec: a TOML file (see `experiments/*.toml` and the module docs of
//! [`crate::experiment`]), parsed and checked here. Every error names the line it is
//! about: toml's own errors carry their span, and the checks after parsing find the
//! line of the key they reject ([`locate`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use super::vpl_spec::{
    GroundTruth, Metric, VplMethod, VplOverrides, VplSampler, VplSpec, DEFAULT_CACHE_POINTS,
    DEFAULT_DISTRIBUTIONS, DEFAULT_FAINT_SHARE, DEFAULT_NEIGHBOURS, MAX_COUNT, MAX_DISTRIBUTIONS,
    MAX_NEIGHBOURS,
};

/// Version of the cache key; bump when the renderer changes what a reference contains.
pub const CACHE_VERSION: u32 = 1;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentSpec {
    pub name: String,
    pub width: u32,
    pub height: u32,
    #[serde(default = "default_max_depth")]
    pub max_depth: i32,
    #[serde(default)]
    pub seed: u64,
    pub spp: Vec<u32>,
    #[serde(default = "default_repeats")]
    pub repeats: u32,
    pub reference: ReferenceSpec,
    pub scenes: Vec<SceneSpec>,
    pub methods: Vec<MethodSpec>,
    /// Also denoise the frame of every unfiltered method (filter "none") with Intel Open
    /// Image Denoise (see [`crate::oidn`]); reported as method "<name>+oidn".
    #[serde(default)]
    pub oidn: bool,
    /// Path of `oidnDenoise` (relative to the spec file); default: `$FILTRACE_OIDN`, PATH.
    #[serde(default)]
    pub oidn_executable: Option<PathBuf>,
    /// Defaults of the many-light methods (`[vpl]`).
    #[serde(default)]
    pub vpl: VplSpec,
    /// The error of the plots and the equal-time tables (default: `relmse-clamped` with
    /// the VPL ground truth, else `relmse`).
    #[serde(default)]
    pub metric: Option<Metric>,
    /// A method whose measured times are the points of the equal-time tables.
    #[serde(default)]
    pub equal_time: Option<String>,
}

fn default_max_depth() -> i32 {
    3
}
fn default_repeats() -> u32 {
    1
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSpec {
    /// Samples per pixel of a path-traced reference (0: not given).
    #[serde(default)]
    pub spp: u32,
    /// `max_depth` of the reference (default: the experiment's).
    #[serde(default)]
    pub max_depth: Option<i32>,
    /// `"vpl"`: no path-traced reference; each method at `n` spp is judged against the
    /// exhaustive VPL sum over the same VPLs and the same camera samples `0..n`.
    #[serde(default)]
    pub ground_truth: Option<GroundTruth>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// A built-in scene name or a scene file path (relative to the spec file).
    pub name: String,
    /// Use this EXR as the reference instead of rendering one (relative to the spec file).
    #[serde(default)]
    pub reference_file: Option<PathBuf>,
    /// `[x, y, w, h]` of the zoomed crop in the report.
    #[serde(default)]
    pub crop: Option<[u32; 4]>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MethodSpec {
    pub name: String,
    /// The filter of a path-traced method (none | atrous | guided | bilateral); empty for
    /// a many-light method.
    #[serde(default)]
    pub filter: String,
    #[serde(default)]
    pub preset: Option<String>,
    /// Paths per guide ray: a number, or "spp" for as many as eye samples per pixel.
    #[serde(default)]
    pub indirect_paths: Option<toml::Value>,
    #[serde(default)]
    pub filter_direct: bool,
    /// Extra filter parameters (name → number), passed to the backend.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    /// A many-light method: the VPL sampler (`filtrace render --vpl-sampler`).
    #[serde(default)]
    pub sampler: Option<VplSampler>,
    /// Records interpolated per shading point, M (default: `[vpl]`'s, else 2).
    #[serde(default, deserialize_with = "super::vpl_spec::de_neighbours")]
    pub neighbours: Option<u32>,
    /// Distributions the sampler uses, uniform included: 1 (uniform) to 4 (full,
    /// unoccluded, bounded, uniform), added in that order (default: `[vpl]`'s, else 4).
    #[serde(default, deserialize_with = "super::vpl_spec::de_distributions")]
    pub distributions: Option<u32>,
    /// Cache points per frame (default: `[vpl]`'s, else 2048).
    #[serde(default, deserialize_with = "super::vpl_spec::de_count")]
    pub cache_points: Option<u32>,
    /// Share of a record's light its faint VPLs may carry without a visibility ray
    /// (default: `[vpl]`'s, else 0.02; 0: every ray, as the thesis).
    #[serde(default, deserialize_with = "super::vpl_spec::de_faint_share")]
    pub faint_share: Option<f32>,
}

impl MethodSpec {
    /// Paths per guide ray at `spp` eye samples per pixel.
    pub fn indirect_paths_at(&self, spp: u32) -> Result<u32, String> {
        match &self.indirect_paths {
            None => Ok(1),
            Some(toml::Value::Integer(n)) if *n >= 0 && *n <= 1 << 20 => Ok(*n as u32),
            Some(toml::Value::String(s)) if s == "spp" => Ok(spp),
            Some(v) => {
                Err(format!("method {}: indirect_paths must be a count or \"spp\", got {v}", self.name))
            }
        }
    }

    /// What renders it, for tables: the filter, or `vpl-<sampler>`.
    pub fn kind_label(&self) -> String {
        match self.sampler {
            Some(s) => format!("vpl-{}", s.name()),
            None => self.filter.clone(),
        }
    }
}

/// Where in the spec a problem is: a top-level key, a key of a `[table]`, or a key of the
/// `index`-th `[[array]]` entry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum At<'a> {
    Top(&'a str),
    Table(&'a str, &'a str),
    Item(&'a str, usize, &'a str),
}

/// A check that failed, and where.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem<'a> {
    pub at: At<'a>,
    pub message: String,
}

fn problem<T>(at: At, message: impl Into<String>) -> Result<T, Problem> {
    Err(Problem { at, message: message.into() })
}

impl ExperimentSpec {
    /// Parses and checks a spec; errors start with `line N: `.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        Self::parse(text).map_err(|(line, msg)| match line {
            Some(l) => format!("line {l}: {msg}"),
            None => msg,
        })
    }

    /// Parses and checks the spec file; errors read `PATH:LINE: message`.
    pub fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&text).map_err(|(line, msg)| match line {
            Some(l) => format!("{}:{l}: {msg}", path.display()),
            None => format!("{}: {msg}", path.display()),
        })
    }

    /// Parses and checks; on error the 1-based line (when known) and the message.
    pub fn parse(text: &str) -> Result<Self, (Option<usize>, String)> {
        let spec: ExperimentSpec = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| line_of_offset(text, s.start));
            (line, format!("experiment spec: {}", e.message().trim_end()))
        })?;
        spec.check().map_err(|p| (locate(text, p.at), p.message))?;
        Ok(spec)
    }

    /// The checks of [`Self::check`], without a line.
    pub fn validate(&self) -> Result<(), String> {
        self.check().map_err(|p| p.message)
    }

    /// Checks what the types cannot.
    pub fn check(&self) -> Result<(), Problem<'_>> {
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            let key = if self.width == 0 || self.width > 16384 { "width" } else { "height" };
            return problem(
                At::Top(key),
                format!("resolution {}x{} out of range (1..=16384)", self.width, self.height),
            );
        }
        if self.spp.is_empty() || self.spp.iter().any(|&s| s == 0 || s > 1 << 16) {
            return problem(
                At::Top("spp"),
                format!("spp must be a non-empty list of counts in 1..=65536, got {:?}", self.spp),
            );
        }
        if self.max_depth == 0 || self.max_depth < -1 {
            return problem(
                At::Top("max_depth"),
                format!("max_depth must be -1 or >= 1, got {}", self.max_depth),
            );
        }
        if self.scenes.is_empty() || self.methods.is_empty() {
            let key = if self.scenes.is_empty() { "scenes" } else { "methods" };
            return problem(At::Top(key), "an experiment needs at least one scene and one method");
        }
        if self.repeats == 0 || self.repeats > 100 {
            return problem(At::Top("repeats"), "repeats must be in 1..=100");
        }
        self.check_reference()?;
        self.check_methods()?;
        for (i, s) in self.scenes.iter().enumerate() {
            if let Some([x, y, w, h]) = s.crop {
                if w == 0 || h == 0 || x + w > self.width || y + h > self.height {
                    return problem(
                        At::Item("scenes", i, "crop"),
                        format!("scene {}: crop {:?} outside the image", s.name, [x, y, w, h]),
                    );
                }
            }
            if s.reference_file.is_some() && self.is_vpl_ground_truth() {
                return problem(
                    At::Item("scenes", i, "reference_file"),
                    format!("scene {}: reference_file cannot be used with ground_truth = \"vpl\"", s.name),
                );
            }
        }
        if let Some(b) = &self.equal_time {
            if !self.methods.iter().any(|m| &m.name == b) {
                return problem(At::Top("equal_time"), format!("equal_time names no method: {b:?}"));
            }
        }
        Ok(())
    }

    fn check_reference(&self) -> Result<(), Problem<'_>> {
        let r = &self.reference;
        match r.ground_truth {
            Some(GroundTruth::Vpl) if r.spp != 0 => problem(
                At::Table("reference", "spp"),
                "reference.spp is not used with ground_truth = \"vpl\" (the exhaustive sum takes each method's own camera samples); remove it",
            ),
            Some(GroundTruth::Vpl) => Ok(()),
            None if r.spp == 0 => problem(
                At::Table("reference", "spp"),
                "reference.spp must be at least 1 (or set ground_truth = \"vpl\")",
            ),
            None => Ok(()),
        }
    }

    fn check_methods(&self) -> Result<(), Problem<'_>> {
        for (i, m) in self.methods.iter().enumerate() {
            let at = |key| At::Item("methods", i, key);
            if !m.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
                return problem(
                    at("name"),
                    format!("method name {:?}: use letters, digits, '-' and '_'", m.name),
                );
            }
            if self.methods[..i].iter().any(|o| o.name == m.name) {
                return problem(at("name"), format!("method names must be unique: {:?} twice", m.name));
            }
            for &s in &self.spp {
                m.indirect_paths_at(s).map_err(|message| Problem { at: at("indirect_paths"), message })?;
            }
            self.check_method_kind(i, m)?;
        }
        Ok(())
    }

    fn check_method_kind<'s>(&self, i: usize, m: &'s MethodSpec) -> Result<(), Problem<'s>> {
        let at = |key| At::Item("methods", i, key);
        let vpl_only = [
            ("neighbours", m.neighbours.is_some()),
            ("distributions", m.distributions.is_some()),
            ("cache_points", m.cache_points.is_some()),
            ("faint_share", m.faint_share.is_some()),
        ];
        match m.sampler {
            None => {
                if let Some((key, _)) = vpl_only.iter().find(|k| k.1) {
                    return problem(
                        at(key),
                        format!("method {}: {key} needs a VPL sampler (sampler = ...)", m.name),
                    );
                }
                if m.filter.is_empty() {
                    return problem(
                        at("name"),
                        format!("method {}: needs a filter (path tracing) or a sampler (many-light)", m.name),
                    );
                }
                if self.is_vpl_ground_truth() {
                    return problem(at("filter"), format!("method {}: a path-traced method cannot be judged against the VPL ground truth; give it a sampler", m.name));
                }
            }
            Some(_) => {
                let path_only = [
                    ("preset", m.preset.is_some()),
                    ("indirect_paths", m.indirect_paths.is_some()),
                    ("filter_direct", m.filter_direct),
                    ("params", !m.params.is_empty()),
                ];
                if !(m.filter.is_empty() || m.filter == "none") {
                    return problem(
                        at("filter"),
                        format!(
                            "method {}: many-light methods are unfiltered (filter = {:?})",
                            m.name, m.filter
                        ),
                    );
                }
                if let Some((key, _)) = path_only.iter().find(|k| k.1) {
                    return problem(
                        at(key),
                        format!("method {}: {key} is for path-traced methods, not with a sampler", m.name),
                    );
                }
            }
        }
        Ok(())
    }

    /// True when methods are judged against the exhaustive VPL sum.
    pub fn is_vpl_ground_truth(&self) -> bool {
        self.reference.ground_truth == Some(GroundTruth::Vpl)
    }

    /// The error the plots use.
    pub fn metric(&self) -> Metric {
        self.metric.unwrap_or(if self.is_vpl_ground_truth() { Metric::RelMseClamped } else { Metric::RelMse })
    }

    /// The many-light settings of `m` with the `[vpl]` defaults; `None` for path methods.
    pub fn vpl_method(&self, m: &MethodSpec) -> Option<VplMethod> {
        let own = VplOverrides {
            neighbours: m.neighbours,
            distributions: m.distributions,
            cache_points: m.cache_points,
            faint_share: m.faint_share,
        };
        Some(self.vpl.resolve(m.sampler?, &own))
    }

    /// The stable hash of everything that determines a scene's reference: the renderer
    /// (`backend_tag`), the scene's content (`scene_fingerprint`, e.g. a hash of the loaded
    /// scene, so that an edited scene file or built-in is never judged against a stale
    /// reference) and the reference settings.
    pub fn reference_key(&self, scene: &SceneSpec, backend_tag: &str, scene_fingerprint: &str) -> String {
        let text = format!(
            "v{CACHE_VERSION}|{backend_tag}|{}|{scene_fingerprint}|{}x{}|spp{}|depth{}|seed{}",
            scene.name,
            self.width,
            self.height,
            self.reference.spp,
            self.reference.max_depth.unwrap_or(self.max_depth),
            self.seed
        );
        format!("{:016x}", fnv1a64(text.as_bytes()))
    }

    /// The key of the VPL ground truth over camera samples `0..spp`: the VPLs (count,
    /// bound, seed) and the camera samples, not the methods.
    pub fn ground_truth_key(
        &self,
        scene: &SceneSpec,
        spp: u32,
        backend_tag: &str,
        scene_fingerprint: &str,
    ) -> String {
        let text = format!(
            "v{CACHE_VERSION}|vpl-ground-truth|{backend_tag}|{}|{scene_fingerprint}|{}x{}|spp{spp}|depth{}|seed{}|vpls{}|clamp{:?}",
            scene.name, self.width, self.height, self.max_depth, self.seed, self.vpl.vpls, self.vpl.clamp
        );
        format!("{:016x}", fnv1a64(text.as_bytes()))
    }
}

/// FNV-1a, 64 bit: stable across runs and platforms (unlike `DefaultHasher`).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// 1-based line of byte `offset` in `text`.
pub fn line_of_offset(text: &str, offset: usize) -> usize {
    1 + text.as_bytes()[..offset.min(text.len())].iter().filter(|&&b| b == b'\n').count()
}

/// The 1-based line of `at` in the spec's text: the line of the key, else of the table
/// header; `None` when neither is written (e.g. a missing key at the top).
pub fn locate(text: &str, at: At) -> Option<usize> {
    let lines: Vec<&str> = text.lines().map(|l| l.split('#').next().unwrap_or("").trim()).collect();
    let is_key = |l: &str, key: &str| l.strip_prefix(key).is_some_and(|r| r.trim_start().starts_with('='));
    let find_key = |from: usize, key: &str| {
        lines[from..]
            .iter()
            .take_while(|l| !l.starts_with('['))
            .position(|l| is_key(l, key))
            .map(|p| from + p)
    };
    let found = match at {
        At::Top(key) => find_key(0, key).or_else(|| {
            // `[[scenes]]`-style keys are written as their headers.
            lines.iter().position(|l| *l == format!("[[{key}]]") || *l == format!("[{key}]"))
        }),
        At::Table(table, key) => {
            let h = lines.iter().position(|l| *l == format!("[{table}]"))?;
            find_key(h + 1, key).or(Some(h))
        }
        At::Item(array, index, key) => {
            let header = format!("[[{array}]]");
            let h = lines.iter().enumerate().filter(|(_, l)| **l == header).nth(index)?.0;
            find_key(h + 1, key).or(Some(h))
        }
    };
    found.map(|i| i + 1)
}
