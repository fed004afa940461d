//! The G-buffer of the cache, traced only where it is read.
//!
//! Cache placement back-projects about `cache_points` screen samples through the pixel
//! centres ([`crate::cache::place_on_surfaces`]), and the cache then needs a receiver
//! (surface, BSDF, outgoing direction) at each chosen pixel only. So the primary rays are
//! traced on demand ([`CameraSurfaces`], one per pixel tried; the whole screen only when a
//! top-up's rejection draws find too little surface), and the receivers are built for the
//! records' pixels ([`RecordReceivers`]). The same rays through the same centres as a
//! full G-buffer: the same points and receivers bit for bit.

use super::eval::Receiver;
use crate::cache::{is_surface, CachePoint, ScreenSurfaces};
use filtrace_core::{Vec2, Vec3};
use filtrace_render::integrator::PathContext;
use filtrace_render::surface::SurfaceInteraction;
use filtrace_render::PinholeCamera;
use rayon::prelude::*;

/// The surfaces seen through the pixel centres of `camera`, each traced when asked for.
pub struct CameraSurfaces<'a> {
    pub ctx: PathContext<'a>,
    pub camera: &'a PinholeCamera,
}

impl CameraSurfaces<'_> {
    /// The surface through the centre of the pixel (row-major).
    fn hit(&self, pixel: usize) -> Option<SurfaceInteraction> {
        let w = self.camera.width() as usize;
        let ray = self.camera.generate_ray((pixel % w) as u32, (pixel / w) as u32, Vec2::splat(0.5));
        self.ctx.intersect(&ray)
    }

    /// The surface through the centre of the pixel, with its BSDF.
    pub fn receiver(&self, pixel: usize) -> Option<Receiver> {
        self.hit(pixel).map(|si| Receiver::new(si, self.ctx.bsdf(&si)))
    }
}

impl ScreenSurfaces for CameraSurfaces<'_> {
    fn size(&self) -> (usize, usize) {
        (self.camera.width() as usize, self.camera.height() as usize)
    }

    fn surface(&self, pixel: usize) -> Option<(Vec3, Vec3)> {
        self.hit(pixel).map(|si| (si.p, si.n_s))
    }

    /// Every pixel in parallel (each is a function of its own ray: the same mask for
    /// any thread count).
    fn surface_mask(&self) -> Vec<bool> {
        let (w, h) = self.size();
        (0..w * h).into_par_iter().map(|p| is_surface(self.surface(p))).collect()
    }
}

/// The receivers of a set of pixels (the cache records'), found by pixel.
#[derive(Clone, Debug, Default)]
pub struct RecordReceivers {
    /// Ascending pixel indices, and the surface through each (`None`: background).
    pixels: Vec<u32>,
    receivers: Vec<Option<Receiver>>,
}

impl RecordReceivers {
    /// The receivers at the pixels of `points`, traced in parallel.
    pub fn trace(surfaces: &CameraSurfaces, points: &[CachePoint]) -> Self {
        let mut pixels: Vec<u32> = points.iter().map(|p| p.pixel).collect();
        pixels.sort_unstable();
        pixels.dedup();
        let receivers = pixels.par_iter().map(|&p| surfaces.receiver(p as usize)).collect();
        RecordReceivers { pixels, receivers }
    }

    /// Every pixel of a full G-buffer (row-major), e.g. for tests.
    pub fn from_pixels(receivers: &[Option<Receiver>]) -> Self {
        RecordReceivers { pixels: (0..receivers.len() as u32).collect(), receivers: receivers.to_vec() }
    }

    /// The surface through `pixel`'s centre (`None`: background or not traced).
    pub fn get(&self, pixel: u32) -> Option<&Receiver> {
        let k = self.pixels.binary_search(&pixel).ok()?;
        self.receivers[k].as_ref()
    }

    /// Pixels held.
    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }

    /// Bytes of the two arrays (the frame's memory estimate is checked against it).
    pub fn heap_bytes(&self) -> usize {
        self.pixels.capacity() * size_of::<u32>() + self.receivers.capacity() * size_of::<Option<Receiver>>()
    }
}
