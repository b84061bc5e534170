//! The steady-state cycle bodies of the chain's processes, out of their `main`s so that they can
//! be tested (`tests/cycle_alloc.rs`: no heap allocation in a steady-state cycle). Each one is
//! what the process runs when it wakes on the upstream event (the IK and the driver on their hop
//! listener, [`crate::hop::wait`], which has drained the event; the mocap on its WaitSet): take
//! the newest input, run the step, publish zero-copy ([`publish`]) and notify.

use crate::hop_service::HopService;
use crate::ports::{latest, publish};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use pcr_control::{
    measured_of, CorrectionStep, DriverStep, IkStep, InterpolatorStep, PoseSensor, SafeDriver,
    SetpointSource,
};
use pcr_driver::Driver;
use pcr_messages::{
    monotonic_ns, Correction, DriverStateMsg, JointSetpoint, MeasuredPose, TaskSetpoint,
};

/// A publisher of `T` on the chain's services.
pub type Pub<T> = Publisher<ipc::Service, T, ()>;
/// A subscriber of `T` on the chain's services.
pub type Sub<T> = Subscriber<ipc::Service, T, ()>;

/// `pcr-planner`, the end of its cycle: the next task setpoint, stamped, published and
/// notified.
pub fn planner_emit<S: SetpointSource>(
    interp: &mut InterpolatorStep<S>,
    t_s: f64,
    pub_sp: &Pub<TaskSetpoint>,
    notify: &Notifier<HopService>,
) {
    let mut sp = interp.step(t_s);
    sp.stamps.interp_pub_ns = monotonic_ns();
    let _ = publish(pub_sp, sp);
    let _ = notify.notify();
}

/// `pcr-ik` on the task-setpoint event (already drained by [`crate::hop::wait`]): solves the
/// newest setpoint and publishes the joint setpoint (+ event). Returns the receive time and the
/// hop latency (planner publish -> receive) when there was a setpoint.
pub fn ik_on_setpoint(
    sub: &Sub<TaskSetpoint>,
    ik: &mut IkStep,
    pub_j: &Pub<JointSetpoint>,
    notify: &Notifier<HopService>,
) -> Option<(u64, u64)> {
    let rx = monotonic_ns();
    let Ok(Some(mut sp)) = latest(sub) else {
        return None;
    };
    sp.stamps.ik_rx_ns = rx;
    let mut j = ik.step(&sp);
    j.stamps.ik_pub_ns = monotonic_ns();
    let _ = publish(pub_j, j);
    let _ = notify.notify();
    Some((rx, rx.saturating_sub(sp.stamps.interp_pub_ns)))
}

/// `pcr-driver`: one drive cycle with `input` (the newest joint setpoint, `None` on a period
/// without one); publishes the driver state (+ event). A watchdog trip (this process stalled) is
/// re-armed and the cycle retried; a driver error is logged, and a transport error is returned
/// (fatal: the process ends).
pub fn driver_run<D: Driver, P: PoseSensor>(
    step: &mut DriverStep<SafeDriver<D>, P>,
    input: Option<&JointSetpoint>,
    pub_st: &Pub<DriverStateMsg>,
    notify: &Notifier<ipc::Service>,
) -> Result<(), anyhow::Error> {
    let mut r = step.step(crate::chain_time_s(), input);
    if r.is_err() && step.driver().tripped() {
        // This process stalled longer than the watchdog (it has held the drive meanwhile):
        // re-arm and carry on; the rate limit bounds any catch-up.
        tracing::warn!("driver process stalled: watchdog re-armed");
        step.driver_mut().reset();
        r = step.step(crate::chain_time_s(), input);
    }
    match r {
        Ok(st) => {
            let _ = publish(pub_st, st);
            let _ = notify.notify();
            Ok(())
        }
        Err(e) => {
            tracing::error!(driver = step.driver().name(), "driver: {e}");
            if matches!(e, pcr_driver::DriverError::Transport(_)) {
                return Err(anyhow::anyhow!("driver transport: {e}"));
            }
            Ok(())
        }
    }
}

/// `pcr-driver` on the joint-setpoint event (already drained by [`crate::hop::wait`]): runs the
/// drive with the newest setpoint ([`driver_run`]). Returns the receive time, the hop latency
/// (IK publish -> receive) and the cycle's outcome when there was a setpoint.
#[allow(clippy::type_complexity)]
pub fn driver_on_setpoint<D: Driver, P: PoseSensor>(
    sub: &Sub<JointSetpoint>,
    step: &mut DriverStep<SafeDriver<D>, P>,
    pub_st: &Pub<DriverStateMsg>,
    notify: &Notifier<ipc::Service>,
) -> Option<(u64, u64, Result<(), anyhow::Error>)> {
    let rx = monotonic_ns();
    let Ok(Some(mut j)) = latest(sub) else {
        return None;
    };
    j.stamps.drv_rx_ns = rx;
    let r = driver_run(step, Some(&j), pub_st, notify);
    Some((rx, rx.saturating_sub(j.stamps.ik_pub_ns), r))
}

/// `pcr-mocap --source driver` on the driver-state event: republishes the measured pose and
/// publishes the correction. Returns the receive time when there was a state.
pub fn mocap_on_state(
    listener: &Listener<ipc::Service>,
    sub: &Sub<DriverStateMsg>,
    corr: &mut CorrectionStep,
    pub_m: &Pub<MeasuredPose>,
    pub_c: &Pub<Correction>,
) -> Option<u64> {
    let _ = listener.try_wait(|_| {});
    let rx = monotonic_ns();
    let Ok(Some(st)) = latest(sub) else {
        return None;
    };
    let m = measured_of(&st);
    let _ = publish(pub_m, m);
    let _ = publish(pub_c, corr.step(&m, st.t_s, &st.planned));
    Some(rx)
}
