//! Closing the loop with measured data (`pcr residuals`): the calibrated model's residual on
//! every measured row of a recording, the features that can explain it, a library of candidate
//! effects (one module each under [`effects`], behind [`effects::Effect`]), an attribution that
//! fits on training blocks and scores on held-out ones, and the extended robot file whose
//! effects the running system compensates.
//!
//! Like the calibration, this crate reads recordings and robot files only: it knows nothing of
//! the simulated plant whose effects its tests try to find.

mod acceptance;
pub mod alignment;
pub mod attribution;
pub mod backward;
pub mod consistency;
pub mod context;
pub mod effects;
pub mod extension;
pub mod features;
pub mod fitted;
pub mod interpolation;
pub mod linear;
pub mod model;
pub mod nuisance;
pub mod options;
mod plausibility;
pub mod progress;
pub mod recalibration;
pub mod refine;
pub mod report;
pub mod scoring;
pub mod series;

pub use attribution::{attribute, Attribution, Verdict};
pub use fitted::Estimate;
pub use options::Options;
pub use progress::{Progress, ProgressSink};
pub use series::{Blocks, Series};

/// `work` run on a thread of rayon's global pool, the calling thread waiting for it (at once
/// where it is one already). Every parallel section an analysis opens from a thread outside
/// the pool hands its work to the pool and sleeps until it is done, and the pool's threads
/// wake and sleep for it: thousands of times an analysis (each evaluation of a refinement,
/// each Jacobian of a calibration). From a thread of the pool, a parallel section starts where
/// the thread is (`BENCHMARKS.md`, "An analysis on a thread of the pool": 0.92-1.00 of the
/// wall on two cores, 0.93-0.99 on one).
pub fn on_the_pool<R: Send>(work: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| work())
}

#[cfg(test)]
mod tests {
    #[test]
    fn work_runs_on_a_thread_of_the_pool_and_answers() {
        // From a thread outside the pool: on one of the pool's.
        let outside = std::thread::spawn(|| {
            assert!(rayon::current_thread_index().is_none());
            super::on_the_pool(|| (rayon::current_thread_index(), 6 * 7))
        })
        .join()
        .unwrap();
        assert!(outside.0.is_some());
        assert_eq!(outside.1, 42);
        // From a thread of the pool: where it is.
        let (here, there) = rayon::scope(|_| {
            let here = rayon::current_thread_index();
            (here, super::on_the_pool(rayon::current_thread_index))
        });
        assert!(here.is_some());
        assert_eq!(here, there);
    }
}
