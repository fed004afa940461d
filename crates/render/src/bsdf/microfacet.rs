//! The Trowbridge–Reitz (GGX) microfacet distribution with Smith masking, sampled by its
//! distribution of visible normals, plus the Fresnel terms the reflective BSDFs use.
//!
//! Parameter: `alpha`, the isotropic GGX roughness. Materials store a *perceptual*
//! roughness `r ∈ [0, 1]`; [`alpha_from_roughness`] maps it to `alpha = r²` (the Disney /
//! glTF convention, so that `r` feels linear), clamped to `alpha ≥ 1e-3` because the
//! distribution becomes a delta (and f32 overflows) as `alpha → 0`.
//!
//! All directions are in the local shading frame (`z` = normal) and unit length.
//!
//! References: Walter et al. 2007, "Microfacet models for refraction through rough
//! surfaces" (GGX D, eq. 33; Smith G1, eq. 34); Heitz 2014, "Understanding the masking-
//! shadowing function" (height-correlated G2, eq. 99); Heitz 2018, "Sampling the GGX
//! distribution of visible normals" (JCGT 7(4), listing 1); pbrt-v4 chapter 9.6
//! (`TrowbridgeReitzDistribution`) and 9.3/9.5 (`FrDielectric`, `FrComplex`).

use filtrace_core::sampling::sample_concentric_disk;
use filtrace_core::{Vec2, Vec3};
use std::f32::consts::PI;

/// Smallest GGX alpha used; below it the lobe is numerically a mirror.
pub const MIN_ALPHA: f32 = 1e-3;

/// Perceptual roughness `r` → GGX `alpha = r²`, clamped to `[MIN_ALPHA, 1]`; NaN → 1
/// (the most forgiving choice: a broad lobe never produces fireflies).
#[inline]
pub fn alpha_from_roughness(r: f32) -> f32 {
    if r.is_nan() {
        return 1.0;
    }
    let r = r.clamp(0.0, 1.0);
    (r * r).max(MIN_ALPHA)
}

/// Isotropic Trowbridge–Reitz (GGX) distribution of microfacet normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrowbridgeReitz {
    pub alpha: f32,
}

impl TrowbridgeReitz {
    #[inline]
    pub fn new(alpha: f32) -> Self {
        TrowbridgeReitz { alpha: alpha.max(MIN_ALPHA) }
    }

