//! The deterministic generator of the procedural scenes: the same seed gives the same
//! scene on every platform.

pub(crate) use filtrace_core::rng::SplitMix64;
