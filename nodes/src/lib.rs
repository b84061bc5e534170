//! Shared plumbing of the chain's process binaries (`src/bin/`): command-line options, the
//! iceoryx2 node and ports (service settings in one place), the protocol-version handshake, cycle
//! statistics with heartbeats, and real-time settings.
//!
//! Each binary wraps one step of `pcr-control` and sleeps until there is work, never
//! busy-spinning: the IK and the driver on their hop listener ([`hop`]), the others on an
//! iceoryx2 WaitSet (events or a periodic timer); SIGINT/SIGTERM end the loop and the process
//! exits cleanly, releasing its shared memory.

pub mod args;
pub mod cycle;
pub mod hop;
pub mod hop_service;
pub mod ports;
pub mod protocol;
pub mod realtime;
pub mod stats;
pub mod timer;

pub use args::CommonArgs;
pub use ports::{iox_config, publish, ChainNode};
pub use protocol::ProtocolGuard;
pub use stats::CycleStats;
pub use timer::{PeriodicTimer, Tick};

/// Exit code of a process that refused to connect because of a protocol version mismatch.
pub const EXIT_VERSION_MISMATCH: i32 = 3;

/// Sets up `tracing` to stderr (level from `RUST_LOG`, default info).
pub fn init_logging() {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .try_init();
}

/// Chain time in seconds: CLOCK_MONOTONIC, the same in every process.
pub fn chain_time_s() -> f64 {
    pcr_messages::monotonic_ns() as f64 * 1e-9
}

/// Common start-up of a chain process: node, protocol handshake (exits with
/// [`EXIT_VERSION_MISMATCH`] and a clear message when a peer speaks another version).
pub fn startup(
    kind: pcr_messages::NodeKind,
    args: &CommonArgs,
) -> anyhow::Result<(ChainNode, ProtocolGuard)> {
    let name = format!("pcr-{}-{}", kind.name(), std::process::id());
    let node = ChainNode::new(&name, &args.prefix, args.protocol_version)?;
    let guard = ProtocolGuard::new(&node, kind)?;
    if let Err(m) = guard.handshake(std::time::Duration::from_millis(args.handshake_ms)) {
        // One write, so that concurrent processes' lines do not interleave.
        let line = format!("pcr-{}: error: {}\n", kind.name(), m.message);
        let _ = std::io::Write::write_all(&mut std::io::stderr(), line.as_bytes());
        std::process::exit(EXIT_VERSION_MISMATCH);
    }
    tracing::info!(
        kind = kind.name(),
        version = args.protocol_version,
        prefix = %args.prefix,
        "connected"
    );
    Ok((node, guard))
}

/// Heartbeat-time protocol check of a running process: a peer of another version is logged
/// (the peer itself refuses to start).
pub fn recheck(guard: &ProtocolGuard) {
    guard.announce();
    if let Err(m) = guard.check() {
        tracing::error!(peer_pid = m.peer.pid, "ignoring peer: {}", m.message);
    }
}

/// Prints why the WaitSet loop ended.
pub fn log_end(kind: pcr_messages::NodeKind, r: iceoryx2::waitset::WaitSetRunResult) {
    use iceoryx2::waitset::WaitSetRunResult as R;
    match r {
        R::Interrupt | R::TerminationRequest => {
            tracing::info!(kind = kind.name(), reason = ?r, "terminating cleanly")
        }
        R::StopRequest | R::AllEventsHandled => {
            tracing::info!(kind = kind.name(), reason = ?r, "loop ended")
        }
    }
}

/// Runs a WaitSet loop until the callback stops it or SIGINT/SIGTERM arrives.
///
/// iceoryx2 reports any EINTR of its wait as [`WaitSetRunResult::Interrupt`], including the one
/// Linux raises when a stopped process is continued (SIGSTOP then SIGCONT): that must not end the
/// process. A real SIGINT/SIGTERM is still pending then, and the next wait reports it as
/// [`WaitSetRunResult::TerminationRequest`], so an `Interrupt` simply waits again.
///
/// [`WaitSetRunResult::Interrupt`]: iceoryx2::waitset::WaitSetRunResult::Interrupt
/// [`WaitSetRunResult::TerminationRequest`]: iceoryx2::waitset::WaitSetRunResult::TerminationRequest
pub fn run_waitset<F>(
    ws: &iceoryx2::waitset::WaitSet<iceoryx2::prelude::ipc::Service>,
    mut f: F,
) -> Result<iceoryx2::waitset::WaitSetRunResult, iceoryx2::waitset::WaitSetRunError>
where
    F: FnMut(
        iceoryx2::prelude::WaitSetAttachmentId<iceoryx2::prelude::ipc::Service>,
    ) -> iceoryx2::prelude::CallbackProgression,
{
    use iceoryx2::waitset::WaitSetRunResult as R;
    loop {
        match ws.wait_and_process(&mut f)? {
            R::Interrupt => continue,
            r => return Ok(r),
        }
    }
}