    /// Normal distribution `D(wm) = α² / (π ((α² − 1) cos²θm + 1)²)` (Walter et al. eq. 33).
    ///
    /// The denominator is evaluated as `sin²θ + α² cos²θ` with `sin²θ` from the x and y
    /// components: `1 − cos²θ` loses every digit near the normal in f32, where it competes
    /// with `α²` down to 1e-6 (the pdf then integrated to 0.988 at `MIN_ALPHA`, and sampling
    /// and pdf disagreed at alpha 0.01: the chi-square tests in `bsdf/tests.rs`).
    #[inline]
    pub fn d(&self, wm: Vec3) -> f32 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        let (sin2, cos2) = (wm.x * wm.x + wm.y * wm.y, wm.z * wm.z);
        let a2 = self.alpha * self.alpha;
        let t = (sin2 + a2 * cos2) / (sin2 + cos2);
        a2 / (PI * t * t)
    }

    /// Smith's auxiliary function `Λ(w) = (√(1 + α² tan²θ) − 1) / 2`.
    #[inline]
    pub fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 <= 0.0 {
            return f32::INFINITY;
        }
        // tan²θ from x and y (not 1 − cos²θ, which cancels near the normal).
        let tan2 = (w.x * w.x + w.y * w.y) / cos2;
        0.5 * ((1.0 + self.alpha * self.alpha * tan2).sqrt() - 1.0)
    }

    /// Smith masking `G1(w) = 1 / (1 + Λ(w))`.
    #[inline]
    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Height-correlated masking-shadowing `G2 = 1 / (1 + Λ(wo) + Λ(wi))` (Heitz 2014 eq. 99).
    #[inline]
    pub fn g(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// Distribution of visible normals `D_wo(wm) = G1(wo) max(0, wo·wm) D(wm) / cos θo`.
    #[inline]
    pub fn d_visible(&self, wo: Vec3, wm: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        self.g1(wo) * wo.dot(wm).max(0.0) * self.d(wm) / wo.z
    }

    /// Samples a visible normal for `wo` (`wo.z > 0`) with density [`Self::d_visible`]
    /// (Heitz 2018, listing 1; the uniform disk point comes from the concentric map).
    #[inline]
    pub fn sample_wm(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let a = self.alpha;
        // Stretch wo to the hemisphere configuration (alpha = 1).
        let wh = Vec3::new(a * wo.x, a * wo.y, wo.z).normalize();
        // Orthonormal basis around wh (T1 perpendicular to z).
        let len2 = wh.x * wh.x + wh.y * wh.y;
        let t1 = if len2 > 1e-12 { Vec3::new(-wh.y, wh.x, 0.0) / len2.sqrt() } else { Vec3::X };
        let t2 = wh.cross(t1);
        // Uniform disk point, warped to the projected visible hemisphere.
        let mut p = sample_concentric_disk(u);
        let h = (1.0 - p.x * p.x).max(0.0).sqrt();
        let s = 0.5 * (1.0 + wh.z);
        p.y = (1.0 - s) * h + s * p.y;
        let pz = (1.0 - p.length_squared()).max(0.0).sqrt();
        let nh = t1 * p.x + t2 * p.y + wh * pz;
        // Unstretch.
        Vec3::new(a * nh.x, a * nh.y, nh.z.max(1e-6)).normalize()
    }
}

/// Mirror reflection of `wo` about `n`.
#[inline]
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    2.0 * wo.dot(n) * n - wo
}

/// Unpolarised Fresnel reflectance of a dielectric interface with relative index `eta`
/// (transmitted over incident side) for light arriving with `cos_i ≥ 0` from the outside
/// (pbrt-v4 `FrDielectric`; total internal reflection → 1).
#[inline]
pub fn fr_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// Minimal complex arithmetic for the conductor Fresnel term.
#[derive(Clone, Copy, Debug)]
struct Complex {
    re: f32,
    im: f32,
}

