//! The preview animation of a sequence: an animated PNG (APNG, which browsers and most
//! image viewers play) assembled in-process from the frames' PNG files, looping, each
//! frame shown for one frame time of the animation.

use std::io::{self, BufReader};
use std::path::{Path, PathBuf};

/// Writes the APNG `path` (atomically: an earlier preview stays whole until the new one is
/// complete) from the 8-bit RGB PNGs `frames`, all of one size, at `fps` frames per second.
pub fn write_preview(path: &Path, frames: &[PathBuf], fps: f32) -> anyhow::Result<()> {
    let Some(first) = frames.first() else { anyhow::bail!("no frames for the preview {}", path.display()) };
    let (width, height) = read_rgb8(first)?.0;
    filtrace_io::write_atomic(path, |w| {
        let mut encoder = png::Encoder::new(w, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_animated(frames.len() as u32, 0).map_err(io::Error::other)?;
        let (num, den) = frame_delay(fps);
        encoder.set_frame_delay(num, den).map_err(io::Error::other)?;
        let mut writer = encoder.write_header().map_err(io::Error::other)?;
        for frame in frames {
            let (size, data) = read_rgb8(frame).map_err(io::Error::other)?;
            if size != (width, height) {
                let msg = format!(
                    "{}: {}x{}, the first frame is {width}x{height}",
                    frame.display(),
                    size.0,
                    size.1
                );
                return Err(io::Error::other(msg));
            }
            writer.write_image_data(&data).map_err(io::Error::other)?;
        }
        writer.finish().map_err(io::Error::other)
    })?;
    Ok(())
}

/// `1 / fps` seconds as the APNG's `delay_num / delay_den` (both 16-bit).
fn frame_delay(fps: f32) -> (u16, u16) {
    let den = (fps as f64 * 100.0).round().clamp(1.0, u16::MAX as f64) as u16;
    (100, den)
}

/// Size and pixels of an 8-bit RGB PNG (the whole file is decoded: a truncated one fails).
pub fn read_rgb8(path: &Path) -> anyhow::Result<((u32, u32), Vec<u8>)> {
    let file = std::fs::File::open(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let mut reader = png::Decoder::new(BufReader::new(file))
        .read_info()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let size = reader.output_buffer_size().unwrap_or(0);
    let mut data = vec![0; size];
    let info = reader.next_frame(&mut data).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if info.color_type != png::ColorType::Rgb || info.bit_depth != png::BitDepth::Eight {
        anyhow::bail!("{}: not an 8-bit RGB PNG", path.display());
    }
    data.truncate(info.buffer_size());
    Ok(((info.width, info.height), data))
}

/// The number of frames of the APNG `path` (1 for a plain PNG) and their size.
#[cfg(test)]
pub fn apng_frames(path: &Path) -> (u32, (u32, u32)) {
    let file = std::fs::File::open(path).unwrap();
    let reader = png::Decoder::new(BufReader::new(file)).read_info().unwrap();
    let info = reader.info();
    (info.animation_control().map_or(1, |a| a.num_frames), (info.width, info.height))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_preview_of_three_frames_decodes_with_three_frames() {
        let dir = std::env::temp_dir().join(format!("filtrace-preview-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let frames: Vec<PathBuf> = (0..3)
            .map(|k| {
                let mut img = filtrace_core::Image::new(5, 4, 3);
                img.data_mut().iter_mut().for_each(|v| *v = k as f32 / 3.0);
                let p = dir.join(format!("f.{k:04}.png"));
                filtrace_io::write_png(&p, &img, &filtrace_io::TonemapParams::srgb_clamp()).unwrap();
                p
            })
            .collect();
        let out = dir.join("f.preview.png");
        write_preview(&out, &frames, 24.0).unwrap();
        assert_eq!(apng_frames(&out), (3, (5, 4)));
        let mut decoder =
            png::Decoder::new(BufReader::new(std::fs::File::open(&out).unwrap())).read_info().unwrap();
        let mut buf = vec![0; decoder.output_buffer_size().unwrap()];
        for k in 0..3u8 {
            decoder.next_frame(&mut buf).unwrap();
            let want = filtrace_io::srgb_oetf(k as f32 / 3.0);
            assert!((buf[0] as f32 / 255.0 - want).abs() < 1.0 / 255.0, "frame {k}: {}", buf[0]);
        }
        assert_eq!(frame_delay(24.0), (100, 2400));
        assert!(write_preview(&out, &[], 24.0).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
