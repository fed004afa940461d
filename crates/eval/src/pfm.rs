//! Portable float maps (PFM): the simplest float image file, used for the reference cache of
//! experiments and to exchange images with Intel Open Image Denoise's `oidnDenoise`.
//! Colour (`PF`, 3 channels) or greyscale (`Pf`); little-endian; rows stored bottom to top.

use std::io::Read;
use std::path::Path;

use filtrace_core::Image;

/// Writes a 1- or 3-channel image (other channel counts: the first three, zero-padded),
/// through `filtrace_io::write_atomic`, so that an interrupted write never leaves a
/// truncated reference in the experiment cache.
pub fn write_pfm(path: &Path, img: &Image) -> Result<(), filtrace_io::IoError> {
    let (w, h, c) = (img.width(), img.height(), img.channels());
    let out_c = if c == 1 { 1 } else { 3 };
    let mut bytes = format!("{}\n{w} {h}\n-1.0\n", if out_c == 3 { "PF" } else { "Pf" }).into_bytes();
    bytes.reserve(w * h * out_c * 4);
    for y in (0..h).rev() {
        for x in 0..w {
            let p = img.pixel(x, y);
            for k in 0..out_c {
                bytes.extend_from_slice(&p.get(k).copied().unwrap_or(0.0).to_le_bytes());
            }
        }
    }
    filtrace_io::write_atomic(path, |w| w.write_all(&bytes))
}

/// Reads a PFM written by [`write_pfm`] or another program (either byte order).
pub fn read_pfm(path: &Path) -> std::io::Result<Image> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.read_to_end(&mut bytes)?;
    parse_pfm(&bytes).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, format!("PFM: {e}")))
}

fn parse_pfm(bytes: &[u8]) -> Result<Image, String> {
    // Three whitespace-separated header tokens sets (magic, size, scale), then one
    // whitespace byte, then the data.
    let mut pos = 0;
    let mut token = || -> Result<String, String> {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err("truncated header".into());
        }
        Ok(String::from_utf8_lossy(&bytes[start..pos]).into_owned())
    };
    let c = match token()?.as_str() {
        "PF" => 3,
        "Pf" => 1,
        m => return Err(format!("bad magic {m:?}")),
    };
    let w: usize = token()?.parse().map_err(|_| "bad width")?;
    let h: usize = token()?.parse().map_err(|_| "bad height")?;
    let scale: f32 = token()?.parse().map_err(|_| "bad scale")?;
    if w == 0 || h == 0 || w > 1 << 16 || h > 1 << 16 {
        return Err(format!("bad size {w}x{h}"));
    }
    let data = &bytes[pos + 1..];
    let n = w * h * c;
    if data.len() < n * 4 {
        return Err(format!("{} bytes of data, {} needed", data.len(), n * 4));
    }
    let mut img = Image::new(w, h, c);
    for (i, chunk) in data[..n * 4].chunks_exact(4).enumerate() {
        let b = [chunk[0], chunk[1], chunk[2], chunk[3]];
        let v = if scale < 0.0 { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) };
        let (x, yb, k) = ((i / c) % w, (i / c) / w, i % c);
        img.pixel_mut(x, h - 1 - yb)[k] = v;
    }
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_every_value_and_the_row_order() {
        let dir = std::env::temp_dir().join(format!("filtrace-pfm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for c in [1, 3] {
            let data: Vec<f32> = (0..5 * 3 * c).map(|i| i as f32 * 0.25 - 1.0).collect();
            let img = Image::from_vec(5, 3, c, data).unwrap();
            let p = dir.join(format!("t{c}.pfm"));
            write_pfm(&p, &img).unwrap();
            assert_eq!(read_pfm(&p).unwrap(), img);
        }
        std::fs::write(dir.join("bad.pfm"), b"PF\n2 2\n-1\n\x00").unwrap();
        assert!(read_pfm(&dir.join("bad.pfm")).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
