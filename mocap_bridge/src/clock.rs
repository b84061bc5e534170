//! Time: the local CLOCK_MONOTONIC (the process chain's time base) and the mapping of QTM's
//! frame timestamps onto it.

/// CLOCK_MONOTONIC in nanoseconds (the same clock as the chain's latency stamps).
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the struct we pass; CLOCK_MONOTONIC always exists.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Frames of the sliding window of [`ClockSync`].
const WINDOW: usize = 128;

/// Maps QTM timestamps (microseconds since the capture started) onto the local clock: the
/// offset is the smallest `receive time - timestamp` over the last frames, i.e. the frame
/// that travelled fastest; each frame's local time is its timestamp plus that offset. Frames
/// that arrive together (one socket read) so keep their own capture times. A timestamp that
/// goes backwards (a new capture, a restarted server) resets the window.
#[derive(Debug, Clone)]
pub struct ClockSync {
    offsets: [i64; WINDOW],
    len: usize,
    head: usize,
    last_ts_us: Option<u64>,
}

impl Default for ClockSync {
    fn default() -> Self {
        Self::new()
    }
}

impl ClockSync {
    /// An empty window.
    pub fn new() -> Self {
        Self {
            offsets: [0; WINDOW],
            len: 0,
            head: 0,
            last_ts_us: None,
        }
    }

    /// Forgets every frame (new connection).
    pub fn reset(&mut self) {
        self.len = 0;
        self.head = 0;
        self.last_ts_us = None;
    }

    /// Adds a frame (QTM timestamp, local receive time ns) and returns its local time, ns.
    pub fn update(&mut self, ts_us: u64, rx_ns: u64) -> u64 {
        if self.last_ts_us.is_some_and(|l| ts_us < l) {
            self.reset();
        }
        self.last_ts_us = Some(ts_us);
        let ts_ns = ts_us.saturating_mul(1000) as i64;
        self.offsets[self.head] = rx_ns as i64 - ts_ns;
        self.head = (self.head + 1) % WINDOW;
        self.len = (self.len + 1).min(WINDOW);
        let off = self.offsets[..self.len].iter().copied().min().unwrap_or(0);
        (ts_ns + off).clamp(0, rx_ns as i64) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_received_together_keep_their_capture_times() {
        let mut c = ClockSync::new();
        let base = 5_000_000_000u64;
        // 100 Hz frames, two per 20 ms read: the first is 10 ms older than it looks
        let mut times = Vec::new();
        for k in 0..20u64 {
            let rx = base + (k / 2 + 1) * 20_000_000 + 50_000;
            times.push(c.update(k * 10_000 + 10_000, rx));
        }
        for w in times.windows(2).skip(4) {
            assert_eq!(w[1] - w[0], 10_000_000, "{times:?}");
        }
        // a restarted server (timestamps from zero again) starts over
        let t = c.update(0, base + 10_000_000_000);
        assert_eq!(t, base + 10_000_000_000);
    }
}
