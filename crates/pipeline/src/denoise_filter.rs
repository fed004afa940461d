//! The filters of `filtrace-denoise` (À-Trous, guided, cross-bilateral) in the pipeline's
//! filter slot: the guide rays' layers become a [`GBuffer`] (normal, position, depth,
//! albedo), reused from frame to frame.

use filtrace_core::Image;
use filtrace_denoise::{Filter, GBuffer, Guidance};
use rayon::prelude::*;

use crate::filter::{GuideLayers, IndirectFilter, NoFilter};

/// A `filtrace-denoise` filter with a fixed scene scale (so that it is stable over frames).
pub struct DenoiseFilter {
    pub filter: Filter,
    /// Length positions and depths are divided by (the scene's bounding-box diagonal);
    /// `None`: estimated per frame by the filter.
    pub scene_scale: Option<f32>,
    gbuf: Option<GBuffer>,
}

impl DenoiseFilter {
    pub fn new(filter: Filter, scene_scale: Option<f32>) -> Self {
        Self { filter, scene_scale, gbuf: None }
    }
}

/// `src` into `dst` (reusing its allocation when the size matches), in parallel; `None`
/// when the filter does not read the layer.
fn copy_layer(dst: &mut Option<Image>, src: &Image, read: bool) {
    if !read {
        *dst = None;
        return;
    }
    match dst {
        Some(d) if d.same_size(src) && d.channels() == src.channels() => copy_par(d, src),
        _ => *dst = Some(src.clone()),
    }
}

fn copy_par(dst: &mut Image, src: &Image) {
    // 64 Ki values (256 KiB) per task.
    dst.data_mut().par_chunks_mut(1 << 16).zip(src.data().par_chunks(1 << 16)).for_each(|(d, s)| {
        d.copy_from_slice(s);
    });
}

impl IndirectFilter for DenoiseFilter {
    fn label(&self) -> String {
        self.filter.name().to_string()
    }

    fn apply(&mut self, noisy: &Image, guide: &GuideLayers, out: &mut Image) -> Result<(), String> {
        // Only the layers the filter reads are copied: no filter reads the albedo (the
        // pipeline demodulates before filtering), and the guided filter reads the position
        // never and the depth only with normal+depth guidance (tested: the output is the
        // same bits as with every layer given).
        let (position, depth) = match self.filter {
            Filter::Guided(p) => (false, p.guidance == Guidance::NormalDepth),
            Filter::Atrous(_) | Filter::Bilateral(_) => (true, true),
        };
        let g = self.gbuf.get_or_insert_with(|| GBuffer::new(guide.normal.clone()));
        if g.normal.same_size(&guide.normal) && g.normal.channels() == guide.normal.channels() {
            copy_par(&mut g.normal, &guide.normal);
        } else {
            g.normal = guide.normal.clone();
        }
        copy_layer(&mut g.position, &guide.position, position);
        copy_layer(&mut g.depth, &guide.depth, depth);
        g.albedo = None;
        g.scene_scale = self.scene_scale;
        self.filter.apply_into(noisy, g, out).map_err(|e| e.to_string())
    }
}

/// Which filter and how: a name (`none`, `atrous`, `guided`, `bilateral`), an optional
/// named preset of that filter (default: its paper preset), and optional overrides.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FilterChoice {
    pub name: String,
    pub preset: Option<String>,
    /// Window radius (guided, bilateral).
    pub radius: Option<u32>,
    /// Number of levels (À-Trous).
    pub iterations: Option<u32>,
}

impl FilterChoice {
    pub fn named(name: &str) -> Self {
        Self { name: name.to_string(), ..Self::default() }
    }

