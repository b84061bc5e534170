//! Stepper motor, firmware and gear of one leg: step-rate limit, missed steps above the pull-out
//! rate, periodic transmission errors of the gear, and gear backlash (play) between the gear and
//! the tendon roll.

use rand::Rng;

/// What the firmware, the motor and the gear output of one leg are doing.
#[derive(Debug, Clone, PartialEq)]
pub struct Actuator {
    /// Firmware step counter (what the drive reports), steps.
    pub counter: i32,
    /// True motor rotor position (differs from the counter by missed steps), steps.
    pub motor: i32,
    /// Gear output (tendon roll) position, steps (fractional inside the play).
    pub output: f64,
    /// Width of the play, steps (0 = no backlash).
    pub backlash: f64,
    /// Periodic transmission errors of the gear (none = an exact gear).
    pub gear_errors: Vec<GearTerm>,
    /// Steps still to do in the current cycle (signed) and their spacing.
    plan: StepPlan,
}

/// One periodic term of a gear's transmission error: the gear turns short of the rotor by
/// `amplitude sin(wavenumber q + phase)` steps at rotor position q.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GearTerm {
    /// 2 pi / period, rad per step.
    pub wavenumber: f64,
    /// Amplitude, steps.
    pub amplitude: f64,
    /// Phase at q = 0, rad.
    pub phase: f64,
}

impl GearTerm {
    /// A term of period `period_steps`, amplitude `amplitude_steps` and phase `phase_deg`.
    pub fn new(period_steps: f64, amplitude_steps: f64, phase_deg: f64) -> GearTerm {
        GearTerm {
            wavenumber: std::f64::consts::TAU / period_steps,
            amplitude: amplitude_steps,
            phase: phase_deg.to_radians(),
        }
    }

    /// How far the gear output is behind the rotor at rotor position `q`, steps.
    fn lag(&self, q: f64) -> f64 {
        self.amplitude * (self.wavenumber * q + self.phase).sin()
    }
}

#[derive(Debug, Clone, PartialEq, Default)]
struct StepPlan {
    /// Start of the cycle, s.
    t0: f64,
    /// Time between steps, s.
    dt: f64,
    /// Steps planned in the cycle (signed).
    total: i32,
    /// Steps already done.
    done: i32,
    /// Whether these steps may be missed.
    lossy: bool,
}

/// Stepper parameters shared by the legs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepperParams {
    /// Step-rate cap of the firmware, steps/s (None = no cap).
    pub max_rate: Option<f64>,
    /// Steps above this rate may be lost (None = never).
    pub pull_out_rate: Option<f64>,
    /// Probability to lose one such step.
    pub miss_probability: f64,
}

impl Actuator {
    /// An actuator at rest at `steps`, the gear output centred in its play.
    pub fn new(steps: i32, backlash: f64) -> Actuator {
        Actuator {
            counter: steps,
            motor: steps,
            output: steps as f64,
            backlash,
            gear_errors: Vec::new(),
            plan: StepPlan::default(),
        }
    }

    /// The same actuator with these periodic transmission errors of its gear, the output
    /// centred in its play about the gear's position.
    pub fn with_gear_errors(mut self, terms: Vec<GearTerm>) -> Actuator {
        self.gear_errors = terms;
        self.output = self.gear_position();
        self
    }

    /// Where the gear (before the play) is for the rotor's position, steps.
    pub fn gear_position(&self) -> f64 {
        let q = f64::from(self.motor);
        q - self.gear_errors.iter().map(|t| t.lag(q)).sum::<f64>()
    }

    /// Plans the cycle `[t0, t0 + period]` towards `target`; returns whether the rate cap limited
    /// it. The firmware spreads the steps evenly: step k (1-based) happens at t0 + k period / n.
    pub fn plan_cycle(&mut self, t0: f64, period: f64, target: i32, p: &StepperParams) -> bool {
        let mut n = target - self.counter;
        let mut limited = false;
        if let Some(rate) = p.max_rate {
            let cap = (rate * period + 1e-9).floor() as i32;
            if n.abs() > cap {
                n = n.signum() * cap;
                limited = true;
            }
        }
        let rate = n.abs() as f64 / period;
        self.plan = StepPlan {
            t0,
            dt: if n == 0 {
                period
            } else {
                period / n.abs() as f64
            },
            total: n,
            done: 0,
            lossy: p.pull_out_rate.is_some_and(|r| rate > r) && p.miss_probability > 0.0,
        };
        limited
    }

