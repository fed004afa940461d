//! The error type of filtrace-io: every variant names the file it is about.

use std::fmt;
use std::path::PathBuf;

#[derive(Debug)]
pub enum IoError {
    /// The file could not be opened, created or written.
    Io { path: PathBuf, source: std::io::Error },
    /// The EXR decoder or encoder failed (not an EXR, truncated, unsupported feature).
    Exr { path: PathBuf, source: exr::error::Error },
    /// The PNG encoder failed.
    Png { path: PathBuf, source: image::ImageError },
    /// A layer the caller needs is not in the file.
    MissingLayer { path: PathBuf, layer: String, available: Vec<String> },
    /// The file holds no channel that could be read.
    Empty { path: PathBuf },
    /// An image handed to the writer does not fit (size or channel count).
    InvalidImage(String),
    /// The file extension names no format this crate writes.
    UnsupportedFormat { path: PathBuf },
}

impl fmt::Display for IoError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IoError::Io { path, source } => write!(f, "{}: {source}", path.display()),
            IoError::Exr { path, source } => {
                write!(f, "{}: OpenEXR error: {source}", path.display())
            }
            IoError::Png { path, source } => {
                write!(f, "{}: cannot write PNG: {source}", path.display())
            }
            IoError::MissingLayer { path, layer, available } => write!(
                f,
                "{}: no layer '{layer}' (channels in the file: {})",
                path.display(),
                if available.is_empty() { "none".to_string() } else { available.join(", ") }
            ),
            IoError::Empty { path } => {
                write!(f, "{}: the EXR holds no readable flat channel", path.display())
            }
            IoError::InvalidImage(msg) => write!(f, "invalid image: {msg}"),
            IoError::UnsupportedFormat { path } => {
                write!(f, "{}: unsupported output format (use a .exr or .png extension)", path.display())
            }
        }
    }
}

impl std::error::Error for IoError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            IoError::Io { source, .. } => Some(source),
            IoError::Exr { source, .. } => Some(source),
            IoError::Png { source, .. } => Some(source),
            _ => None,
        }
    }
}
