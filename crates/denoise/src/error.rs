//! Errors of the filters: every bad input is reported, never a panic.

use std::fmt;

/// What went wrong with a filter's input or parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum DenoiseError {
    /// A buffer has the wrong number of channels.
    ChannelCount { buffer: &'static str, expected: &'static str, found: usize },
    /// A buffer's size differs from the colour image's.
    SizeMismatch { buffer: &'static str, expected: (usize, usize), found: (usize, usize) },
    /// A filter setting needs a guide buffer that the G-buffer lacks.
    MissingGuide { buffer: &'static str, needed_by: &'static str },
    /// A parameter is out of its documented range.
    InvalidParameter { name: &'static str, reason: String },
}

impl fmt::Display for DenoiseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::ChannelCount { buffer, expected, found } => {
                write!(f, "{buffer} buffer has {found} channels, expected {expected}")
            }
            Self::SizeMismatch { buffer, expected, found } => write!(
                f,
                "{buffer} buffer is {}x{}, but the colour image is {}x{}",
                found.0, found.1, expected.0, expected.1
            ),
            Self::MissingGuide { buffer, needed_by } => {
                write!(f, "{needed_by} needs a {buffer} guide buffer, which was not given")
            }
            Self::InvalidParameter { name, reason } => write!(f, "invalid parameter {name}: {reason}"),
        }
    }
}

impl std::error::Error for DenoiseError {}

pub(crate) fn invalid(name: &'static str, reason: impl Into<String>) -> DenoiseError {
    DenoiseError::InvalidParameter { name, reason: reason.into() }
}
