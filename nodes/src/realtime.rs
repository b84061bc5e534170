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
