//! Gilbert–Elliott bursty loss whose state changes with time, not per packet.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::impairment::GilbertElliott;
use crate::time::{duration_ns, Time};

/// The channel state of a continuous-time two-state Markov chain.
///
/// Sojourn times are exponential with the configured means, so a burst lasts as long in
/// milliseconds whether the sender sends 10 or 1000 packets a second. The chain is only
/// looked at when a packet is sent: if several transitions happened since the last look,
/// the state at `now` is drawn from the exact transition probability of the chain
/// (`p_ss(Δ) = π_s + (1 − π_s)·e^{−(λ+μ)Δ}`), and by memorylessness a fresh exponential
/// sojourn starts there. So rare packets cost O(1), not one draw per elapsed burst.
#[derive(Debug, Clone)]
pub(crate) struct BurstChain {
    params: GilbertElliott,
    bad: bool,
    /// When the current sojourn ends; `None` before the first look.
    until: Option<Time>,
}

impl BurstChain {
    pub(crate) fn new(params: GilbertElliott) -> BurstChain {
        BurstChain {
            params,
            bad: false,
            until: None,
        }
    }

    pub(crate) fn params(&self) -> &GilbertElliott {
        &self.params
    }

    /// Whether the channel is in the bad state at `now`. `now` must not go backwards
    /// (an earlier `now` reads the current state).
    pub(crate) fn is_bad_at(&mut self, now: Time, rng: &mut ChaCha8Rng) -> bool {
        let pi_bad = self.params.bad_fraction();
        match self.until {
            None => {
                // First look: the stationary distribution.
                self.bad = rng.random::<f64>() < pi_bad;
                self.until = Some(now + self.sojourn(rng));
            }
            Some(until) if now >= until => {
                let entered_bad = !self.bad;
                let elapsed_s = (now - until).as_secs_f64();
                let rate_sum = 1.0 / self.params.mean_good.as_secs_f64()
                    + 1.0 / self.params.mean_bad.as_secs_f64();
                let pi_entered = if entered_bad { pi_bad } else { 1.0 - pi_bad };
                let p_stay = pi_entered + (1.0 - pi_entered) * (-rate_sum * elapsed_s).exp();
                self.bad = if rng.random::<f64>() < p_stay {
                    entered_bad
                } else {
                    !entered_bad
                };
                self.until = Some(now + self.sojourn(rng));
            }
            Some(_) => {}
        }
        self.bad
    }

    fn sojourn(&self, rng: &mut ChaCha8Rng) -> std::time::Duration {
        let mean = if self.bad {
            self.params.mean_bad
        } else {
            self.params.mean_good
        };
        // 1 - u lies in (0, 1], so the logarithm is finite.
        let u: f64 = rng.random();
        let ns = -(duration_ns(mean) as f64) * (1.0 - u).ln();
        std::time::Duration::from_nanos(ns.round() as u64)
    }

    /// Loss probability at `now`, from the state.
    pub(crate) fn loss_at(&mut self, now: Time, rng: &mut ChaCha8Rng) -> f64 {
        if self.is_bad_at(now, rng) {
            self.params.loss_bad
        } else {
            self.params.loss_good
        }
    }
}
