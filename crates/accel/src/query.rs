//! The single-ray queries of [`SceneAccel`]: the top level, then each object's bottom
//! level, compiled once for the SSE kernels and once, whole, for AVX2.

use crate::wide::{self, RayBoxes};
#[cfg(target_arch = "x86_64")]
use crate::Simd;
use crate::{closer, object_ray, Hit, SceneAccel, MERGED};
use filtrace_core::{Ray, Vec3A};

/// [`Ray::is_valid`] in a few vector operations (component by component it took about 70
/// instructions, a tenth of a small mesh's any-hit query): `0 x` is zero exactly for
/// finite `x`, NaN otherwise.
#[inline(always)]
pub(crate) fn valid(ray: &Ray) -> bool {
    let (o, d) = (Vec3A::from(ray.origin), Vec3A::from(ray.dir));
    let finite = (o * 0.0 + d * 0.0).cmpeq(Vec3A::ZERO).all();
    finite && d.cmpne(Vec3A::ZERO).any() && !ray.t_min.is_nan() && !ray.t_max.is_nan()
}

impl SceneAccel {
    /// Closest hit with `t` in `[ray.t_min, ray.t_max]`, or `None` (also for rays with
    /// NaN/infinite components or a zero direction).
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: `build_simd` keeps `Simd::Avx2` only where the CPU has AVX2 and FMA.
            return unsafe { self.intersect_avx2(ray) };
        }
        self.intersect_sse(ray)
    }

    /// The whole closest-hit query compiled for AVX2 (both levels inlined).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_avx2(&self, ray: &Ray) -> Option<Hit> {
        if !valid(ray) {
            return None;
        }
        self.intersect_with::<true>(ray)
    }

    /// The SSE query, out of line: inlined, its frame was set up on the AVX2 path too.
    #[inline(never)]
    fn intersect_sse(&self, ray: &Ray) -> Option<Hit> {
        if !valid(ray) {
            return None;
        }
        self.intersect_with::<false>(ray)
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
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: as in `intersect`.
            return unsafe { self.occluded_avx2(ray) };
        }
        self.occluded_sse(ray)
    }

    /// The whole any-hit query compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn occluded_avx2(&self, ray: &Ray) -> bool {
        valid(ray) && self.occluded_with::<true>(ray)
    }

    /// The SSE query, out of line (as `intersect_sse`).
    #[inline(never)]
    fn occluded_sse(&self, ray: &Ray) -> bool {
        valid(ray) && self.occluded_with::<false>(ray)
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
        // `if let`, not `Option::is_some_and`: that was compiled out of line, without the
        // AVX2 features, and the ray went through the stack twice on every query.
        if let Some((o, d)) = object_ray(&rec.world_to_object, rec.identity, ray) {
            return self.blas[rec.mesh as usize].occluded::<AVX2>(o, d, ray.t_min, ray.t_max);
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::valid;
    use filtrace_core::{Ray, Vec3};

    /// The vector form agrees with `Ray::is_valid` on every mix of special components.
    #[test]
    fn valid_is_ray_is_valid() {
        let specials =
            [0.0, -0.0, 1.5, -2.0, f32::MIN_POSITIVE, f32::MAX, f32::INFINITY, f32::NEG_INFINITY, f32::NAN];
        let mut checked = 0;
        for (k, &a) in specials.iter().enumerate() {
            for &b in &specials {
                for axis in 0..3 {
                    let mut v = [0.25f32, -0.5, 0.75];
                    v[axis] = a;
                    v[(axis + 1) % 3] = if k % 2 == 0 { b } else { v[(axis + 1) % 3] };
                    let w = Vec3::from_array(v);
                    let zero_dir = Vec3::new(a * 0.0, 0.0, -0.0);
                    for ray in [
                        Ray { origin: w, dir: Vec3::X, t_min: 0.0, t_max: f32::INFINITY },
                        Ray { origin: Vec3::ONE, dir: w, t_min: b, t_max: a },
                        Ray { origin: w, dir: zero_dir, t_min: 0.0, t_max: 1.0 },
                        Ray { origin: Vec3::ZERO, dir: Vec3::from_array([b, a, 0.0]), t_min: a, t_max: b },
                    ] {
                        assert_eq!(valid(&ray), ray.is_valid(), "{ray:?}");
                        checked += ray.is_valid() as usize;
                    }
                }
            }
        }
        assert!(checked > 100, "{checked}");
    }
}