    /// The times (s) of the steps still planned in the current cycle, in order.
    pub fn planned_step_times(&self) -> impl Iterator<Item = f64> + '_ {
        let p = &self.plan;
        (p.done + 1..=p.total.abs()).map(move |j| p.t0 + j as f64 * p.dt)
    }

    /// Executes the planned steps due up to time `t`; returns whether any step happened.
    pub fn advance_to<R: Rng>(&mut self, t: f64, miss_probability: f64, rng: &mut R) -> bool {
        let mut moved = false;
        while self.plan.done < self.plan.total.abs() {
            let tk = self.plan.t0 + (self.plan.done + 1) as f64 * self.plan.dt;
            if tk > t + 1e-12 {
                break;
            }
            self.plan.done += 1;
            let dir = self.plan.total.signum();
            self.counter += dir;
            let lost = self.plan.lossy && rng.random::<f64>() < miss_probability;
            if !lost {
                self.motor += dir;
                self.take_up_play();
                moved = true;
            }
        }
        moved
    }

    /// Whether steps of the current cycle are still pending.
    pub fn moving(&self) -> bool {
        self.plan.done < self.plan.total.abs()
    }

    /// A motor step made outside the stepper model (firmware in the loop): the counter and
    /// the rotor go to `pos`, the output follows through the gear and the play. No rate limit,
    /// no missed steps.
    pub fn external_step(&mut self, pos: i32) {
        self.motor += pos - self.counter;
        self.counter = pos;
        self.take_up_play();
    }

    /// The tendon roll follows the gear once the gear has taken up the slack of the play.
    fn take_up_play(&mut self) {
        let half = 0.5 * self.backlash;
        let g = self.gear_position();
        if g - self.output > half {
            self.output = g - half;
        } else if self.output - g > half {
            self.output = g + half;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn backlash_is_a_dead_band_on_reversal() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let p = StepperParams {
            max_rate: None,
            pull_out_rate: None,
            miss_probability: 0.0,
        };
        let mut a = Actuator::new(0, 4.0);
        a.plan_cycle(0.0, 0.02, 10, &p);
        a.advance_to(0.02, 0.0, &mut rng);
        assert_eq!(a.output, 8.0);
        // Reversal: the first 4 steps do not move the output.
        a.plan_cycle(0.02, 0.02, 6, &p);
        a.advance_to(0.04, 0.0, &mut rng);
        assert_eq!(a.output, 8.0);
        a.plan_cycle(0.04, 0.02, 3, &p);
        a.advance_to(0.06, 0.0, &mut rng);
        assert_eq!(a.output, 5.0);
    }

    #[test]
    fn a_gear_error_moves_the_output_periodically_in_the_rotor_position() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let p = StepperParams {
            max_rate: None,
            pull_out_rate: None,
            miss_probability: 0.0,
        };
        let mut a = Actuator::new(0, 0.0).with_gear_errors(vec![GearTerm::new(8.0, 0.5, 90.0)]);
        // At q = 0 the gear lags by 0.5 sin(90 deg).
        assert!((a.output + 0.5).abs() < 1e-12);
        for target in 1..=16 {
            a.plan_cycle(0.02 * target as f64, 0.02, target, &p);
            a.advance_to(0.02 * (target + 1) as f64, 0.0, &mut rng);
            let want = target as f64
                - 0.5
                    * (std::f64::consts::TAU * target as f64 / 8.0 + std::f64::consts::FRAC_PI_2)
                        .sin();
            assert!(
                (a.output - want).abs() < 1e-12,
                "{target}: {} vs {want}",
                a.output
            );
        }
    }

    #[test]
    fn rate_limit_and_even_spacing() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let p = StepperParams {
            max_rate: Some(600.0),
            pull_out_rate: None,
            miss_probability: 0.0,
        };
        let mut a = Actuator::new(0, 0.0);
        assert!(a.plan_cycle(0.0, 0.02, 100, &p));
        a.advance_to(0.01, 0.0, &mut rng);
        assert_eq!(a.counter, 6);
        a.advance_to(0.02, 0.0, &mut rng);
        assert_eq!(a.counter, 12);
    }

    #[test]
    fn missed_steps_only_above_pull_out() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let p = StepperParams {
            max_rate: None,
            pull_out_rate: Some(500.0),
            miss_probability: 0.5,
        };
        let mut a = Actuator::new(0, 0.0);
        a.plan_cycle(0.0, 0.02, 8, &p); // 400 steps/s
        a.advance_to(0.02, 0.5, &mut rng);
        assert_eq!((a.counter, a.motor), (8, 8));
        a.plan_cycle(0.02, 0.02, 8 + 100, &p); // 5000 steps/s
        a.advance_to(0.04, 0.5, &mut rng);
        assert_eq!(a.counter, 108);
        assert!(a.motor < 90 && a.motor > 20, "{}", a.motor);
    }
}
