//! Time alignment of motion-capture samples with the recording's rows.
//!
//! A capture system reports each sample some time after it measured it (its latency: exposure,
//! marker reconstruction, transport). A row of the recording stamped t compares the pose the
//! planner asked for at t with "the pose measured at the same time"
//! (`../shared/spec/calibration.md`): the sample *measured* at t, which arrives only at
//! t + latency. [`CaptureAligner`] holds the rows until that sample has arrived and gives each
//! row the sample measured nearest to its time (within half a capture tolerance), with the
//! capture system's declared latency subtracted from the time a sample was reported.
//!
//! The latency is a declared property of the measuring system (the lab measures it once, e.g.
//! with QTM's own latency measurement, and writes it in the `[capture]` section); it is not
//! fitted here. Whatever the declaration misses remains in the recording as a lag of the
//! measurement behind the command, which `pcr residuals` finds as `latency`. Without a
//! declaration the recorders keep the causal rule (a row holds the latest sample reported by its
//! time).

use std::collections::VecDeque;

/// One capture sample: the time it was measured and what it saw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlignedSample<T> {
    /// Time of the measurement (reported time minus the declared latency), s.
    pub t_s: f64,
    /// What it measured.
    pub value: T,
}

/// Holds rows until the capture samples measured at their time have been reported, then pairs
/// each row with the nearest sample by measurement time.
#[derive(Debug, Clone)]
pub struct CaptureAligner<R, T> {
    latency_s: f64,
    tolerance_s: f64,
    rows: VecDeque<(f64, R)>,
    samples: VecDeque<AlignedSample<T>>,
}

impl<R, T: Clone> CaptureAligner<R, T> {
    /// `latency_s`: the capture system's declared latency (>= 0); `tolerance_s`: the largest
    /// distance in time between a row and the sample it takes (half the capture period is the
    /// natural choice).
    pub fn new(latency_s: f64, tolerance_s: f64) -> Self {
        Self {
            latency_s: latency_s.max(0.0),
            tolerance_s: tolerance_s.max(0.0),
            rows: VecDeque::new(),
            samples: VecDeque::new(),
        }
    }

    /// The declared latency, s.
    pub fn latency_s(&self) -> f64 {
        self.latency_s
    }

    /// How long a row waits for its sample, s.
    pub fn delay_s(&self) -> f64 {
        self.latency_s + self.tolerance_s
    }

    /// A sample reported at `reported_s`.
    pub fn push_sample(&mut self, reported_s: f64, value: T) {
        self.samples.push_back(AlignedSample {
            t_s: reported_s - self.latency_s,
            value,
        });
    }

    /// A row stamped `t_s` (rows in time order).
    pub fn push_row(&mut self, t_s: f64, row: R) {
        self.rows.push_back((t_s, row));
    }

    /// Rows waiting.
    pub fn waiting(&self) -> usize {
        self.rows.len()
    }

    /// The rows whose samples have all been reported by `now_s` (every sample measured within
    /// the tolerance of the row's time), each with the samples measured within the tolerance,
    /// nearest first. `pick` chooses from those candidates (e.g. the nearest one that saw the
    /// platform).
    pub fn ready(&mut self, now_s: f64) -> Vec<(f64, R, Vec<AlignedSample<T>>)> {
        let mut out = Vec::new();
        while self
            .rows
            .front()
            .is_some_and(|(t, _)| *t + self.delay_s() <= now_s + 1e-9)
        {
            let Some((t, row)) = self.rows.pop_front() else {
                break;
            };
            out.push((t, row, self.candidates(t)));
            self.prune(t);
        }
        out
    }

    /// Every waiting row with what has arrived (end of a recording).
    pub fn flush(&mut self) -> Vec<(f64, R, Vec<AlignedSample<T>>)> {
        let mut out = Vec::new();
        while let Some((t, row)) = self.rows.pop_front() {
            out.push((t, row, self.candidates(t)));
        }
        self.samples.clear();
        out
    }

    fn candidates(&self, t: f64) -> Vec<AlignedSample<T>> {
        let mut c: Vec<AlignedSample<T>> = self
            .samples
            .iter()
            .filter(|s| (s.t_s - t).abs() <= self.tolerance_s + 1e-9)
            .cloned()
            .collect();
        // Nearest first; of two equally near, the earlier (a causal tie-break).
        c.sort_by(|a, b| {
            let da = (a.t_s - t).abs();
            let db = (b.t_s - t).abs();
            da.total_cmp(&db).then(a.t_s.total_cmp(&b.t_s))
        });
        c
    }

    /// Drops samples no later row can take (rows come in time order, so every later row is
    /// after `released_s`).
    fn prune(&mut self, released_s: f64) {
        while self
            .samples
            .front()
            .is_some_and(|s| s.t_s < released_s - self.tolerance_s - 1e-9)
        {
            self.samples.pop_front();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_takes_the_sample_measured_at_its_time() {
        // Capture at 100 Hz with 10 ms latency; rows every 20 ms.
        let mut a: CaptureAligner<u32, f64> = CaptureAligner::new(0.010, 0.005);
        let mut got = Vec::new();
        for k in 0..10u32 {
            let now = k as f64 * 0.02;
            // Samples measured at now - 10 ms and now - 20 ms are reported by now.
            for j in [2 * k as i64 - 1, 2 * k as i64] {
                if j >= 0 {
                    let measured = j as f64 * 0.01 - 0.01;
                    a.push_sample(measured + 0.010, measured);
                }
            }
            a.push_row(now, k);
            got.extend(a.ready(now));
        }
        got.extend(a.flush());
        assert_eq!(got.len(), 10);
        for (t, k, c) in &got[..got.len() - 1] {
            assert_eq!(*t, *k as f64 * 0.02);
            let best = c.first().expect("a sample near every row but the last");
            assert!(
                (best.value - t).abs() < 1e-12,
                "row {t}: sample {}",
                best.value
            );
        }
    }

    #[test]
    fn rows_wait_for_the_latency_and_the_tolerance() {
        let mut a: CaptureAligner<(), f64> = CaptureAligner::new(0.030, 0.005);
        a.push_row(0.0, ());
        assert!(a.ready(0.02).is_empty());
        assert!(a.ready(0.034).is_empty());
        assert_eq!(a.ready(0.035).len(), 1);
    }

    #[test]
    fn a_missing_sample_leaves_the_row_unmeasured() {
        let mut a: CaptureAligner<(), f64> = CaptureAligner::new(0.0, 0.005);
        a.push_sample(0.0, 1.0);
        a.push_row(0.0, ());
        a.push_row(0.02, ());
        a.push_sample(0.04, 3.0);
        let r = a.ready(0.05);
        assert_eq!(r.len(), 2);
        assert_eq!(r[0].2.len(), 1);
        assert!(r[1].2.is_empty(), "no sample within 5 ms of 0.02 s");
    }
}
