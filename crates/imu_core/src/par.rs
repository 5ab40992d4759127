//! Rayon's pool, or the calling thread when the pool has one.
//!
//! A call from outside the pool waits while the pool's workers run it. With one worker
//! (`RAYON_NUM_THREADS=1`, the setting that keeps rayon from competing with other pools on a small
//! machine) every call from every thread of the caller queues behind that worker, so a caller
//! that runs its own threads (Python's, the GIL released) gets no parallelism at all. There the
//! work runs on the caller's thread instead.

/// Whether to enter rayon's pool: it has more than one thread.
pub fn parallel() -> bool {
    rayon::current_num_threads() > 1
}
