//! The chain's hot hops (planner -> IK, IK -> driver): how a downstream stage sleeps and wakes.
//!
//! The hop events use their own iceoryx2 service type, [`HopService`], whose event is a
//! semaphore in shared memory. Such a listener has no file descriptor and cannot join a WaitSet,
//! so the IK and the driver wait on their one hop listener itself ([`wait`]); their periodic work
//! (the driver's period tick, every stage's heartbeat) arrives as events on the same listener: a
//! [`Ticker`] thread of the process notifies its own listener with [`TICK`] and [`HEARTBEAT`] at
//! absolute CLOCK_MONOTONIC times, so the stage still sleeps in one place, and every step still
//! runs on the main thread ([`start`] sets both up). Why: BENCHMARKS.md, "The hop on a semaphore event and
//! the listener alone".
//!
//! SIGINT/SIGTERM: iceoryx2 installs its signal handler only when a WaitSet (or `Node::wait`)
//! first waits, so a process without one would simply die of SIGTERM (no hold command from the
//! driver, no statistics). [`catch_termination`] installs a handler that sets a flag, without
//! `SA_RESTART`, so the signal interrupts the wait and [`wait`] reports it as [`Wake::terminate`].
//! The ticker thread blocks every signal, so that they reach the main thread; should one land on
//! another thread, the ticker sees the request at its next release and wakes the main thread.

pub use crate::hop_service::{HopService, HEARTBEAT, MAX_EVENT_ID, SAMPLE, TICK};
use crate::ports::ChainNode;
use anyhow::{anyhow, Result};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::EventId;
use std::fmt::Debug;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// What woke the stage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Wake {
    /// A new sample from upstream.
    pub sample: bool,
    /// The period tick.
    pub tick: bool,
    /// The heartbeat time.
    pub heartbeat: bool,
    /// SIGINT/SIGTERM arrived: end the loop.
    pub terminate: bool,
}

impl Wake {
    fn note(&mut self, id: EventId) {
        if id == SAMPLE {
            self.sample = true;
        } else if id == TICK {
            self.tick = true;
        } else if id == HEARTBEAT {
            self.heartbeat = true;
        }
    }
}

/// Sleeps on the hop listener until something arrives, drains every pending event and says what
/// woke the stage. A signal that interrupts the wait without a termination request (SIGCONT
/// after SIGSTOP, SIGUSR1) is a wake-up with nothing set.
pub fn wait(listener: &Listener<HopService>) -> Result<Wake> {
    let mut w = Wake::default();
    match listener.blocking_wait(|a| w.note(a.id)) {
        Ok(_) => {}
        Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {}
        Err(e) => return Err(anyhow!("hop listener: {e:?}")),
    }
    w.terminate = termination_requested();
    Ok(w)
}

static TERMINATE: AtomicBool = AtomicBool::new(false);

extern "C" fn on_termination(_: libc::c_int) {
    TERMINATE.store(true, Ordering::SeqCst);
}

/// Catches SIGINT and SIGTERM for [`wait`]: call once at start-up, before the first wait (and
/// never use an iceoryx2 WaitSet in the same process: its signal handler would replace this
/// one).
pub fn catch_termination() -> Result<()> {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: sigaction with a handler that only stores to an atomic; no SA_RESTART.
        let r = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_termination as extern "C" fn(libc::c_int) as libc::sighandler_t;
            libc::sigemptyset(&mut sa.sa_mask);
            sa.sa_flags = 0;
            libc::sigaction(sig, &sa, std::ptr::null_mut())
        };
        if r != 0 {
            return Err(anyhow!(
                "cannot catch signal {sig}: {}",
                std::io::Error::last_os_error()
            ));
        }
    }
    Ok(())
}

/// True once SIGINT or SIGTERM arrived (after [`catch_termination`]).
pub fn termination_requested() -> bool {
    TERMINATE.load(Ordering::SeqCst)
}

