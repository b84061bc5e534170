//! Real-time settings where permitted: SCHED_FIFO priority, CPU affinity, mlockall; each falls
//! back with a warning when the process lacks the permission.

/// What was applied.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RealtimeApplied {
    /// SCHED_FIFO priority in effect (0 = normal scheduling).
    pub priority: i32,
    /// Pinned to this CPU.
    pub cpu: Option<usize>,
    /// Memory locked.
    pub locked: bool,
}

/// Applies what is asked and permitted; never fails (warns instead).
pub fn apply(priority: i32, cpu: Option<usize>, lock: bool) -> RealtimeApplied {
    let mut r = RealtimeApplied::default();
    if let Some(c) = cpu {
        // SAFETY: cpu_set_t is plain data; the calls only read/write it.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(c, &mut set);
            if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0 {
                r.cpu = Some(c);
            } else {
                tracing::warn!(
                    cpu = c,
                    err = %std::io::Error::last_os_error(),
                    "CPU affinity not permitted; running on any CPU"
                );
            }
        }
    }
    if priority > 0 {
        let p = libc::sched_param {
            sched_priority: priority.clamp(1, 99),
        };
        // SAFETY: plain syscall on this process.
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) } == 0 {
            r.priority = p.sched_priority;
        } else {
            tracing::warn!(
                priority,
                err = %std::io::Error::last_os_error(),
                "SCHED_FIFO not permitted; running with normal scheduling"
            );
        }
    }
    if lock {
        // MCL_CURRENT only: the shared memory is mapped already, and MCL_FUTURE would make later
        // mappings fail under a small RLIMIT_MEMLOCK.
        // SAFETY: plain syscall.
        if unsafe { libc::mlockall(libc::MCL_CURRENT) } == 0 {
            r.locked = true;
        } else {
            tracing::warn!(
                err = %std::io::Error::last_os_error(),
                "mlockall not permitted; memory may page"
            );
        }
    }
    if priority > 0 || cpu.is_some() || lock {
        tracing::info!(?r, "real-time settings");
    }
    r
}

/// Returns the calling thread to normal (SCHED_OTHER) scheduling.
pub fn apply_normal() {
    let p = libc::sched_param { sched_priority: 0 };
    // SAFETY: plain syscall on this process.
    unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &p) };
}

/// Keeps the CPUs out of deep idle states while held: writes `us` (microseconds of tolerated
/// wake-up latency, usually 0) to `/dev/cpu_dma_latency` (the kernel's PM QoS interface) and
/// keeps the file open; the request ends when the returned file is dropped. Deep idle states
/// (and, in a virtual machine, a halted virtual CPU) are where most of a sleeping real-time
/// process's wake-up latency comes from. Warns and returns `None` where not permitted.
pub fn hold_cpu_dma_latency(us: i32) -> Option<std::fs::File> {
    use std::io::Write;
    let path = "/dev/cpu_dma_latency";
    let r = std::fs::OpenOptions::new()
        .write(true)
        .open(path)
        .and_then(|mut f| f.write_all(&us.to_ne_bytes()).map(|()| f));
    match r {
        Ok(f) => {
            tracing::info!(us, "CPU wake-up latency held at {us} us ({path})");
            Some(f)
        }
        Err(e) => {
            tracing::warn!(err = %e, "{path} not writable: CPUs may sleep deeply");
            None
        }
    }
}
