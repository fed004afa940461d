//! Fallible allocation of the big buffers: a `Vec` of `n` copies made with
//! `try_reserve_exact`, so that even a wrong estimate ([`crate::memory`]) ends in an
//! [`AllocError`], not an abort; and the byte counts and sizes its messages print.

use std::fmt;

/// A byte count printed in GiB, MiB or KiB.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bytes(pub u64);

impl fmt::Display for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.0 as f64;
        let (gib, mib) = ((1u64 << 30) as f64, (1u64 << 20) as f64);
        if b >= gib {
            write!(f, "{:.1} GiB", b / gib)
        } else if b >= mib {
            write!(f, "{:.1} MiB", b / mib)
        } else {
            write!(f, "{:.1} KiB", b / 1024.0)
        }
    }
}

/// Bytes of `n` values of `T`.
pub fn bytes_of<T>(n: u64) -> u64 {
    n.saturating_mul(std::mem::size_of::<T>() as u64)
}

/// A big buffer that could not be allocated.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AllocError {
    pub what: String,
    pub bytes: u64,
}

impl fmt::Display for AllocError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "out of memory: cannot allocate {} for {}", Bytes(self.bytes), self.what)
    }
}

impl std::error::Error for AllocError {}

/// `n` copies of `value`, allocated fallibly (`what` names the buffer in the error).
pub fn try_vec<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>, AllocError> {
    let mut v = Vec::new();
    try_resize(&mut v, n, value, what)?;
    Ok(v)
}

/// `v.resize(n, value)`, with the growth allocated fallibly.
pub fn try_resize<T: Clone>(v: &mut Vec<T>, n: usize, value: T, what: &str) -> Result<(), AllocError> {
    if n > v.len() {
        v.try_reserve_exact(n - v.len())
            .map_err(|_| AllocError { what: what.to_string(), bytes: bytes_of::<T>(n as u64) })?;
    }
    v.resize(n, value);
    Ok(())
}
