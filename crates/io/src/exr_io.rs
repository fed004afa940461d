//! Multi-layer float32 OpenEXR: [`ExrImage`] (named channel planes), [`write_exr`],
//! [`read_exr`].

use crate::aliases::{self, LayerAlias};
use crate::error::IoError;
use exr::prelude as x;
use filtrace_core::Image;
use std::path::{Path, PathBuf};

/// One named channel plane: `width * height` values, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrChannel {
    pub name: String,
    pub data: Vec<f32>,
}

/// An EXR's pixels as named f32 channel planes of one size (the data window).
#[derive(Clone, Debug, PartialEq)]
pub struct ExrImage {
    width: usize,
    height: usize,
    channels: Vec<ExrChannel>,
    /// The file it was read from (for error messages), if any.
    source: Option<PathBuf>,
    /// Notes from reading: parts skipped because their size differs, duplicate names.
    warnings: Vec<String>,
    /// Text attributes of the header (`name`, `value`), e.g. `filtrace:spp_done`.
    attributes: Vec<(String, String)>,
}

impl ExrImage {
    /// An empty image of `width x height` pixels with no channels yet.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            channels: Vec::new(),
            source: None,
            warnings: Vec::new(),
            attributes: Vec::new(),
        }
    }

    /// Sets a text attribute of the header (replacing one of the same name), written by
    /// [`write_exr`] and read back by [`read_exr`]. EXR text is Latin-1: other characters
    /// are an error.
    pub fn set_attribute(&mut self, name: &str, value: &str) -> Result<(), IoError> {
        if x::Text::new_or_none(name).is_none() || x::Text::new_or_none(value).is_none() || name.is_empty() {
            return Err(IoError::InvalidImage(format!(
                "EXR attribute '{name}' = '{value}': names and values must be non-empty Latin-1 text"
            )));
        }
        self.attributes.retain(|(n, _)| n != name);
        self.attributes.push((name.to_string(), value.to_string()));
        Ok(())
    }

    /// The text attribute `name` of the header, if any.
    pub fn attribute(&self, name: &str) -> Option<&str> {
        self.attributes.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }

    pub fn width(&self) -> usize {
        self.width
    }
    pub fn height(&self) -> usize {
        self.height
    }
    pub fn channels(&self) -> &[ExrChannel] {
        &self.channels
    }
    pub fn channel_names(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.name.clone()).collect()
    }
    /// Notes collected while reading (skipped parts); empty for images built in memory.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The plane of channel `name` (exact, case-sensitive).
    pub fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels.iter().find(|c| c.name == name).map(|c| c.data.as_slice())
    }

    /// Adds (or replaces) the channels `layer.names[k]` from channel `k` of `image`.
    /// `layer` empty gives bare names (`R`), otherwise `layer.R`.
    pub fn insert(&mut self, layer: &str, names: &[&str], image: &Image) -> Result<(), IoError> {
        if image.width() != self.width || image.height() != self.height {
            return Err(IoError::InvalidImage(format!(
                "layer '{layer}' is {}x{}, the EXR is {}x{}",
                image.width(),
                image.height(),
                self.width,
                self.height
            )));
        }
        if names.len() != image.channels() {
            return Err(IoError::InvalidImage(format!(
                "layer '{layer}' has {} channels but {} names were given",
                image.channels(),
                names.len()
            )));
        }
        let c = image.channels();
        for (k, short) in names.iter().enumerate() {
            let name = if layer.is_empty() { short.to_string() } else { format!("{layer}.{short}") };
            let data: Vec<f32> = image.data().chunks_exact(c).map(|p| p[k]).collect();
            match self.channels.iter_mut().find(|ch| ch.name == name) {
                Some(ch) => ch.data = data,
                None => self.channels.push(ExrChannel { name, data }),
            }
        }
        Ok(())
    }

    /// Adds a raw plane (length must be `width * height`).
    pub fn insert_channel(&mut self, name: &str, data: Vec<f32>) -> Result<(), IoError> {
        if data.len() != self.width * self.height {
            return Err(IoError::InvalidImage(format!(
                "channel '{name}' has {} values, expected {}",
                data.len(),
                self.width * self.height
            )));
        }
        self.channels.retain(|c| c.name != name);
        self.channels.push(ExrChannel { name: name.to_string(), data });
        Ok(())
    }

    /// The distinct channel-name prefixes (layers) in the file; `""` is the bare group.
    pub fn layer_prefixes(&self) -> Vec<String> {
        let mut v: Vec<String> = Vec::new();
        for c in &self.channels {
            let (p, _) = aliases::split_channel_name(&c.name);
            if !v.iter().any(|q| q == p) {
                v.push(p.to_string());
            }
        }
        v
    }

    /// Looks a layer up: each name in `names` is tried in turn (first hit wins); a name
    /// known to the alias table ([`crate::aliases`]) also finds the layer under the names
    /// other renderers use (`layer(&["albedo"])` finds `ViewLayer.Denoising Albedo.R/G/B`).
    /// Returns an image of the layer's channels (3 for colour-like layers, 1 for depth;
    /// all of the group's channels for a name outside the table).
    pub fn layer(&self, names: &[&str]) -> Option<Image> {
        names.iter().find_map(|n| self.layer_one(n))
    }

    /// [`ExrImage::layer`], with an error that names the file and lists its channels.
    pub fn require_layer(&self, names: &[&str]) -> Result<Image, IoError> {
        self.layer(names).ok_or_else(|| IoError::MissingLayer {
            path: self.source.clone().unwrap_or_else(|| PathBuf::from("<memory>")),
            layer: names.join(" / "),
            available: self.channel_names(),
        })
    }

    fn layer_one(&self, name: &str) -> Option<Image> {
        match aliases::find_alias(name) {
            Some(alias) => self.layer_by_alias(alias),
            None => self.layer_generic(name),
        }
    }

    fn group(&self, prefix_alias: &str) -> Vec<(&str, &ExrChannel)> {
        // The first prefix (in file order) that answers to the alias.
        let prefixes = self.layer_prefixes();
        let Some(prefix) = prefixes.iter().find(|p| aliases::prefix_matches(p, prefix_alias)) else {
            return Vec::new();
        };
        self.channels
            .iter()
            .filter_map(|c| {
                let (p, comp) = aliases::split_channel_name(&c.name);
                (p == prefix).then_some((comp, c))
            })
            .collect()
    }

    fn layer_by_alias(&self, alias: &LayerAlias) -> Option<Image> {
        for name in alias.names {
            let group = self.group(name);
            if group.is_empty() {
                continue;
            }
            let sets = if name.is_empty() { &alias.components[..1] } else { alias.components };
            for set in sets {
                let picked: Option<Vec<&ExrChannel>> = set
                    .iter()
                    .map(|want| {
                        group.iter().find(|(comp, _)| comp.eq_ignore_ascii_case(want)).map(|(_, c)| *c)
                    })
                    .collect();
                if let Some(picked) = picked {
                    return Some(self.interleave(&picked));
                }
            }
        }
        None
    }

    fn layer_generic(&self, name: &str) -> Option<Image> {
        let mut group = self.group(name);
        if group.is_empty() {
            return None;
        }
        group.sort_by(|a, b| {
            (aliases::generic_component_rank(a.0), a.0).cmp(&(aliases::generic_component_rank(b.0), b.0))
        });
        let picked: Vec<&ExrChannel> = group.into_iter().map(|(_, c)| c).collect();
        Some(self.interleave(&picked))
    }

    fn interleave(&self, planes: &[&ExrChannel]) -> Image {
        let c = planes.len();
        let n = self.width * self.height;
        let mut data = vec![0.0f32; n * c];
        for (k, plane) in planes.iter().enumerate() {
            for (i, v) in plane.data.iter().enumerate() {
                data[i * c + k] = *v;
            }
        }
        Image::from_vec(self.width, self.height, c, data).expect("planes are width*height long")
    }
}

