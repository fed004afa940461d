//! The single-ray queries of [`SceneAccel`]: the top level, then each object's bottom
//! level, compiled once for the SSE kernels and once, whole, for AVX2.

use crate::wide::{self, RayBoxes};
#[cfg(target_arch = "x86_64")]
use crate::Simd;
use crate::{closer, object_ray, Hit, SceneAccel, MERGED};
use filtrace_core::Ray;

impl SceneAccel {
    /// Closest hit with `t` in `[ray.t_min, ray.t_max]`, or `None` (also for rays with
    /// NaN/infinite components or a zero direction).
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: `build_simd` keeps `Simd::Avx2` only where the CPU has AVX2 and FMA.
            return unsafe { self.intersect_avx2(ray) };
        }
        self.intersect_with::<false>(ray)
    }

    /// The whole closest-hit query compiled for AVX2 (both levels inlined).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_avx2(&self, ray: &Ray) -> Option<Hit> {
        self.intersect_with::<true>(ray)
    }

    #[inline(always)]
    pub(crate) fn intersect_with<const AVX2: bool>(&self, ray: &Ray) -> Option<Hit> {
        let mut t_max = ray.t_max;
        if let Some(o) = self.single {
            return self.intersect_object::<AVX2>(o, ray, &mut t_max);
        }
        let mut best = None;
        let rb = RayBoxes::new(ray.origin, ray.dir);
        wide::traverse::<_, true>(
            &self.tlas,
            &rb,
            ray.t_min,
            &mut t_max,
            |first: u32, count: u32, t_max: &mut f32| {
                for k in first..first + count {
                    let object = self.tlas_order[k as usize];
                    if let Some(h) = self.intersect_object::<AVX2>(object, ray, t_max) {
                        let smaller =
                            || best.is_some_and(|b: Hit| (h.instance, h.prim) < (b.instance, b.prim));
                        if closer(h.t, best.map(|b| b.t), smaller) {
                            best = Some(h);
                        }
                    }
                }
                false
            },
        );
        best
    }

    /// True when anything is hit with `t` in `[ray.t_min, ray.t_max]` (false for invalid rays).
    pub fn occluded(&self, ray: &Ray) -> bool {
        if !ray.is_valid() {
            return false;
        }
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: as in `intersect`.
            return unsafe { self.occluded_avx2(ray) };
        }
        self.occluded_with::<false>(ray)
    }

    /// The whole any-hit query compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn occluded_avx2(&self, ray: &Ray) -> bool {
        self.occluded_with::<true>(ray)
    }

    #[inline(always)]
    pub(crate) fn occluded_with<const AVX2: bool>(&self, ray: &Ray) -> bool {
        if let Some(o) = self.single {
            return self.occluded_object::<AVX2>(o, ray);
        }
        let rb = RayBoxes::new(ray.origin, ray.dir);
        let mut t_max = ray.t_max;
        wide::traverse::<_, false>(
            &self.tlas,
            &rb,
            ray.t_min,
            &mut t_max,
            |first: u32, count: u32, _: &mut f32| {
                (first..first + count).any(|k| self.occluded_object::<AVX2>(self.tlas_order[k as usize], ray))
            },
        )
    }

    #[inline(always)]
    fn intersect_object<const AVX2: bool>(&self, object: u32, ray: &Ray, t_max: &mut f32) -> Option<Hit> {
        if object == MERGED {
            let (t, u, v, k) = self.merged.intersect::<AVX2>(ray.origin, ray.dir, ray.t_min, t_max)?;
            let (instance, prim) = self.merged_refs[k as usize];
            return Some(Hit { t, u, v, instance, prim });
        }
        let inst = object;
        let rec = &self.instances[inst as usize];
        let (o, d) = object_ray(&rec.world_to_object, rec.identity, ray)?;
        let (t, u, v, prim) = self.blas[rec.mesh as usize].intersect::<AVX2>(o, d, ray.t_min, t_max)?;
        Some(Hit { t, u, v, instance: inst, prim })
    }

    #[inline(always)]
    fn occluded_object<const AVX2: bool>(&self, object: u32, ray: &Ray) -> bool {
        if object == MERGED {
            return self.merged.occluded::<AVX2>(ray.origin, ray.dir, ray.t_min, ray.t_max);
        }
        let rec = &self.instances[object as usize];
        object_ray(&rec.world_to_object, rec.identity, ray)
            .is_some_and(|(o, d)| self.blas[rec.mesh as usize].occluded::<AVX2>(o, d, ray.t_min, ray.t_max))
    }
}
