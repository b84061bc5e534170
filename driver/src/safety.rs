//! Safety limits as decorators around any [`Driver`] (openrr-arci style): each wrapper is itself
//! a `Driver`, so they stack, e.g.
//! `Watchdog::new(PositionLimit::new(RateLimit::new(serial, 600.0), lo, hi), 0.1)`.
//!
//! Order matters for [`RateLimit`]: it measures each change from the last command *it* passed
//! on, so nothing that modifies commands (such as [`PositionLimit`]) may sit between it and the
//! drive; put it innermost.
//!
//! * [`PositionLimit`] clamps each motor's target into `[min, max]` steps.
//! * [`RateLimit`] clamps each motor's change per cycle to `max_rate * period` steps, measured
//!   from the last command it passed on (seeded from the drive's reported position).
//! * [`Watchdog`] (stale setpoint): when the caller stops writing for longer than a timeout, it
//!   commands the drive to hold where it is and latches a fault until [`Watchdog::reset`].
//!
//! Every intervention is counted, logged through `tracing` and reported as
//! [`DriverState::limited`] (or [`DriverState::fault`] for the watchdog).

use crate::interface::{Driver, DriverError, DriverState, MotorCommand, N_MOTORS};

/// Counters shared by the wrappers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SafetyCounters {
    /// Commands passed on.
    pub commands: u64,
    /// Commands modified (clamped) or refused.
    pub interventions: u64,
}

/// Clamps targets into a position range.
#[derive(Debug)]
pub struct PositionLimit<D> {
    inner: D,
    min: [i32; N_MOTORS],
    max: [i32; N_MOTORS],
    limited: bool,
    counters: SafetyCounters,
}

impl<D: Driver> PositionLimit<D> {
    /// Wraps `inner` with per-motor bounds (inclusive).
    pub fn new(inner: D, min: [i32; N_MOTORS], max: [i32; N_MOTORS]) -> Self {
        assert!(min.iter().zip(&max).all(|(a, b)| a <= b), "min > max");
        Self {
            inner,
            min,
            max,
            limited: false,
            counters: SafetyCounters::default(),
        }
    }
    /// The wrapped driver.
    pub fn inner(&self) -> &D {
        &self.inner
    }
    /// The wrapped driver, mutable.
    pub fn inner_mut(&mut self) -> &mut D {
        &mut self.inner
    }
    /// Unwraps.
    pub fn into_inner(self) -> D {
        self.inner
    }
    /// Counters.
    pub fn counters(&self) -> SafetyCounters {
        self.counters
    }
}

impl<D: Driver> Driver for PositionLimit<D> {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn diagnostics(&self) -> Vec<(String, u64)> {
        let mut v = self.inner.diagnostics();
        v.push(("position_limit.commands".into(), self.counters.commands));
        v.push((
            "position_limit.interventions".into(),
            self.counters.interventions,
        ));
        v
    }
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        let mut c = *cmd;
        self.limited = false;
        for i in 0..N_MOTORS {
            let v = c.steps[i].clamp(self.min[i], self.max[i]);
            if v != c.steps[i] {
                tracing::warn!(
                    driver = self.inner.name(),
                    motor = i,
                    requested = c.steps[i],
                    clamped = v,
                    "position limit"
                );
                c.steps[i] = v;
                self.limited = true;
            }
        }
        self.counters.commands += 1;
        if self.limited {
            self.counters.interventions += 1;
        }
        self.inner.write(time_s, period_s, &c)
    }
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        let mut s = self.inner.read(time_s, period_s)?;
        s.limited |= self.limited;
        Ok(s)
    }
}

/// Clamps the per-cycle change of each target to `max_rate * period_s` steps.
#[derive(Debug)]
pub struct RateLimit<D> {
    inner: D,
    max_rate: f64,
    last: Option<[i32; N_MOTORS]>,
    limited: bool,
    counters: SafetyCounters,
}