    /// The `filtrace-denoise` filter, or `None` for `none`. Errors name the valid choices.
    pub fn denoise_filter(&self) -> Result<Option<Filter>, String> {
        use filtrace_denoise::{AtrousParams, BilateralParams, GuidedParams};
        fn pick<P: Copy>(
            filter: &str,
            presets: &[(&'static str, P)],
            want: Option<&str>,
        ) -> Result<P, String> {
            let want = want.unwrap_or(presets[0].0);
            presets.iter().find(|(n, _)| *n == want).map(|(_, p)| *p).ok_or_else(|| {
                let names: Vec<_> = presets.iter().map(|(n, _)| *n).collect();
                format!("filter {filter} has no preset {want:?} (presets: {})", names.join(", "))
            })
        }
        let preset = self.preset.as_deref();
        let f = match self.name.as_str() {
            "none" => {
                if self.preset.is_some() || self.radius.is_some() || self.iterations.is_some() {
                    return Err("filter none takes no preset, radius or iterations".into());
                }
                return Ok(None);
            }
            "atrous" => {
                let mut p = pick("atrous", &AtrousParams::presets(), preset)?;
                if let Some(i) = self.iterations {
                    p.iterations = i;
                }
                p.validate().map_err(|e| e.to_string())?;
                Filter::Atrous(p)
            }
            "guided" => {
                let mut p = pick("guided", &GuidedParams::presets(), preset)?;
                if let Some(r) = self.radius {
                    p.radius = r;
                }
                p.validate().map_err(|e| e.to_string())?;
                Filter::Guided(p)
            }
            "bilateral" => {
                let mut p = pick("bilateral", &BilateralParams::presets(), preset)?;
                if let Some(r) = self.radius {
                    p.radius = r;
                    p.sigma_spatial = r as f32 / 2.0;
                }
                p.validate().map_err(|e| e.to_string())?;
                Filter::Bilateral(p)
            }
            other => return Err(format!("unknown filter {other:?} (none, atrous, guided, bilateral)")),
        };
        if self.radius.is_some() && matches!(f, Filter::Atrous(_)) {
            return Err("atrous has no radius; use iterations".into());
        }
        if self.iterations.is_some() && !matches!(f, Filter::Atrous(_)) {
            return Err(format!("{} has no iterations; use radius", self.name));
        }
        Ok(Some(f))
    }

    /// The filter for the pipeline's filter slot.
    pub fn build(&self, scene_scale: Option<f32>) -> Result<Box<dyn IndirectFilter>, String> {
        Ok(match self.denoise_filter()? {
            None => Box::new(NoFilter),
            Some(f) => Box::new(DenoiseFilter::new(f, scene_scale)),
        })
    }
}

/// A filter chosen by name with its paper preset: `none`, `atrous`, `guided`, `bilateral`.
pub fn filter_by_name(name: &str, scene_scale: Option<f32>) -> Result<Box<dyn IndirectFilter>, String> {
    FilterChoice::named(name).build(scene_scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::rng::{splitmix64, unit_f32};

    /// Guide layers of two tilted planes meeting at a crease, with a strip of background,
    /// a zero-albedo patch and a noisy indirect map.
    fn layers(w: usize, h: usize) -> (Image, GuideLayers) {
        let mut noisy = Image::new(w, h, 3);
        let mut g = GuideLayers {
            normal: Image::new(w, h, 3),
            depth: Image::new(w, h, 1),
            albedo: Image::new(w, h, 3),
            position: Image::new(w, h, 3),
            coverage: Image::new(w, h, 1),
        };
        let mut s = 7u64;
        let mut u = || {
            s = splitmix64(s);
            unit_f32(s)
        };
        for y in 0..h {
            for x in 0..w {
                if x < 2 {
                    continue; // background: all zero
                }
                let left = x < w / 2;
                let n = if left { [0.6f32, 0.0, 0.8] } else { [-0.6, 0.0, 0.8] };
                let (fx, fy) = (x as f32, y as f32);
                g.normal.pixel_mut(x, y).copy_from_slice(&n);
                g.depth.pixel_mut(x, y)[0] = 3.0 + 0.05 * fx.min(w as f32 - fx);
                g.position.pixel_mut(x, y).copy_from_slice(&[
                    fx * 0.1,
                    fy * 0.1,
                    0.05 * fx.min(w as f32 - fx),
                ]);
                g.albedo.pixel_mut(x, y).copy_from_slice(&[0.7, 0.5 * u(), if y == 3 { 0.0 } else { 0.3 }]);
                g.coverage.pixel_mut(x, y)[0] = 1.0;
                let c = if left { 0.3 } else { 1.2 };
                noisy.pixel_mut(x, y).copy_from_slice(&[c * 2.0 * u(), c * 2.0 * u(), c * 2.0 * u()]);
            }
        }
        (noisy, g)
    }

    #[test]
    fn layers_left_out_of_the_filters_gbuffer_are_layers_no_filter_reads() {
        // Every preset of every filter through `DenoiseFilter` (which copies only what the
        // filter reads) against the same filter given every layer: the same bits. Twice, so
        // that the reused G-buffer is checked too.
        use filtrace_denoise::{AtrousParams, BilateralParams, GuidedParams};
        let (w, h) = (37, 23);
        let (noisy, g) = layers(w, h);
        let full = GBuffer {
            normal: g.normal.clone(),
            position: Some(g.position.clone()),
            depth: Some(g.depth.clone()),
            albedo: Some(g.albedo.clone()),
            scene_scale: Some(5.0),
        };
        let mut filters: Vec<Filter> = Vec::new();
        filters.extend(AtrousParams::presets().iter().map(|p| Filter::Atrous(p.1)));
        filters.extend(
            GuidedParams::presets().iter().map(|p| Filter::Guided(GuidedParams { radius: 4, ..p.1 })),
        );
        filters.extend(BilateralParams::presets().iter().map(|p| Filter::Bilateral(p.1)));
        for f in filters {
            let mut want = Image::new(w, h, 3);
            f.apply_into(&noisy, &full, &mut want).unwrap();
            let mut df = DenoiseFilter::new(f, Some(5.0));
            for round in 0..2 {
                let mut got = Image::new(w, h, 3);
                df.apply(&noisy, &g, &mut got).unwrap();
                let bits = |i: &Image| i.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "{f:?}, round {round}");
            }
        }
    }

    #[test]
    fn every_preset_of_every_filter_is_reachable_by_name_and_bad_choices_are_errors() {
        use filtrace_denoise::{AtrousParams, BilateralParams, GuidedParams};
        let names: Vec<(&str, Vec<&str>)> = vec![
            ("atrous", AtrousParams::presets().iter().map(|p| p.0).collect()),
            ("guided", GuidedParams::presets().iter().map(|p| p.0).collect()),
            ("bilateral", BilateralParams::presets().iter().map(|p| p.0).collect()),
        ];
        for (f, presets) in names {
            for p in presets {
                let c = FilterChoice { preset: Some(p.into()), ..FilterChoice::named(f) };
                assert_eq!(c.denoise_filter().unwrap().unwrap().name(), f);
            }
        }
        assert_eq!(FilterChoice::named("none").denoise_filter(), Ok(None));
        let bad = [
            FilterChoice::named("median"),
            FilterChoice { preset: Some("nope".into()), ..FilterChoice::named("guided") },
            FilterChoice { radius: Some(0), ..FilterChoice::named("guided") },
            FilterChoice { radius: Some(4), ..FilterChoice::named("atrous") },
            FilterChoice { iterations: Some(3), ..FilterChoice::named("guided") },
            FilterChoice { preset: Some("paper".into()), ..FilterChoice::named("none") },
        ];
        for c in bad {
            assert!(c.denoise_filter().is_err(), "{c:?}");
        }
        let r = FilterChoice { radius: Some(8), ..FilterChoice::named("guided") }.denoise_filter().unwrap();
        assert!(matches!(r, Some(Filter::Guided(p)) if p.radius == 8));
    }
}
