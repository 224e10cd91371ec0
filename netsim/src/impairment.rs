//! What a link does to packets: the configuration half of the link model.

use std::time::Duration;

/// The shape of a link's delay variation around its latency.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum JitterDist {
    /// Delay uniform in `[latency − jitter, latency + jitter]` (netem's default).
    #[default]
    Uniform,
    /// Delay normal with mean `latency` and standard deviation `jitter`.
    Normal,
    /// Heavy-tailed WLAN spikes: delay = `latency + jitter · (U^(−1/α) − 1)`, a Lomax
    /// (Pareto II) tail with shape α = [`PARETO_SHAPE`]: `latency` is the floor, the median
    /// excess is `jitter · (√2 − 1)`, and one packet in 100 waits ≥ 9 · `jitter` extra.
    Pareto,
}

/// The Lomax shape α used by [`JitterDist::Pareto`] (α = 2: finite mean, infinite variance).
pub const PARETO_SHAPE: f64 = 2.0;

impl JitterDist {
    /// The spec-string name (`uniform`, `normal`, `pareto`).
    pub fn name(self) -> &'static str {
        match self {
            JitterDist::Uniform => "uniform",
            JitterDist::Normal => "normal",
            JitterDist::Pareto => "pareto",
        }
    }
}

/// Gilbert–Elliott bursty loss in continuous time.
///
/// The channel alternates between a good and a bad state; each stay is exponentially
/// distributed with the given mean, whatever the packet rate. A packet sent while the
/// channel is good is lost with `loss_good`, while bad with `loss_bad`.
/// Mean loss = `π_good · loss_good + π_bad · loss_bad` with
/// `π_bad = mean_bad / (mean_good + mean_bad)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GilbertElliott {
    /// Mean time in the good state (the gap between bursts).
    pub mean_good: Duration,
    /// Mean time in the bad state (the burst).
    pub mean_bad: Duration,
    /// Loss probability while good.
    pub loss_good: f64,
    /// Loss probability while bad.
    pub loss_bad: f64,
}

impl Default for GilbertElliott {
    /// 100 ms bursts of total loss every ~1 s (10% mean loss).
    fn default() -> Self {
        GilbertElliott {
            mean_good: Duration::from_millis(900),
            mean_bad: Duration::from_millis(100),
            loss_good: 0.0,
            loss_bad: 1.0,
        }
    }
}

impl GilbertElliott {
    /// The long-run fraction of time spent in the bad state, `π_bad`.
    pub fn bad_fraction(&self) -> f64 {
        let bad = self.mean_bad.as_secs_f64();
        bad / (bad + self.mean_good.as_secs_f64())
    }

    /// The long-run loss probability.
    pub fn mean_loss(&self) -> f64 {
        let pi_bad = self.bad_fraction();
        (1.0 - pi_bad) * self.loss_good + pi_bad * self.loss_bad
    }

    fn validate(&self) -> Result<(), ConfigError> {
        if self.mean_good.is_zero() || self.mean_bad.is_zero() {
            return Err(ConfigError::ZeroBurstMean);
        }
        probability("burst-good-loss", self.loss_good)?;
        probability("burst-loss", self.loss_bad)
    }
}

/// Why a link or uplink configuration was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    /// A probability is NaN or outside `[0, 1]`.
    #[error("{name} = {value} is not a probability in [0, 1]")]
    Probability {
        /// Which parameter (its spec-string key).
        name: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// A Gilbert–Elliott mean sojourn is zero.
    #[error("Gilbert-Elliott mean good and bad durations must be positive")]
    ZeroBurstMean,
    /// The bandwidth is zero.
    #[error("rate must be positive")]
    ZeroRate,
    /// The queue limit is zero (nothing could ever be sent).
    #[error("queue limit must be at least one packet")]
    ZeroQueue,
    /// The beacon interval is zero.
    #[error("beacon interval must be positive")]
    ZeroBeacon,
}

fn probability(name: &'static str, value: f64) -> Result<(), ConfigError> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(ConfigError::Probability { name, value })
    }
}

