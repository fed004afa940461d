//! Shadow-ray accounting for the experiments' clocks (the thesis, 6.5: "time without ray
//! queries" and "number of rays"). Every shadow ray of the VPL renderer, in the cache
//! evaluation, the shading and the exhaustive sum, goes through [`occluded`] (or, for the
//! cache's rays from one record, [`occluded_fan`]): it counts
//! per thread and, while [`record_every`] is on, keeps every k-th ray so that an
//! experiment can replay them and time the ray queries alone. Images do not change.
//!
//! Counters are thread-local (an add, no shared cache line); [`pool_counts`] sums them
//! over the threads of the current rayon pool and the calling thread, so a caller that
//! wants its own frame's counts runs it in a pool of its own.

use filtrace_accel::{SceneAccel, SegmentFan};
use filtrace_core::Ray;
use std::cell::{Cell, RefCell};
use std::sync::atomic::{AtomicU64, Ordering};

thread_local! {
    static TRACED: Cell<u64> = const { Cell::new(0) };
    static KEPT: RefCell<Vec<Ray>> = const { RefCell::new(Vec::new()) };
}

/// Keep every k-th ray (0: keep none).
static KEEP_EVERY: AtomicU64 = AtomicU64::new(0);

/// `accel.occluded(ray)`, counted (and kept while recording).
#[inline]
pub fn occluded(accel: &SceneAccel, ray: &Ray) -> bool {
    count(ray);
    accel.occluded(ray)
}

/// `accel.occluded_fan(fan, active)`, each active lane counted (and kept while recording)
/// as one ray, as [`occluded`] counts it.
#[inline]
pub fn occluded_fan(accel: &SceneAccel, fan: &SegmentFan, active: u8) -> u8 {
    if KEEP_EVERY.load(Ordering::Relaxed) == 0 {
        // Not recording: one add for the fan (the lanes' rays were 38 instructions per
        // cache pair when built one by one just to be counted).
        TRACED.with(|c| c.set(c.get() + u64::from(active.count_ones())));
    } else {
        let mut bits = active;
        while bits != 0 {
            count(&fan.lane(bits.trailing_zeros() as usize));
            bits &= bits - 1;
        }
    }
    accel.occluded_fan(fan, active)
}

fn count(ray: &Ray) {
    let n = TRACED.with(|c| {
        let n = c.get();
        c.set(n + 1);
        n
    });
    let every = KEEP_EVERY.load(Ordering::Relaxed);
    if every != 0 && n.is_multiple_of(every) {
        KEPT.with(|k| k.borrow_mut().push(*ray));
    }
}

/// Keep every `k`-th shadow ray of each thread from now on (0 stops). Process-wide.
pub fn record_every(k: u64) {
    KEEP_EVERY.store(k, Ordering::Relaxed);
}

/// Shadow rays traced so far, summed over the current pool's threads and the caller
/// (when it is not one of them), and the rays kept since the last call (drained).
pub fn pool_counts() -> (u64, Vec<Ray>) {
    let drain = || (TRACED.with(Cell::get), KEPT.with(|k| std::mem::take(&mut *k.borrow_mut())));
    let mut per_thread = rayon::broadcast(|_| drain());
    if rayon::current_thread_index().is_none() {
        per_thread.push(drain());
    }
    let traced = per_thread.iter().map(|t| t.0).sum();
    (traced, per_thread.into_iter().flat_map(|t| t.1).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_keeps_every_kth_ray_of_a_pool() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let accel = SceneAccel::build(&scene);
        let ray = Ray::new(filtrace_core::Vec3::new(278.0, 273.0, -800.0), filtrace_core::Vec3::Z);
        pool.install(|| {
            let (before, _) = pool_counts();
            record_every(4);
            use rayon::prelude::*;
            (0..100).into_par_iter().for_each(|_| {
                occluded(&accel, &ray);
            });
            record_every(0);
            let (after, kept) = pool_counts();
            assert_eq!(after - before, 100);
            // Each thread keeps its 0th, 4th, ... ray: 25 or 26 of 100.
            assert!((25..=27).contains(&kept.len()), "{}", kept.len());
            assert!(kept.iter().all(|r| *r == ray));
            // A fan counts its active lanes, and answers as the single rays do.
            let mut fan = SegmentFan::new(ray.origin, 0.0);
            for i in 0..5 {
                fan.set_lane(i, filtrace_core::Vec3::new(0.01 * i as f32, 0.0, 1.0).normalize(), 2000.0);
            }
            let answer = occluded_fan(&accel, &fan, 0b10110);
            let (after_fan, _) = pool_counts();
            assert_eq!(after_fan - after, 3);
            for i in [1, 2, 4] {
                assert_eq!(answer & (1 << i) != 0, accel.occluded(&fan.lane(i)), "lane {i}");
            }
        });
    }
}