/// Writes all channels as one single-part float32 EXR (ZIP compression, scan lines),
/// channels sorted by name as the format requires. The file is encoded in memory and
/// written by [`crate::write_atomic`]: a failed write leaves what was at `path` as it was
/// (the `exr` crate's own `to_file` deletes the file on an error), and `path` may be a pipe
/// or a device (the encoder seeks back to its offset table, which a pipe cannot do).
pub fn write_exr(path: impl AsRef<Path>, image: &ExrImage) -> Result<(), IoError> {
    let path = path.as_ref();
    if image.width == 0 || image.height == 0 {
        return Err(IoError::InvalidImage(format!(
            "{}: cannot write an empty {}x{} EXR",
            path.display(),
            image.width,
            image.height
        )));
    }
    if image.channels.is_empty() {
        return Err(IoError::InvalidImage(format!("{}: no channels to write", path.display())));
    }
    let list: x::SmallVec<[x::AnyChannel<x::FlatSamples>; 4]> = image
        .channels
        .iter()
        .map(|c| x::AnyChannel::new(c.name.as_str(), x::FlatSamples::F32(c.data.clone())))
        .collect();
    let mut attributes = x::LayerAttributes::default();
    for (name, value) in &image.attributes {
        // Checked by `set_attribute`.
        attributes
            .other
            .insert(x::Text::new_or_panic(name), x::AttributeValue::Text(x::Text::new_or_panic(value)));
    }
    let layer = x::Layer::new(
        (image.width, image.height),
        attributes,
        x::Encoding::SMALL_LOSSLESS,
        x::AnyChannels::sort(list),
    );
    let exr = x::Image::from_layer(layer);
    use x::WritableImage;
    let mut bytes = std::io::Cursor::new(Vec::new());
    exr.write().to_buffered(&mut bytes).map_err(|e| exr_error(path, e))?;
    let mut bytes = bytes.into_inner();
    if image.attributes.len() > 1 {
        sort_header_attributes(&mut bytes)
            .map_err(|source| IoError::Io { path: path.to_path_buf(), source })?;
    }
    crate::write_atomic(path, |w| w.write_all(&bytes))
}