/// Sets up a stage that sleeps on its hop listener of service `base`: catches SIGINT/SIGTERM
/// ([`catch_termination`]) and starts its [`Ticker`] (the period tick if `tick` is given, the
/// heartbeat of `c`). Call after the real-time settings (the ticker inherits them).
pub fn start(
    name: &str,
    c: &crate::CommonArgs,
    base: &'static str,
    tick: Option<Duration>,
) -> Result<Ticker> {
    catch_termination()?;
    Ticker::spawn(
        &format!("{name}-ticker-{}", std::process::id()),
        &c.prefix,
        c.protocol_version,
        base,
        tick,
        c.heartbeat(),
    )
}

/// Drains the hop listener without blocking and says what was pending.
pub fn poll(listener: &Listener<HopService>) -> Result<Wake> {
    let mut w = Wake::default();
    listener
        .try_wait(|a| w.note(a.id))
        .map_err(|e| anyhow!("hop listener: {e:?}"))?;
    w.terminate = termination_requested();
    Ok(w)
}

/// A thread that notifies a process's own hop listener with [`TICK`] every `tick` (if any) and
/// [`HEARTBEAT`] every `heartbeat`, at absolute CLOCK_MONOTONIC times (no drift). Stops and
/// joins when dropped (within one of its periods).
#[derive(Debug)]
pub struct Ticker {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Ticker {
    /// Starts the thread; it opens its own iceoryx2 node (`name`) under `prefix` and a notifier
    /// on the hop service `base`. Call after the real-time settings: the thread inherits the
    /// process's scheduling class, priority and CPU.
    pub fn spawn(
        name: &str,
        prefix: &str,
        version: u32,
        base: &'static str,
        tick: Option<Duration>,
        heartbeat: Duration,
    ) -> Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
        let (name, prefix, s) = (name.to_string(), prefix.to_string(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("ticker".into())
            .spawn(move || {
                block_all_signals();
                let notifier = ChainNode::new(&name, &prefix, version)
                    .and_then(|cn| Ok((cn.hop_notifier(base)?, cn)));
                let (notifier, _cn) = match notifier {
                    Ok(n) => {
                        let _ = ready_tx.send(Ok(()));
                        n
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(format!("{e:#}")));
                        return;
                    }
                };
                run_ticker(&notifier, &s, tick, heartbeat);
            })
            .map_err(|e| anyhow!("ticker thread: {e}"))?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Self {
                stop,
                thread: Some(thread),
            }),
            Ok(Err(e)) => Err(anyhow!("ticker: {e}")),
            Err(_) => Err(anyhow!("ticker thread ended before it was ready")),
        }
    }
}

impl Drop for Ticker {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn block_all_signals() {
    // SAFETY: sigset_t is plain data; pthread_sigmask only affects this thread.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigfillset(&mut set);
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
    }
}

fn sleep_until_ns(t_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (t_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (t_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: plain syscall; EINTR cannot happen (every signal is blocked here), and an early
    // return is harmless (the caller checks the time).
    unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        )
    };
}

fn run_ticker(
    notifier: &Notifier<HopService>,
    stop: &AtomicBool,
    tick: Option<Duration>,
    heartbeat: Duration,
) {
    let now = pcr_messages::monotonic_ns();
    let tick_ns = tick.map(|t| (t.as_nanos() as u64).max(1));
    let hb_ns = (heartbeat.as_nanos() as u64).max(1);
    let mut next_tick = tick_ns.map(|p| now + p);
    let mut next_hb = now + hb_ns;
    while !stop.load(Ordering::Relaxed) {
        let due = next_tick.map_or(next_hb, |t| t.min(next_hb));
        sleep_until_ns(due);
        let now = pcr_messages::monotonic_ns();
        if stop.load(Ordering::Relaxed) {
            break;
        }
        if termination_requested() {
            // The signal reached another thread: wake the main thread to see it.
            let _ = notifier.notify_with_custom_event_id(HEARTBEAT);
        }
        if let (Some(t), Some(p)) = (next_tick.as_mut(), tick_ns) {
            if now >= *t {
                let _ = notifier.notify_with_custom_event_id(TICK);
                // The next release after now (missed releases are not replayed).
                *t += p * ((now - *t) / p + 1);
            }
        }
        if now >= next_hb {
            let _ = notifier.notify_with_custom_event_id(HEARTBEAT);
            next_hb += hb_ns * ((now - next_hb) / hb_ns + 1);
        }
    }
}
