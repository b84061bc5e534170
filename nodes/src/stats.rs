//! Cycle statistics (HDR histograms of cycle time and wake-up latency after the release, deadline misses) and the
//! heartbeat that reports them.

use hdrhistogram::Histogram;
use pcr_messages::{Heartbeat, NodeKind};

/// Per-process cycle statistics. Recording does not allocate.
#[derive(Debug)]
pub struct CycleStats {
    kind: NodeKind,
    version: u32,
    period_ns: u64,
    cycle: Histogram<u64>,
    jitter: Histogram<u64>,
    cycles: u64,
    misses: u64,
    stale: u64,
    hb_seq: u64,
}

fn hist() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("static histogram bounds")
}

impl CycleStats {
    /// Statistics for a process of `kind` with a `period_ns` deadline.
    pub fn new(kind: NodeKind, version: u32, period_ns: u64) -> Self {
        Self {
            kind,
            version,
            period_ns,
            cycle: hist(),
            jitter: hist(),
            cycles: 0,
            misses: 0,
            stale: 0,
            hb_seq: 0,
        }
    }

    /// Records one cycle: its work time and its wake-up latency (ns): how late the process
    /// woke after the cycle's release (its timer tick, or the upstream publication that woke
    /// it). A cycle misses its deadline when it finishes more than a period after its release
    /// (the implicit deadline of a periodic task: latency + work > period).
    pub fn record(&mut self, work_ns: u64, latency_ns: u64) {
        self.cycles += 1;
        self.cycle.saturating_record(work_ns.max(1));
        self.jitter.saturating_record(latency_ns.max(1));
        if work_ns + latency_ns > self.period_ns {
            self.misses += 1;
        }
    }

    /// Counts periods that expired without being served (each is a deadline miss).
    pub fn missed_periods(&mut self, n: u64) {
        self.misses += n;
    }

    /// Counts a cycle with stale or missing input.
    pub fn stale_input(&mut self) {
        self.stale += 1;
    }

    /// Deadline misses so far.
    pub fn misses(&self) -> u64 {
        self.misses
    }

    /// Cycles so far.
    pub fn cycles(&self) -> u64 {
        self.cycles
    }

    fn pct(h: &Histogram<u64>) -> [u64; 3] {
        if h.is_empty() {
            return [0; 3];
        }
        [h.value_at_quantile(0.5), h.value_at_quantile(0.99), h.max()]
    }

    /// The heartbeat message reporting the statistics.
    pub fn heartbeat(&mut self, holding: bool) -> Heartbeat {
        self.hb_seq += 1;
        Heartbeat {
            version: self.version,
            kind: self.kind as u32,
            pid: std::process::id(),
            holding: u32::from(holding),
            seq: self.hb_seq,
            cycles: self.cycles,
            deadline_misses: self.misses,
            stale_inputs: self.stale,
            cycle_ns: Self::pct(&self.cycle),
            jitter_ns: Self::pct(&self.jitter),
        }
    }

    /// A one-line summary for the log at exit.
    pub fn summary(&self) -> String {
        let c = Self::pct(&self.cycle);
        let j = Self::pct(&self.jitter);
        format!(
            "{}: {} cycles, {} deadline misses, {} stale inputs; cycle p50/p99/max {:.1}/{:.1}/{:.1} us; \
             wake-up latency p50/p99/max {:.1}/{:.1}/{:.1} us",
            self.kind.name(),
            self.cycles,
            self.misses,
            self.stale,
            c[0] as f64 / 1e3,
            c[1] as f64 / 1e3,
            c[2] as f64 / 1e3,
            j[0] as f64 / 1e3,
            j[1] as f64 / 1e3,
            j[2] as f64 / 1e3
        )
    }
}
