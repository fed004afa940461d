//! The importance cache: records placed through the G-buffer, their distributions over
//! the VPLs, nearest-record search, and the samplers that draw VPLs from them.
