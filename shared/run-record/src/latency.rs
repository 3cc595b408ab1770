//! Latency percentiles and the bounded-memory histogram they come from.

use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};

/// Percentiles of a latency, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// Samples.
    pub count: usize,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Percentiles {
    /// Nearest-rank percentiles of the finite values; `None` when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Self> {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let rank =
            |p: f64| v[(((p / 100.0) * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
        Some(Self {
            count: v.len(),
            p50: rank(50.0),
            p90: rank(90.0),
            p99: rank(99.0),
            max: v[v.len() - 1],
        })
    }
}

/// A latency distribution kept in bounded memory however many samples it takes: an
/// HDR histogram of microseconds to 3 significant digits (percentiles within 0.1 %), up to
/// an hour; the largest sample is kept exactly.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    micros: Histogram<u64>,
    max_ms: f64,
}

/// Microseconds per millisecond: the histogram's unit.
pub(crate) const MICROS_PER_MS: f64 = 1000.0;
/// The largest latency the histogram tells apart (larger ones count as this), microseconds.
pub(crate) const HIGHEST_MICROS: u64 = 3_600_000_000;
/// Significant decimal digits the histogram keeps.
pub(crate) const SIGNIFICANT_DIGITS: u8 = 3;

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self {
            // Constant bounds, valid (the tests build one): this cannot fail.
            micros: Histogram::new_with_max(HIGHEST_MICROS, SIGNIFICANT_DIGITS)
                .unwrap_or_else(|e| unreachable!("constant histogram bounds: {e}")),
            max_ms: f64::NAN,
        }
    }
}

impl LatencyHistogram {
    /// Adds a sample; NaN (the stage did not handle the frame) and negative values are
    /// left out.
    pub fn record(&mut self, ms: f64) {
        if !(ms >= 0.0) || !ms.is_finite() {
            return;
        }
        self.micros
            .saturating_record((ms * MICROS_PER_MS).round().min(HIGHEST_MICROS as f64) as u64);
        self.max_ms = if self.max_ms.is_nan() {
            ms
        } else {
            self.max_ms.max(ms)
        };
    }

    /// The percentiles of the samples so far; `None` when there are none.
    pub fn percentiles(&self) -> Option<Percentiles> {
        if self.micros.is_empty() {
            return None;
        }
        let at =
            |q: f64| (self.micros.value_at_quantile(q) as f64 / MICROS_PER_MS).min(self.max_ms);
        Some(Percentiles {
            count: self.micros.len() as usize,
            p50: at(0.50),
            p90: at(0.90),
            p99: at(0.99),
            max: self.max_ms,
        })
    }
}
