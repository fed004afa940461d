//! Errors of the adaptive sampler. Bad input is reported, never a panic.

use std::fmt;

/// Everything that can go wrong when building an importance map, apportioning a
/// budget or scheduling batches.
#[derive(Clone, Debug, PartialEq)]
pub enum AdaptiveError {
    /// The normal and position layers differ in size.
    SizeMismatch { normal: (usize, usize), position: (usize, usize) },
    /// A layer has fewer channels than needed (normal and position need 3, importance 1).
    Channels { layer: &'static str, expected: usize, found: usize },
    /// A parameter is outside its documented range.
    InvalidParameter { name: &'static str, value: String, expected: &'static str },
    /// The image has no pixels; there is nothing to sample.
    EmptyImage,
    /// `budget < min_spp * pixels`: the minimum alone exceeds the budget.
    BudgetBelowMinimum { budget: u64, min_spp: u32, pixels: usize },
    /// An importance value is NaN, infinite or negative.
    InvalidImportance { pixel: usize, value: f32 },
    /// A pixel would get more samples than fit in `u32`, or the total overflows `u64`.
    Overflow,
}

impl fmt::Display for AdaptiveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::SizeMismatch { normal, position } => write!(
                f,
                "normal layer is {}x{} but position layer is {}x{}",
                normal.0, normal.1, position.0, position.1
            ),
            Self::Channels { layer, expected, found } => {
                write!(f, "{layer} layer needs {expected} channel(s), found {found}")
            }
            Self::InvalidParameter { name, value, expected } => {
                write!(f, "parameter {name} = {value} is invalid: expected {expected}")
            }
            Self::EmptyImage => write!(f, "the image has no pixels"),
            Self::BudgetBelowMinimum { budget, min_spp, pixels } => write!(
                f,
                "sample budget {budget} is below the minimum {min_spp} spp x {pixels} pixels = {}",
                *min_spp as u128 * *pixels as u128
            ),
            Self::InvalidImportance { pixel, value } => {
                write!(f, "importance of pixel {pixel} is {value}; importance must be finite and >= 0")
            }
            Self::Overflow => write!(f, "sample counts overflow (budget too large)"),
        }
    }
}

impl std::error::Error for AdaptiveError {}
