//! Simulated time as one value: the step index, the step size and the time they give.

/// Where a simulation is in time: `step` steps of `dt` taken, so `time = step · dt`.
///
/// Time is derived from the step index instead of summed step by step, so every backend (the
/// GPU counts steps as integers) agrees on it to the last bit, however long the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clock {
    /// Steps taken.
    pub step: u64,
    /// Time step [s].
    pub dt: f64,
}

impl Clock {
    /// A clock at step 0 with steps of `dt`.
    pub fn start(dt: f64) -> Self {
        Self { step: 0, dt }
    }

    /// Simulated time [s].
    pub fn time(&self) -> f64 {
        self.step as f64 * self.dt
    }

    /// The time at which step `k` of a batch starting here begins [s].
    pub fn time_of(&self, k: u64) -> f64 {
        (self.step + k) as f64 * self.dt
    }

    /// This clock `steps` steps later.
    #[must_use]
    pub fn advanced(self, steps: u64) -> Self {
        Self {
            step: self.step + steps,
            ..self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Clock;

    #[test]
    fn time_is_the_step_count_times_dt_not_a_running_sum() {
        let dt = 1e-4;
        let mut c = Clock::start(dt);
        let mut sum = 0.0;
        for _ in 0..100_000 {
            c = c.advanced(1);
            sum += dt;
        }
        assert_eq!(c.step, 100_000);
        assert_eq!(c.time(), 100_000.0 * dt);
        assert_ne!(c.time(), sum, "a running sum drifts; the clock does not");
        assert_eq!(Clock::start(dt).time_of(3), 3.0 * dt);
    }
}
