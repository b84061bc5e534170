//! A precise periodic timer for the WaitSet.
//!
//! iceoryx2's own interval attachments wait with `epoll_wait`, whose timeout is whole
//! milliseconds (rounded up): a 20 ms tick can come up to 1 ms late, which is half of the 2 ms
//! period the latency benchmark runs at. [`PeriodicTimer`] is a Linux `timerfd` on
//! CLOCK_MONOTONIC with absolute, nanosecond expiries (no drift, no rounding), attached to the
//! same WaitSet as a file descriptor, so the process still sleeps in one place and still ends
//! on SIGINT/SIGTERM through the WaitSet.

use iceoryx2_bb_posix::file_descriptor::{FileDescriptor, FileDescriptorBased};
use iceoryx2_bb_posix::file_descriptor_set::SynchronousMultiplexing;
use std::cell::Cell;
use std::time::Duration;

/// Why the timer could not be created.
#[derive(Debug, thiserror::Error)]
#[error("periodic timer: {what}: {source}")]
pub struct TimerError {
    what: &'static str,
    source: std::io::Error,
}

/// A periodic CLOCK_MONOTONIC timer (Linux `timerfd`), readable once per period.
#[derive(Debug)]
pub struct PeriodicTimer {
    fd: FileDescriptor,
    period_ns: u64,
    /// The next expiry not yet consumed, CLOCK_MONOTONIC ns ([`pcr_messages::monotonic_ns`]).
    next_ns: Cell<u64>,
}

/// One consumed tick of a [`PeriodicTimer`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tick {
    /// When this tick was due (its release time), CLOCK_MONOTONIC ns.
    pub release_ns: u64,
    /// Whole periods that expired unserved before this one (0 when on time).
    pub missed: u64,
}

impl PeriodicTimer {
    /// A timer expiring every `period`, first one period from now. Non-blocking.
    pub fn new(period: Duration) -> Result<Self, TimerError> {
        let err = |what| TimerError {
            what,
            source: std::io::Error::last_os_error(),
        };
        if period.is_zero() {
            return Err(TimerError {
                what: "period",
                source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "zero period"),
            });
        }
        // SAFETY: plain syscalls; the returned descriptor is owned by `FileDescriptor` below.
        let raw = unsafe {
            libc::timerfd_create(
                libc::CLOCK_MONOTONIC,
                libc::TFD_NONBLOCK | libc::TFD_CLOEXEC,
            )
        };
        if raw < 0 {
            return Err(err("timerfd_create"));
        }
        let fd = FileDescriptor::new(raw).ok_or_else(|| err("file descriptor"))?;
        let mut now = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `now` is a valid timespec to write to.
        unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut now) };
        let ts = |d: Duration| libc::timespec {
            tv_sec: d.as_secs() as libc::time_t,
            tv_nsec: d.subsec_nanos() as libc::c_long,
        };
        let first = Duration::new(now.tv_sec as u64, now.tv_nsec as u32) + period;
        let next_ns = first.as_nanos() as u64;
        let spec = libc::itimerspec {
            it_interval: ts(period),
            it_value: ts(first),
        };
        // SAFETY: `raw` is our open timerfd; `spec` is valid.
        let r = unsafe {
            libc::timerfd_settime(raw, libc::TFD_TIMER_ABSTIME, &spec, std::ptr::null_mut())
        };
        if r < 0 {
            return Err(err("timerfd_settime"));
        }
        Ok(Self {
            fd,
            period_ns: period.as_nanos() as u64,
            next_ns: Cell::new(next_ns),
        })
    }

    /// Consumes the expirations since the last call: `None` if none (spurious wake-up), else
    /// the newest due tick with its release time and how many periods before it went unserved.
    /// Must be called on every wake-up (the WaitSet is level-triggered).
    pub fn tick(&self) -> Option<Tick> {
        let n = self.expirations();
        if n == 0 {
            return None;
        }
        let next = self.next_ns.get();
        let release_ns = next + (n - 1) * self.period_ns;
        self.next_ns.set(next + n * self.period_ns);
        Some(Tick {
            release_ns,
            missed: n - 1,
        })
    }

    fn expirations(&self) -> u64 {
        let mut n: u64 = 0;
        // SAFETY: reads 8 bytes into `n` from our timerfd (non-blocking).
        let r = unsafe {
            libc::read(
                self.fd.native_handle(),
                (&mut n as *mut u64).cast(),
                std::mem::size_of::<u64>(),
            )
        };
        if r == std::mem::size_of::<u64>() as isize {
            n
        } else {
            0
        }
    }
}

impl FileDescriptorBased for PeriodicTimer {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.fd
    }
}

impl SynchronousMultiplexing for PeriodicTimer {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_once_per_period_at_the_release_times_and_counts_missed_periods() {
        let t = PeriodicTimer::new(Duration::from_millis(5)).unwrap();
        let created = pcr_messages::monotonic_ns();
        std::thread::sleep(Duration::from_millis(23));
        let tick = t.tick().unwrap();
        assert!(tick.missed >= 3, "{tick:?} after 23 ms at 5 ms");
        // the newest due release, on the 5 ms grid, in the past
        let now = pcr_messages::monotonic_ns();
        assert!(tick.release_ns <= now);
        assert!(tick.release_ns >= created + 5_000_000 * (tick.missed + 1) - 1_000_000);
        let slow = PeriodicTimer::new(Duration::from_secs(60)).unwrap();
        assert_eq!(slow.tick(), None, "not expired yet");
        assert!(PeriodicTimer::new(Duration::ZERO).is_err());
    }
}
