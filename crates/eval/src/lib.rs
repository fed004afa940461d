//! # filtrace-eval
//!
//! How good is an image? [`metrics`] compares a rendered or filtered image with a
//! reference: MSE, relative MSE, PSNR, SSIM and LDR-FLIP, plus per-pixel error maps.
//! Everything here sees only images, never a scene.

pub mod metrics;

// Experiments and their reports.
pub mod experiment;
pub mod figures;
pub mod oidn;
pub mod pfm;
pub mod plots;
pub mod report;