impl<D: Driver> RateLimit<D> {
    /// Wraps `inner`; `max_rate` in steps/s (the firmware's default is 600).
    pub fn new(inner: D, max_rate: f64) -> Self {
        assert!(max_rate > 0.0, "max_rate must be positive");
        Self {
            inner,
            max_rate,
            last: None,
            limited: false,
            counters: SafetyCounters::default(),
        }
    }
    /// The wrapped driver.
    pub fn inner(&self) -> &D {
        &self.inner
    }
    /// The wrapped driver, mutable.
    pub fn inner_mut(&mut self) -> &mut D {
        &mut self.inner
    }
    /// Unwraps.
    pub fn into_inner(self) -> D {
        self.inner
    }
    /// Counters.
    pub fn counters(&self) -> SafetyCounters {
        self.counters
    }
    /// Forgets the reference position (re-seeded from the next read), e.g. after zeroing.
    pub fn resync(&mut self) {
        self.last = None;
    }
}

impl<D: Driver> Driver for RateLimit<D> {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn diagnostics(&self) -> Vec<(String, u64)> {
        let mut v = self.inner.diagnostics();
        v.push(("rate_limit.commands".into(), self.counters.commands));
        v.push((
            "rate_limit.interventions".into(),
            self.counters.interventions,
        ));
        v
    }
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        let reference = match self.last {
            Some(r) => r,
            None => self.inner.read(time_s, period_s)?.steps,
        };
        // Floor: never more than the rate allows, whatever the rounding.
        let max_step = (self.max_rate * period_s.max(0.0)).floor() as i64;
        let mut c = *cmd;
        self.limited = false;
        for (i, &r) in reference.iter().enumerate() {
            let r = i64::from(r);
            let want = i64::from(c.steps[i]);
            let v = want.clamp(r - max_step, r + max_step);
            if v != want {
                tracing::warn!(
                    driver = self.inner.name(),
                    motor = i,
                    requested = c.steps[i],
                    clamped = v,
                    "rate limit"
                );
                c.steps[i] = v as i32;
                self.limited = true;
            }
        }
        self.counters.commands += 1;
        if self.limited {
            self.counters.interventions += 1;
        }
        self.inner.write(time_s, period_s, &c)?;
        self.last = Some(c.steps);
        Ok(())
    }
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        let mut s = self.inner.read(time_s, period_s)?;
        if !s.enabled || s.fault {
            // The drive is not following: restart from where it is.
            self.last = Some(s.steps);
        }
        s.limited |= self.limited;
        Ok(s)
    }
}

/// Stale-setpoint watchdog: holds the drive and latches a fault when writes stop.
#[derive(Debug)]
pub struct Watchdog<D> {
    inner: D,
    timeout_s: f64,
    last_write: Option<f64>,
    last_state: Option<DriverState>,
    tripped: bool,
    counters: SafetyCounters,
}

impl<D: Driver> Watchdog<D> {
    /// Wraps `inner`; trips when more than `timeout_s` (caller's clock) passes between writes.
    pub fn new(inner: D, timeout_s: f64) -> Self {
        assert!(timeout_s > 0.0, "timeout must be positive");
        Self {
            inner,
            timeout_s,
            last_write: None,
            last_state: None,
            tripped: false,
            counters: SafetyCounters::default(),
        }
    }
    /// The wrapped driver.
    pub fn inner(&self) -> &D {
        &self.inner
    }
    /// The wrapped driver, mutable.
    pub fn inner_mut(&mut self) -> &mut D {
        &mut self.inner
    }
    /// Unwraps.
    pub fn into_inner(self) -> D {
        self.inner
    }
    /// Counters (interventions = trips and refused writes).
    pub fn counters(&self) -> SafetyCounters {
        self.counters
    }
    /// Whether the watchdog has tripped.
    pub fn tripped(&self) -> bool {
        self.tripped
    }
    /// Re-arms after a trip; the next write starts a new stream.
    pub fn reset(&mut self) {
        self.tripped = false;
        self.last_write = None;
    }

