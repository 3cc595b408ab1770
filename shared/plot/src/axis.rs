//! One axis of a chart: its range, linear or logarithmic, with round tick positions and
//! their labels. Charts draw in the axis's own units (log10 of the value on a log axis), so
//! both kinds share one coordinate type.

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
use std::ops::Range;

/// How values map onto an axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Evenly spaced values.
    Linear,
    /// Decades evenly spaced; values at or below zero sit at the axis's low end.
    Log,
    /// Logarithmic when the positive values span more than [`LOG_SPREAD`], else linear.
    Auto,
}

/// Largest ratio of the largest to the smallest positive value drawn on a linear axis by
/// [`Scale::Auto`]: beyond two decades the small values would be flattened onto the axis.
pub const LOG_SPREAD: f64 = 100.0;

/// Relative margin added on either side of a linear axis's data.
const PAD: f64 = 0.05;

impl Scale {
    /// [`Scale::Linear`] or [`Scale::Log`]: `Auto` decided over `values` (non-finite ones
    /// ignored); a log axis needs some positive value, else it is linear.
    pub fn resolve(self, values: impl IntoIterator<Item = f64>) -> Scale {
        let (mut min_pos, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values.into_iter().filter(|v| v.is_finite()) {
            max = max.max(v);
            if v > 0.0 {
                min_pos = min_pos.min(v);
            }
        }
        match self {
            Scale::Linear => Scale::Linear,
            Scale::Log | Scale::Auto if !min_pos.is_finite() => Scale::Linear,
            Scale::Log => Scale::Log,
            Scale::Auto if max / min_pos > LOG_SPREAD => Scale::Log,
            Scale::Auto => Scale::Linear,
        }
    }
}

/// A fitted axis, `lo..hi` in data units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Axis {
    pub log: bool,
    pub lo: f64,
    pub hi: f64,
}

impl Axis {
    /// The axis over the finite `values`; a linear one starts at zero when `from_zero` and
    /// the values are not negative. No values: 0..1.
    pub fn fit(values: &[f64], scale: Scale, from_zero: bool) -> Self {
        let finite = || values.iter().copied().filter(|v| v.is_finite());
        let (lo, hi) = finite().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        if !lo.is_finite() {
            return Self {
                log: false,
                lo: 0.0,
                hi: 1.0,
            };
        }
        if scale.resolve(finite()) == Scale::Log {
            let min_pos = finite().filter(|v| *v > 0.0).fold(f64::INFINITY, f64::min);
            let lo = 10f64.powf(min_pos.log10().floor());
            let mut hi = 10f64.powf(hi.log10().ceil());
            if hi <= lo {
                hi = lo * 10.0;
            }
            return Self { log: true, lo, hi };
        }
        let (lo, hi) = if from_zero && lo >= 0.0 {
            (0.0, hi)
        } else {
            (lo, hi)
        };
        let span = hi - lo;
        let (lo, hi) = if span <= f64::EPSILON * hi.abs().max(1.0) {
            (lo - 0.5, hi + 0.5)
        } else if from_zero && lo == 0.0 {
            (0.0, hi + PAD * span)
        } else {
            (lo - PAD * span, hi + PAD * span)
        };
        Self { log: false, lo, hi }
    }

    /// Widens a linear axis about its centre to `span` (data units); a log axis is kept.
    pub fn widen_to(&mut self, span: f64) {
        if !self.log && span > self.hi - self.lo {
            let mid = 0.5 * (self.lo + self.hi);
            (self.lo, self.hi) = (mid - 0.5 * span, mid + 0.5 * span);
        }
    }

    /// `v` in drawing units (log10 on a log axis, clamped to the axis's low end).
    pub fn to(&self, v: f64) -> f64 {
        if self.log { v.max(self.lo).log10() } else { v }
    }

    /// The axis's ends in drawing units.
    pub fn ends(&self) -> (f64, f64) {
        (self.to(self.lo), self.to(self.hi))
    }