/// Sorts the header attributes of a single-part EXR (in memory) by name. The exr crate
/// writes custom attributes in `HashMap` order, which changes from run to run; sorted, the
/// same image gives the same bytes. The header keeps its length, so the offset table after
/// it stays valid.
fn sort_header_attributes(file: &mut [u8]) -> std::io::Result<()> {
    let bad = || std::io::Error::new(std::io::ErrorKind::InvalidData, "EXR header not understood");
    let head = &file[..file.len().min(1 << 22)];
    let zero_after = |at: usize| head.get(at..).and_then(|b| b.iter().position(|&c| c == 0)).map(|k| at + k);
    // Magic and version (8 bytes), then `name\0 type\0 size:i32 value` records up to a 0.
    let mut records: Vec<&[u8]> = Vec::new();
    let mut at = 8;
    loop {
        let name_end = zero_after(at).ok_or_else(bad)?;
        if name_end == at {
            break;
        }
        let size_at = zero_after(name_end + 1).ok_or_else(bad)? + 1;
        let size = head.get(size_at..size_at + 4).ok_or_else(bad)?;
        let end = size_at + 4 + i32::from_le_bytes(size.try_into().map_err(|_| bad())?).max(0) as usize;
        records.push(head.get(at..end).ok_or_else(bad)?);
        at = end;
    }
    records.sort_by_key(|r| r.split(|&c| c == 0).next().unwrap_or_default());
    let sorted = records.concat();
    file[8..8 + sorted.len()].copy_from_slice(&sorted);
    Ok(())
}

fn exr_error(path: &Path, e: exr::error::Error) -> IoError {
    match e {
        exr::error::Error::Io(source) => IoError::Io { path: path.to_path_buf(), source },
        source => IoError::Exr { path: path.to_path_buf(), source },
    }
}

/// Deflate, the strongest of the EXR compressions, packs at most ~1032 bytes into one.
const MAX_COMPRESSION_RATIO: u64 = 2048;