    fn check(&mut self, time_s: f64) -> bool {
        if let Some(t) = self.last_write {
            if !self.tripped && time_s - t > self.timeout_s {
                self.tripped = true;
                self.counters.interventions += 1;
                tracing::error!(
                    driver = self.inner.name(),
                    silent_s = time_s - t,
                    "stale setpoint: watchdog tripped, holding position"
                );
            }
        }
        self.tripped
    }

    fn hold(&mut self, time_s: f64, period_s: f64, enable: bool) -> Result<(), DriverError> {
        let steps = match self.last_state {
            Some(s) => s.steps,
            None => self.inner.read(time_s, period_s)?.steps,
        };
        self.inner
            .write(time_s, period_s, &MotorCommand { steps, enable })
    }
}

impl<D: Driver> Driver for Watchdog<D> {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn diagnostics(&self) -> Vec<(String, u64)> {
        let mut v = self.inner.diagnostics();
        v.push(("watchdog.commands".into(), self.counters.commands));
        v.push(("watchdog.interventions".into(), self.counters.interventions));
        v
    }
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        if self.check(time_s) {
            self.counters.interventions += 1;
            self.hold(time_s, period_s, cmd.enable)?;
            return Err(DriverError::Limit(
                "watchdog tripped (stale setpoint): holding; call reset()".into(),
            ));
        }
        self.counters.commands += 1;
        self.last_write = Some(time_s);
        self.inner.write(time_s, period_s, cmd)
    }
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        let was = self.tripped;
        if self.check(time_s) && !was {
            // The caller went silent: stop the drive where it is.
            let enable = self.last_state.map(|s| s.enabled).unwrap_or(true);
            self.hold(time_s, period_s, enable)?;
        }
        let mut s = self.inner.read(time_s, period_s)?;
        self.last_state = Some(s);
        s.fault |= self.tripped;
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records what reaches the drive; moves instantly.
    #[derive(Default)]
    struct Fake {
        writes: Vec<MotorCommand>,
        pos: [i32; N_MOTORS],
        enabled: bool,
    }
    impl Driver for Fake {
        fn name(&self) -> &str {
            "fake"
        }
        fn write(&mut self, _: f64, _: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
            self.writes.push(*cmd);
            self.pos = cmd.steps;
            self.enabled = cmd.enable;
            Ok(())
        }
        fn read(&mut self, t: f64, _: f64) -> Result<DriverState, DriverError> {
            Ok(DriverState {
                time_s: t,
                steps: self.pos,
                enabled: self.enabled,
                ..Default::default()
            })
        }
    }

    fn cmd(steps: [i32; 3]) -> MotorCommand {
        MotorCommand {
            steps,
            enable: true,
        }
    }

    #[test]
    fn position_limit_clamps_and_reports() {
        let mut d = PositionLimit::new(Fake::default(), [-100; 3], [100, 50, 100]);
        d.write(0.0, 0.02, &cmd([150, 60, -7])).unwrap();
        assert_eq!(d.inner().writes[0].steps, [100, 50, -7]);
        assert!(d.read(0.0, 0.02).unwrap().limited);
        d.write(0.02, 0.02, &cmd([1, 2, 3])).unwrap();
        assert!(!d.read(0.02, 0.02).unwrap().limited);
        assert_eq!(
            d.counters(),
            SafetyCounters {
                commands: 2,
                interventions: 1
            }
        );
    }

    #[test]
    fn rate_limit_clamps_from_the_measured_position() {
        let fake = Fake {
            pos: [1000, 0, 0],
            ..Default::default()
        };
        let mut d = RateLimit::new(fake, 600.0);
        // 600 steps/s * 20 ms = 12 steps per cycle, from the drive's reported position.
        d.write(0.0, 0.02, &cmd([0, 5, -50])).unwrap();
        assert_eq!(d.inner().writes[0].steps, [988, 5, -12]);
        assert!(d.read(0.0, 0.02).unwrap().limited);
        d.write(0.02, 0.02, &cmd([0, 5, -50])).unwrap();
        assert_eq!(d.inner().writes[1].steps, [976, 5, -24]);
        // Exactly at the limit is not limited.
        d.write(0.04, 0.02, &cmd([964, 17, -36])).unwrap();
        assert!(!d.read(0.04, 0.02).unwrap().limited);
        // Extreme values do not overflow.
        d.write(0.06, 0.02, &cmd([i32::MIN, i32::MAX, 0])).unwrap();
        assert_eq!(d.inner().writes[3].steps, [952, 29, -24]);
    }

    #[test]
    fn watchdog_holds_on_stale_setpoints() {
        let mut d = Watchdog::new(Fake::default(), 0.1);
        for k in 0..5 {
            let t = k as f64 * 0.02;
            d.write(t, 0.02, &cmd([k, k, k])).unwrap();
            assert!(!d.read(t, 0.02).unwrap().fault);
        }
        // The caller stalls for 0.2 s, then reads: the watchdog holds the drive.
        let s = d.read(0.3, 0.02).unwrap();
        assert!(s.fault);
        assert!(d.tripped());
        assert_eq!(d.inner().writes.last().unwrap().steps, [4, 4, 4]);
        // Further writes are refused (and keep holding) until reset.
        let e = d.write(0.32, 0.02, &cmd([50, 50, 50])).unwrap_err();
        assert!(matches!(e, DriverError::Limit(_)));
        assert_eq!(d.inner().writes.last().unwrap().steps, [4, 4, 4]);
        d.reset();
        d.write(0.34, 0.02, &cmd([5, 5, 5])).unwrap();
        assert!(!d.read(0.34, 0.02).unwrap().fault);
    }

    #[test]
    fn watchdog_trips_on_a_late_write() {
        let mut d = Watchdog::new(Fake::default(), 0.1);
        d.write(0.0, 0.02, &cmd([1, 1, 1])).unwrap();
        d.read(0.0, 0.02).unwrap();
        assert!(d.write(0.5, 0.02, &cmd([9, 9, 9])).is_err());
        assert_eq!(d.inner().writes.last().unwrap().steps, [1, 1, 1]);
        assert_eq!(d.counters().interventions, 2);
    }

    #[test]
    fn clamped_then_returning_command_moves_back() {
        let inner = RateLimit::new(Fake::default(), 600.0);
        let mut d = PositionLimit::new(inner, [-20; 3], [20; 3]);
        for k in 0..10 {
            let t = k as f64 * 0.02;
            d.write(t, 0.02, &cmd([1000, 0, 0])).unwrap();
            d.read(t, 0.02).unwrap();
        }
        d.write(0.2, 0.02, &cmd([0, 0, 0])).unwrap();
        assert_eq!(d.inner().inner().writes.last().unwrap().steps, [8, 0, 0]);
    }

    #[test]
    fn wrappers_stack() {
        let inner = RateLimit::new(Fake::default(), 600.0);
        let mut d = Watchdog::new(PositionLimit::new(inner, [-20; 3], [20; 3]), 0.1);
        for k in 0..10 {
            let t = k as f64 * 0.02;
            d.write(t, 0.02, &cmd([1000, -1000, 3])).unwrap();
            d.read(t, 0.02).unwrap();
        }
        let f = &d.inner().inner().inner().writes;
        assert_eq!(f[0].steps, [12, -12, 3]);
        assert_eq!(f.last().unwrap().steps, [20, -20, 3]);
        assert_eq!(d.name(), "fake");
        let diag = d.diagnostics();
        let get = |k: &str| diag.iter().find(|(n, _)| n == k).unwrap().1;
        assert_eq!(get("position_limit.interventions"), 10);
        assert_eq!(get("rate_limit.interventions"), 1);
        assert_eq!(get("watchdog.commands"), 10);
        assert_eq!(get("watchdog.interventions"), 0);
    }
}
