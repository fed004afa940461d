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

/// A filter chosen by name: `none`, or one of `filtrace-denoise`'s with its paper preset.
pub fn filter_by_name(name: &str, scene_scale: Option<f32>) -> Result<Box<dyn IndirectFilter>, String> {
    if name == "none" {
        return Ok(Box::new(NoFilter));
    }
    let f = Filter::from_name(name)
        .ok_or_else(|| format!("unknown filter {name:?} (none, atrous, guided, bilateral)"))?;
    Ok(Box::new(DenoiseFilter::new(f, scene_scale)))
}