/// Refuses a file whose headers claim more decoded pixel data than its size could hold
/// (ratio above [`MAX_COMPRESSION_RATIO`], plus 64 MiB): a corrupt size in a small file made
/// the decoder allocate gigabytes (or abort on an allocation that cannot succeed).
fn check_claimed_size(path: &Path) -> Result<(), IoError> {
    let file_len =
        std::fs::metadata(path).map_err(|source| IoError::Io { path: path.to_path_buf(), source })?.len();
    let meta = match std::panic::catch_unwind(|| exr::meta::MetaData::read_from_file(path, false)) {
        Ok(Ok(m)) => m,
        Ok(Err(e)) => return Err(exr_error(path, e)),
        Err(_) => return Err(IoError::InvalidImage(format!("{}: corrupt EXR header", path.display()))),
    };
    let decoded: u64 = meta
        .headers
        .iter()
        .map(|h| (h.layer_size.area() as u64).saturating_mul(h.channels.bytes_per_pixel as u64))
        .fold(0, u64::saturating_add);
    if decoded > file_len.saturating_mul(MAX_COMPRESSION_RATIO).saturating_add(64 << 20) {
        return Err(IoError::InvalidImage(format!(
            "{}: the header claims {decoded} bytes of pixels in a {file_len}-byte file (corrupt size)",
            path.display()
        )));
    }
    Ok(())
}

/// Reads every flat channel of every part (largest mip level) as f32. Parts of another
/// size than the first are skipped with a note in [`ExrImage::warnings`]; part names
/// become prefixes (`part.R`).
pub fn read_exr(path: impl AsRef<Path>) -> Result<ExrImage, IoError> {
    let path = path.as_ref();
    if !path.exists() {
        return Err(IoError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "file not found"),
        });
    }
    check_claimed_size(path)?;
    use x::{ReadChannels, ReadLayers};
    // Decompressed on this thread, so that a panic of the decoder on a corrupt file (exr 1.74's
    // B44 decoder overflows on some) is caught here; on its worker threads it aborted.
    let read = || {
        x::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .non_parallel()
            .from_file(path)
    };
    let file = match std::panic::catch_unwind(read) {
        Ok(r) => r.map_err(|e| exr_error(path, e))?,
        Err(_) => {
            return Err(IoError::InvalidImage(format!(
                "{}: corrupt EXR (the decoder failed on its data)",
                path.display()
            )))
        }
    };
    let Some(first) = file.layer_data.first() else {
        return Err(IoError::Empty { path: path.to_path_buf() });
    };
    let (w, h) = (first.size.0, first.size.1);
    let mut out = ExrImage::new(w, h);
    out.source = Some(path.to_path_buf());
    for (name, value) in file.attributes.other.iter().chain(&first.attributes.other) {
        if let x::AttributeValue::Text(t) = value {
            out.attributes.push((name.to_string(), t.to_string()));
        }
    }
    for layer in &file.layer_data {
        let part = layer.attributes.layer_name.as_ref().map(|t| t.to_string());
        if layer.size.0 != w || layer.size.1 != h {
            out.warnings.push(format!(
                "part '{}' skipped: {}x{} differs from {w}x{h}",
                part.as_deref().unwrap_or(""),
                layer.size.0,
                layer.size.1
            ));
            continue;
        }
        for ch in &layer.channel_data.list {
            let short = ch.name.to_string();
            let name = match &part {
                Some(p) if !p.is_empty() => format!("{p}.{short}"),
                _ => short,
            };
            let data: Vec<f32> = match &ch.sample_data {
                x::FlatSamples::F16(v) => v.iter().map(|s| s.to_f32()).collect(),
                x::FlatSamples::F32(v) => v.clone(),
                x::FlatSamples::U32(v) => v.iter().map(|s| *s as f32).collect(),
            };
            if out.channel(&name).is_some() {
                out.warnings.push(format!("duplicate channel '{name}' ignored"));
                continue;
            }
            out.channels.push(ExrChannel { name, data });
        }
    }
    if out.channels.is_empty() {
        return Err(IoError::Empty { path: path.to_path_buf() });
    }
    Ok(out)
}
