//! Intel Open Image Denoise as a comparison method, through the `oidnDenoise` command-line
//! tool (shipped by PyPI `pyoidn` as `pyoidn/oidn/bin/oidnDenoise`): the noisy frame, its
//! albedo and normal go out as PFM files, the denoised frame comes back as PFM. OIDN denoises
//! the whole colour (direct and indirect light), unlike the pipeline's filters.
//!
//! The tool is found from, in order: the spec's `oidn_executable`, the environment variable
//! `FILTRACE_OIDN`, `oidnDenoise` on `PATH`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use filtrace_core::Image;

/// How to enable the comparison, for reports.
pub const HOW_TO_ENABLE: &str =
    "Intel Open Image Denoise: add `oidn = true` to the spec and make `oidnDenoise` \
findable (`pip install pyoidn` ships it as site-packages/pyoidn/oidn/bin/oidnDenoise; point FILTRACE_OIDN \
or the spec's `oidn_executable` at it, or put it on PATH).";

/// The `oidnDenoise` to use, if any.
pub fn find_executable(from_spec: Option<&Path>) -> Option<PathBuf> {
    if let Some(p) = from_spec {
        return p.is_file().then(|| p.to_path_buf());
    }
    if let Some(p) = std::env::var_os("FILTRACE_OIDN").map(PathBuf::from) {
        return p.is_file().then_some(p);
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|d| d.join("oidnDenoise")).find(|p| p.is_file())
}

/// Denoises `color` (3 channels, HDR) with `albedo` and `normal` (3 channels each) by
/// running `exe` in folder `work`. Returns the image and the milliseconds the tool took
/// (process start and PFM I/O included).
pub fn denoise(
    exe: &Path,
    work: &Path,
    color: &Image,
    albedo: &Image,
    normal: &Image,
) -> Result<(Image, f64), String> {
    std::fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
    let (c, a, n, o) =
        (work.join("color.pfm"), work.join("albedo.pfm"), work.join("normal.pfm"), work.join("out.pfm"));
    for (p, im) in [(&c, color), (&a, albedo), (&n, normal)] {
        crate::pfm::write_pfm(p, im).map_err(|e| e.to_string())?;
    }
    std::fs::remove_file(&o).ok();
    let t = Instant::now();
    let result = Command::new(exe)
        .arg("--hdr")
        .arg(&c)
        .arg("--alb")
        .arg(&a)
        .arg("--nrm")
        .arg(&n)
        .arg("-o")
        .arg(&o)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", exe.display()))?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    if !result.status.success() {
        return Err(format!(
            "{} failed ({}): {}",
            exe.display(),
            result.status,
            String::from_utf8_lossy(&result.stderr).trim()
        ));
    }
    let out = crate::pfm::read_pfm(&o).map_err(|e| format!("{}: {e}", o.display()))?;
    if !out.same_size(color) {
        return Err(format!("{} returned a {}x{} image", exe.display(), out.width(), out.height()));
    }
    Ok((out, ms))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    /// A stand-in for `oidnDenoise` that checks the arguments and halves the colour, so the
    /// PFM protocol is tested without OIDN installed.
    #[test]
    fn protocol_round_trip_with_a_fake_tool() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("filtrace-oidn-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let exe = dir.join("fakeDenoise");
        // Copies --hdr to -o (PFM bytes unchanged) after checking --alb and --nrm exist.
        std::fs::write(
            &exe,
            "#!/bin/sh\nwhile [ $# -gt 0 ]; do case $1 in --hdr) c=$2;; --alb) a=$2;; --nrm) n=$2;; -o) o=$2;; esac; shift 2; done\n\
             [ -f \"$a\" ] && [ -f \"$n\" ] && cp \"$c\" \"$o\"\n",
        )
        .unwrap();
        std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).unwrap();
        let data: Vec<f32> = (0..4 * 3 * 3).map(|i| i as f32 * 0.5).collect();
        let color = Image::from_vec(4, 3, 3, data).unwrap();
        let aux = Image::filled(4, 3, 3, 0.5);
        let (out, ms) = denoise(&exe, &dir.join("work"), &color, &aux, &aux).unwrap();
        assert_eq!(out, color);
        assert!(ms >= 0.0);
        // A failing tool is an error with its message, not a panic.
        std::fs::write(&exe, "#!/bin/sh\necho broken >&2\nexit 3\n").unwrap();
        let e = denoise(&exe, &dir.join("work"), &color, &aux, &aux).unwrap_err();
        assert!(e.contains("broken"), "{e}");
        assert!(find_executable(Some(&dir.join("missing"))).is_none());
        std::fs::remove_dir_all(&dir).ok();
    }
}
