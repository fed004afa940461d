//! A small pool of large `f32` buffers reused between filter calls.
//!
//! Filters need scratch buffers of tens to hundreds of megabytes at 1080p (the guided
//! filter's per-window coefficients: 16 floats per pixel). Fresh allocations of that size
//! are fresh pages from the kernel: page faults and zeroing cost about a fifth of the guided
//! filter's time (perf, bench filters at 1080p). Reusing them removes that cost in
//! interactive use. The pool holds at most a few buffers; contents are unspecified.

use std::sync::Mutex;

static POOL: Mutex<Vec<Vec<f32>>> = Mutex::new(Vec::new());
/// Enough for every plane of one filter call (colour, guides, masks, output: about 20).
const MAX_BUFFERS: usize = 32;

/// A buffer of exactly `len` values (contents unspecified).
///
/// Only a pooled buffer of about the right size is reused: handing a large plane to a small
/// request (a band's column sums, a ring of weight rows) left the next large request to a
/// fresh allocation. A fresh buffer is `calloc`ed: its pages are zeroed when the parallel
/// pass that fills it first touches them, not by one thread up front (a serial 133 MB
/// memset for the guided filter's coefficients at 1080p).
pub(crate) fn take(len: usize) -> Vec<f32> {
    let pooled = {
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        let fits = |v: &Vec<f32>| v.capacity() >= len && v.capacity() - len <= len.max(SMALL);
        let best = (0..pool.len()).filter(|&i| fits(&pool[i])).min_by_key(|&i| pool[i].capacity());
        best.map(|i| pool.swap_remove(i))
    };
    match pooled {
        Some(mut v) => {
            v.resize(len, 0.0);
            v.truncate(len);
            v
        }
        None => vec![0.0; len],
    }
}

/// Slack below which any large-enough buffer fits a request (values: 1 MB).
const SMALL: usize = 1 << 18;

/// Returns a buffer to the pool.
pub(crate) fn give(v: Vec<f32>) {
    let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
    if pool.len() < MAX_BUFFERS {
        pool.push(v);
    } else if let Some(i) = (0..pool.len()).min_by_key(|&i| pool[i].capacity()) {
        if pool[i].capacity() < v.capacity() {
            pool[i] = v;
        }
    }
}

/// A pooled `Vec<f32>`: taken from the pool, given back on drop.
pub(crate) struct Buf(Vec<f32>);

impl Buf {
    /// `n` zeros.
    pub fn zeros(n: usize) -> Self {
        Self::filled(n, 0.0)
    }
    /// `n` copies of `v`.
    pub fn filled(n: usize, v: f32) -> Self {
        let mut b = take(n);
        b.fill(v);
        Self(b)
    }
    /// `n` values of unspecified content (to be overwritten).
    pub fn uninit(n: usize) -> Self {
        Self(take(n))
    }
}

impl std::ops::Deref for Buf {
    type Target = Vec<f32>;
    fn deref(&self) -> &Vec<f32> {
        &self.0
    }
}

impl std::ops::DerefMut for Buf {
    fn deref_mut(&mut self) -> &mut Vec<f32> {
        &mut self.0
    }
}

impl Clone for Buf {
    fn clone(&self) -> Self {
        let mut b = Self::uninit(self.0.len());
        b.copy_from_slice(&self.0);
        b
    }
}

impl Drop for Buf {
    fn drop(&mut self) {
        give(std::mem::take(&mut self.0));
    }
}
