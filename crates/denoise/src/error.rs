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

/// Errors unless `v` is finite and > 0 (a sigma, eps or scale that is 0, negative or NaN
/// would divide by zero or weigh nothing).
pub(crate) fn require_positive(name: &'static str, v: f32) -> Result<(), DenoiseError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(name, format!("must be finite and > 0, got {v}")))
    }
}

/// The edge-stopping sigmas of the À-Trous and bilateral filters: each off (`None`) or
/// finite and > 0.
pub(crate) fn require_positive_sigmas(
    color: Option<f32>,
    normal: Option<f32>,
    position: Option<f32>,
) -> Result<(), DenoiseError> {
    for (name, s) in [("sigma_color", color), ("sigma_normal", normal), ("sigma_position", position)] {
        if let Some(s) = s {
            require_positive(name, s)?;
        }
    }
    Ok(())
}