/// Everything one one-way link does to a packet (netem's core, plus a WLAN beacon).
///
/// In order: the packet waits in a bounded queue and is serialised at `rate_bps`
/// (tail drop when `queue_limit` packets are waiting); it is lost by the Gilbert–Elliott
/// burst state at its send time, or independently with `loss`; it is delayed by
/// `latency` plus jitter, except that with probability `reorder` it skips the delay
/// (netem's reordering: it overtakes packets already in flight); with probability
/// `duplicate` a second copy follows with its own delay; a multicast packet is finally
/// held until the next multiple of `beacon`, as an access point holds group traffic
/// until the next (DTIM) beacon.
///
/// `Default` is a perfect link: no delay, no loss. Spec strings
/// (`"loss=20%,delay=50ms,jitter=20ms"`) parse into this type with [`str::parse`];
/// `Display` writes one back.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    /// Base one-way delay.
    pub latency: Duration,
    /// Spread of the delay around `latency` (meaning depends on `jitter_dist`).
    pub jitter: Duration,
    /// Shape of the delay spread.
    pub jitter_dist: JitterDist,
    /// Independent loss probability.
    pub loss: f64,
    /// Bursty loss, if any (applied before and in addition to `loss`).
    pub burst: Option<GilbertElliott>,
    /// Probability of delivering a second copy.
    pub duplicate: f64,
    /// Probability that a packet skips the delay and overtakes earlier ones.
    pub reorder: f64,
    /// Bandwidth in bits per second (`None`: infinite, no queue).
    pub rate_bps: Option<u64>,
    /// Packets that may wait for the wire, including the one being serialised (only
    /// matters with a rate; default [`DEFAULT_QUEUE_LIMIT`]).
    pub queue_limit: usize,
    /// Multicast hold: deliveries of multicast packets are rounded up to a multiple of this.
    pub beacon: Option<Duration>,
}

/// The default queue limit in packets (netem's default).
pub const DEFAULT_QUEUE_LIMIT: usize = 1000;

impl Default for LinkConfig {
    /// A perfect link: no delay, no loss, infinite bandwidth.
    fn default() -> Self {
        LinkConfig {
            latency: Duration::ZERO,
            jitter: Duration::ZERO,
            jitter_dist: JitterDist::Uniform,
            loss: 0.0,
            burst: None,
            duplicate: 0.0,
            reorder: 0.0,
            rate_bps: None,
            queue_limit: DEFAULT_QUEUE_LIMIT,
            beacon: None,
        }
    }
}

impl LinkConfig {
    /// Checks every parameter; the model refuses a config that fails.
    pub fn validate(&self) -> Result<(), ConfigError> {
        probability("loss", self.loss)?;
        probability("dup", self.duplicate)?;
        probability("reorder", self.reorder)?;
        if let Some(burst) = &self.burst {
            burst.validate()?;
        }
        if self.rate_bps == Some(0) {
            return Err(ConfigError::ZeroRate);
        }
        if self.queue_limit == 0 {
            return Err(ConfigError::ZeroQueue);
        }
        if self.beacon == Some(Duration::ZERO) {
            return Err(ConfigError::ZeroBeacon);
        }
        Ok(())
    }

    /// The long-run probability that a packet is lost by `loss` and `burst` together
    /// (queue drops excluded: they depend on the traffic).
    pub fn mean_loss(&self) -> f64 {
        let burst = self.burst.map_or(0.0, |b| b.mean_loss());
        1.0 - (1.0 - self.loss) * (1.0 - burst)
    }
}

/// The part of the loss that all receivers of one transmission share: the sender's own
/// radio hop to the access point. A packet lost here is lost for every receiver at once;
/// the per-receiver links then add their own independent part.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct UplinkConfig {
    /// Independent shared loss probability.
    pub loss: f64,
    /// Shared bursty loss (interference near the sender hits every receiver).
    pub burst: Option<GilbertElliott>,
}

impl UplinkConfig {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), ConfigError> {
        probability("uplink-loss", self.loss)?;
        if let Some(burst) = &self.burst {
            burst.validate()?;
        }
        Ok(())
    }

    /// The long-run probability that a transmission is lost on the uplink.
    pub fn mean_loss(&self) -> f64 {
        let burst = self.burst.map_or(0.0, |b| b.mean_loss());
        1.0 - (1.0 - self.loss) * (1.0 - burst)
    }
}
