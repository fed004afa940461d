//! Tests of the importance cache.
