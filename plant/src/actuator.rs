//! Stepper motor, firmware and gear of one leg: step-rate limit, missed steps above the pull-out
//! rate, and gear backlash (play) between the motor and the tendon roll.

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
    /// Steps still to do in the current cycle (signed) and their spacing.
    plan: StepPlan,
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
            plan: StepPlan::default(),
        }
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

    fn take_up_play(&mut self) {
        let half = 0.5 * self.backlash;
        let m = self.motor as f64;
        if m - self.output > half {
            self.output = m - half;
        } else if self.output - m > half {
            self.output = m + half;
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
