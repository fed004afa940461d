//! The filters of `filtrace-denoise` (À-Trous, guided, cross-bilateral) in the pipeline's
//! filter slot: the guide rays' layers become a [`GBuffer`] (normal, position, depth,
//! albedo), reused from frame to frame.

use filtrace_core::Image;
use filtrace_denoise::{Filter, GBuffer};

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

fn copy_into(dst: &mut Option<Image>, src: &Image) {
    match dst {
        Some(d) if d.same_size(src) && d.channels() == src.channels() => {
            d.data_mut().copy_from_slice(src.data())
        }
        _ => *dst = Some(src.clone()),
    }
}

impl IndirectFilter for DenoiseFilter {
    fn label(&self) -> String {
        self.filter.name().to_string()
    }

    fn apply(&mut self, noisy: &Image, guide: &GuideLayers, out: &mut Image) -> Result<(), String> {
        let g = self.gbuf.get_or_insert_with(|| GBuffer::new(guide.normal.clone()));
        if g.normal.same_size(&guide.normal) {
            g.normal.data_mut().copy_from_slice(guide.normal.data());
        } else {
            g.normal = guide.normal.clone();
        }
        copy_into(&mut g.position, &guide.position);
        copy_into(&mut g.depth, &guide.depth);
        copy_into(&mut g.albedo, &guide.albedo);
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