    /// Tick positions in drawing units: 1-2-5 steps on a linear axis; decades (and 2×, 5×
    /// when there are few) on a log one. Light grid positions second.
    pub fn ticks(&self) -> (Vec<f64>, Vec<f64>) {
        if self.log {
            let (a, b) = self.ends();
            let decades: Vec<f64> = (a.round() as i32..=b.round() as i32)
                .map(f64::from)
                .collect();
            let within = |t: &f64| *t >= a - 1e-9 && *t <= b + 1e-9;
            let between = |m: &[f64]| -> Vec<f64> {
                decades
                    .iter()
                    .flat_map(|d| m.iter().map(move |k| d + k.log10()))
                    .filter(within)
                    .collect()
            };
            let bold = if decades.len() <= 4 {
                let mut t = between(&[1.0, 2.0, 5.0]);
                t.sort_by(f64::total_cmp);
                t
            } else {
                decades.clone()
            };
            let light = between(&[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
            return (bold, light);
        }
        let step = self.step();
        let first = (self.lo / step).ceil() as i64;
        let last = (self.hi / step).floor() as i64;
        let bold: Vec<f64> = (first..=last).map(|k| k as f64 * step).collect();
        let light: Vec<f64> = ((first * 2 - 1)..=(last * 2 + 1))
            .map(|k| k as f64 * step / 2.0)
            .filter(|t| *t >= self.lo && *t <= self.hi)
            .collect();
        (bold, light)
    }

    /// A 1-2-5 × 10ⁿ step giving about six ticks over a linear axis.
    fn step(&self) -> f64 {
        let raw = (self.hi - self.lo) / 6.0;
        let magnitude = 10f64.powf(raw.log10().floor());
        [1.0, 2.0, 5.0, 10.0]
            .iter()
            .map(|k| k * magnitude)
            .find(|s| *s >= raw)
            .unwrap_or(10.0 * magnitude)
    }

    /// The label of the tick at `t` (drawing units).
    pub fn label(&self, t: f64) -> String {
        let (v, resolution) = if self.log {
            let v = 10f64.powf(t);
            (v, v)
        } else {
            (t, self.step())
        };
        let decimals = (-resolution.log10().floor()).clamp(0.0, 6.0) as usize;
        let text = format!("{v:.decimals$}");
        if text.starts_with('-') && text.trim_start_matches(['-', '0', '.']).is_empty() {
            text[1..].to_string()
        } else {
            text
        }
    }

    /// The plotters coordinate of the axis (drawing units), with its ticks.
    pub fn coord(&self) -> Ticked {
        let (a, b) = self.ends();
        let (bold, light) = self.ticks();
        Ticked::new(a..b, bold, light)
    }
}

/// A linear plotters coordinate with given tick positions (plotters' own `WithKeyPoints`
/// cannot take a label formatter).
#[derive(Clone)]
pub(crate) struct Ticked {
    inner: RangedCoordf64,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Ticked {
    pub fn new(range: Range<f64>, bold: Vec<f64>, light: Vec<f64>) -> Self {
        Self {
            inner: range.into(),
            bold,
            light,
        }
    }
}

impl Ranged for Ticked {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.inner.range()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_goes_log_only_when_the_spread_asks_for_it() {
        assert_eq!(Scale::Auto.resolve([0.01, 35.0, 80.0]), Scale::Log);
        assert_eq!(
            Scale::Auto.resolve([0.0, 0.0, 9.0, 35.0, 80.0]),
            Scale::Linear
        );
        assert_eq!(Scale::Auto.resolve([9.0, 35.0, 80.0]), Scale::Linear);
        assert_eq!(Scale::Auto.resolve([f64::NAN, 1.0]), Scale::Linear);
        assert_eq!(
            Scale::Log.resolve([0.0, -1.0]),
            Scale::Linear,
            "nothing positive"
        );
        assert_eq!(Scale::Auto.resolve([]), Scale::Linear);
    }

    #[test]
    fn a_log_axis_spans_whole_decades_and_clamps_zero_to_its_low_end() {
        let axis = Axis::fit(&[0.0, 0.004, 35.0, 250.0], Scale::Auto, false);
        assert!(axis.log);
        assert_eq!((axis.lo, axis.hi), (0.001, 1000.0));
        assert_eq!(axis.to(0.0), -3.0);
        let (bold, _) = axis.ticks();
        assert_eq!(bold.first().copied(), Some(-3.0));
        assert_eq!(axis.label(2.0), "100");
        assert_eq!(axis.label(-2.0), "0.01");
    }

    #[test]
    fn a_linear_axis_has_round_ticks_inside_it() {
        let axis = Axis::fit(&[0.0, 71.0, 85.2], Scale::Linear, true);
        assert_eq!(axis.lo, 0.0);
        let (bold, light) = axis.ticks();
        assert_eq!(bold, vec![0.0, 20.0, 40.0, 60.0, 80.0]);
        assert!(light.iter().all(|t| *t >= axis.lo && *t <= axis.hi));
        assert_eq!(axis.label(20.0), "20");
        let small = Axis::fit(&[0.91, 0.99], Scale::Linear, false);
        assert_eq!(small.label(0.95), "0.95");
    }

    #[test]
    fn degenerate_data_still_gives_an_axis() {
        for values in [&[][..], &[f64::NAN], &[3.0], &[3.0, 3.0]] {
            let axis = Axis::fit(values, Scale::Auto, false);
            assert!(axis.lo < axis.hi, "{values:?}: {axis:?}");
            assert!(!axis.ticks().0.is_empty(), "{values:?}: no ticks");
        }
    }
}