impl Complex {
    #[inline]
    fn new(re: f32, im: f32) -> Self {
        Complex { re, im }
    }
    #[inline]
    fn add(self, o: Complex) -> Complex {
        Complex::new(self.re + o.re, self.im + o.im)
    }
    #[inline]
    fn sub(self, o: Complex) -> Complex {
        Complex::new(self.re - o.re, self.im - o.im)
    }
    #[inline]
    fn mul(self, o: Complex) -> Complex {
        Complex::new(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
    }
    #[inline]
    fn scale(self, s: f32) -> Complex {
        Complex::new(self.re * s, self.im * s)
    }
    #[inline]
    fn norm(self) -> f32 {
        self.re * self.re + self.im * self.im
    }
    #[inline]
    fn div(self, o: Complex) -> Complex {
        let d = o.norm();
        Complex::new((self.re * o.re + self.im * o.im) / d, (self.im * o.re - self.re * o.im) / d)
    }
    /// Principal square root.
    #[inline]
    fn sqrt(self) -> Complex {
        let n = self.norm().sqrt();
        if n == 0.0 {
            return Complex::new(0.0, 0.0);
        }
        let t1 = (0.5 * (n + self.re.abs())).sqrt();
        let t2 = 0.5 * self.im / t1;
        if self.re >= 0.0 {
            Complex::new(t1, t2)
        } else {
            Complex::new(t2.abs(), t1.copysign(self.im))
        }
    }
}

/// Fresnel reflectance of a conductor with complex index `eta + i k` for one wavelength
/// (pbrt-v4 `FrComplex`).
#[inline]
pub fn fr_conductor_scalar(cos_i: f32, eta: f32, k: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let e = Complex::new(eta, k);
    let sin2_i = 1.0 - cos_i * cos_i;
    let sin2_t = Complex::new(sin2_i, 0.0).div(e.mul(e));
    let cos_t = Complex::new(1.0, 0.0).sub(sin2_t).sqrt();
    let ci = Complex::new(cos_i, 0.0);
    let e_ci = e.scale(cos_i);
    let r_parl = e_ci.sub(cos_t).div(e_ci.add(cos_t));
    let r_perp = ci.sub(e.mul(cos_t)).div(ci.add(e.mul(cos_t)));
    let f = 0.5 * (r_parl.norm() + r_perp.norm());
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Lane-wise square root (`powf(0.5)` is a much slower `pow` call).
#[inline]
fn sqrt3(v: Vec3) -> Vec3 {
    Vec3::new(v.x.sqrt(), v.y.sqrt(), v.z.sqrt())
}

/// Per-channel conductor Fresnel reflectance: the same formula as
/// [`fr_conductor_scalar`], evaluated for the three channels at once in `Vec3` lanes and
/// using `|a/b|² = |a|²/|b|²` to avoid complex divisions (the scalar version stays as the
/// reference it is tested against).
#[inline]
pub fn fr_conductor(cos_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    let c = cos_i.clamp(0.0, 1.0);
    let sin2_i = 1.0 - c * c;
    // e² = (η² − k²) + i 2ηk; sin²θt = sin²θi / e².
    let e2_re = eta * eta - k * k;
    let e2_im = 2.0 * eta * k;
    let inv_norm = Vec3::ONE / (e2_re * e2_re + e2_im * e2_im);
    // w = 1 − sin²θt; cos θt = √w (principal root).
    let w_re = Vec3::ONE - sin2_i * e2_re * inv_norm;
    let w_im = sin2_i * e2_im * inv_norm;
    let n = sqrt3(w_re * w_re + w_im * w_im);
    let t1 = sqrt3(0.5 * (n + w_re.abs()));
    let t2 = 0.5 * w_im / t1.max(Vec3::splat(1e-30));
    let pos = w_re.cmpge(Vec3::ZERO);
    let ct_re = Vec3::select(pos, t1, t2.abs());
    let ct_im =
        Vec3::select(pos, t2, Vec3::new(t1.x.copysign(w_im.x), t1.y.copysign(w_im.y), t1.z.copysign(w_im.z)));
    // r_parl = (e c − cos θt) / (e c + cos θt).
    let (ec_re, ec_im) = (eta * c, k * c);
    let parl_num = (ec_re - ct_re) * (ec_re - ct_re) + (ec_im - ct_im) * (ec_im - ct_im);
    let parl_den = (ec_re + ct_re) * (ec_re + ct_re) + (ec_im + ct_im) * (ec_im + ct_im);
    // r_perp = (c − e cos θt) / (c + e cos θt).
    let ect_re = eta * ct_re - k * ct_im;
    let ect_im = eta * ct_im + k * ct_re;
    let perp_num = (c - ect_re) * (c - ect_re) + ect_im * ect_im;
    let perp_den = (c + ect_re) * (c + ect_re) + ect_im * ect_im;
    let f = 0.5 * (parl_num / parl_den + perp_num / perp_den);
    // Non-finite (e.g. eta = k = 0) → total reflection, as the scalar version.
    let fin = f.is_finite_mask();
    Vec3::select(fin, f.clamp(Vec3::ZERO, Vec3::ONE), Vec3::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ D(wm) cos θm dωm = 1 (the projected microfacet area equals the macro area).
    #[test]
    fn ggx_normalisation() {
        for alpha in [0.05, 0.2, 0.5, 1.0] {
            let d = TrowbridgeReitz::new(alpha);
            // Integrate in (z = cos θ, φ): D is isotropic, dω = dz dφ.
            let n = 200_000;
            let mut s = 0.0f64;
            for i in 0..n {
                let z = (i as f64 + 0.5) / n as f64;
                let wm = Vec3::new((1.0 - z * z).sqrt() as f32, 0.0, z as f32);
                s += d.d(wm) as f64 * z * 2.0 * std::f64::consts::PI / n as f64;
            }
            assert!((s - 1.0).abs() < 2e-3, "alpha {alpha}: {s}");
        }
    }

    /// ∫ D_wo(wm) dωm = 1 for several wo (checks G1 against D).
    #[test]
    fn visible_normals_normalised() {
        for alpha in [0.1, 0.5, 1.0] {
            let d = TrowbridgeReitz::new(alpha);
            for cos_o in [0.2f32, 0.7, 1.0] {
                let wo = Vec3::new((1.0 - cos_o * cos_o).sqrt(), 0.0, cos_o);
                let (nz, nphi) = (2000, 256);
                let mut s = 0.0f64;
                for i in 0..nz {
                    let z = (i as f32 + 0.5) / nz as f32;
                    let r = (1.0 - z * z).sqrt();
                    for j in 0..nphi {
                        let phi = 2.0 * PI * (j as f32 + 0.5) / nphi as f32;
                        let wm = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                        s += d.d_visible(wo, wm) as f64;
                    }
                }
                s *= 2.0 * std::f64::consts::PI / (nz * nphi) as f64;
                assert!((s - 1.0).abs() < 5e-3, "alpha {alpha} cos {cos_o}: {s}");
            }
        }
    }

    #[test]
    fn fresnel_limits() {
        // Normal incidence: ((n-1)/(n+1))^2.
        assert!((fr_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fr_dielectric(0.0, 1.5) - 1.0).abs() < 1e-6);
        // Conductor with k = 0 equals the dielectric formula.
        for c in [0.1, 0.5, 0.9, 1.0] {
            assert!((fr_conductor_scalar(c, 1.5, 0.0) - fr_dielectric(c, 1.5)).abs() < 1e-5);
        }
        // Normal incidence: ((n-1)^2 + k^2) / ((n+1)^2 + k^2); gold-ish red channel.
        let (n, k) = (0.143f32, 3.983f32);
        let f0 = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((fr_conductor_scalar(1.0, n, k) - f0).abs() < 1e-5);
        assert!((fr_conductor_scalar(0.0, n, k) - 1.0).abs() < 1e-4);
    }

    /// The lane-wise conductor Fresnel equals the scalar complex-arithmetic reference.
    #[test]
    fn fr_conductor_vectorised_matches_scalar() {
        let metals = [
            (Vec3::new(0.143, 0.374, 1.442), Vec3::new(3.983, 2.385, 1.603)), // gold
            (Vec3::new(1.657, 0.880, 0.521), Vec3::new(9.224, 6.270, 4.837)), // aluminium
            (Vec3::new(1.5, 0.2, 3.0), Vec3::new(0.0, 0.01, 0.5)),            // k = 0 and small k
            (Vec3::ZERO, Vec3::ZERO),                                         // degenerate
        ];
        for (eta, k) in metals {
            for i in 0..=100 {
                let c = i as f32 / 100.0;
                let v = fr_conductor(c, eta, k);
                for ch in 0..3 {
                    let s = fr_conductor_scalar(c, eta[ch], k[ch]);
                    assert!((v[ch] - s).abs() < 2e-5, "cos {c} eta {eta} k {k} ch {ch}: {} vs {s}", v[ch]);
                }
            }
        }
    }

    #[test]
    fn alpha_mapping() {
        assert_eq!(alpha_from_roughness(0.5), 0.25);
        assert_eq!(alpha_from_roughness(0.0), MIN_ALPHA);
        assert_eq!(alpha_from_roughness(2.0), 1.0);
        assert_eq!(alpha_from_roughness(f32::NAN), 1.0);
    }
}
