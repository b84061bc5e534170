//! Command-line options shared by every process binary.

use clap::Args;
use std::time::Duration;

/// Options of every chain process (the supervisor passes them).
#[derive(Debug, Clone, Args)]
pub struct CommonArgs {
    /// Prefix of every iceoryx2 file of this chain (isolates chains and tests).
    #[arg(long, env = "PCR_IOX2_PREFIX", default_value = "pcr_")]
    pub prefix: String,
    /// Control period, ms.
    #[arg(long, default_value_t = 20.0)]
    pub period_ms: f64,
    /// Heartbeat period, ms.
    #[arg(long, default_value_t = 100.0)]
    pub heartbeat_ms: f64,
    /// Robot configuration.
    #[arg(long, default_value = "configs/robot.toml")]
    pub robot: String,
    /// SCHED_FIFO priority (1..99); 0 = normal scheduling.
    #[arg(long, default_value_t = 0)]
    pub rt_priority: i32,
    /// CPU to pin the process to.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Lock the process's memory (mlockall) once its ports exist.
    #[arg(long)]
    pub mlockall: bool,
    /// Protocol version to speak (tests only: simulates a binary of another revision).
    #[arg(long, hide = true, default_value_t = pcr_messages::PROTOCOL_VERSION)]
    pub protocol_version: u32,
    /// How long to listen for peers' protocol announcements before starting, ms.
    #[arg(long, default_value_t = 300)]
    pub handshake_ms: u64,
}

impl CommonArgs {
    /// The control period.
    pub fn period(&self) -> Duration {
        Duration::from_secs_f64(self.period_ms.max(0.05) * 1e-3)
    }
    /// The heartbeat period.
    pub fn heartbeat(&self) -> Duration {
        Duration::from_secs_f64(self.heartbeat_ms.max(1.0) * 1e-3)
    }
}
