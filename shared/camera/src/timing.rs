//! Capture timestamps, frames the driver lost, and lateness.
//!
//! [`FrameClock`] stamps each frame of one connection to a camera:
//!
//! - **The timestamp** is the driver's (`CAP_PROP_POS_MSEC`: the GStreamer buffer's
//!   presentation time, the V4L2 buffer's time) when it gives one that grows from frame to
//!   frame, moved onto the reader's clock by one offset per connection (the read time of
//!   the connection's first frame minus its driver time), so that timestamps keep growing
//!   across reconnections whose driver time starts again from zero; otherwise (the image
//!   sequence reader, a driver reporting 0 or a constant) the reader's clock when the frame
//!   was read, for the rest of the connection.
//! - **Dropped frames**: with driver timestamps and a known frame period, a gap of more
//!   than 1.5 periods between two frames means `round(gap / period) − 1` frames were lost
//!   before this one (the driver or the camera could not deliver them). Without driver
//!   timestamps no such gap is counted: the read time jitters with the reader, not the camera.
//! - **Lateness**: the driver's clock is not the reader's, so the offset between them is
//!   estimated as the smallest `read − driver` seen so far (the frame that waited least);
//!   a frame's lag is how much longer than that it waited before it was read. A frame
//!   whose lag exceeds the limit is late (it sat in a buffer while newer ones were taken).
//!
//! Everything here is arithmetic on the times it is given: the tests drive it directly.

/// The stamp of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    /// The frame's time on the reader's clock, nanoseconds: the driver's moved by the
    /// connection's offset, or the read time (see `from_driver`).
    pub timestamp_ns: u64,
    /// Whether `timestamp_ns` is the driver's.
    pub from_driver: bool,
    /// Frames lost just before this one (gaps in the driver's timestamps).
    pub dropped_before: u64,
    /// When the frame was captured on the reader's clock (the read time, or the driver's
    /// time moved onto the reader's clock by the estimated offset), nanoseconds.
    pub capture_ns: u64,
    /// How much longer than the least-delayed frame this one waited before it was read.
    pub lag_ns: u64,
}

/// Stamps the frames of one connection (make a new one after reconnecting).
#[derive(Debug, Clone)]
pub struct FrameClock {
    period_ns: Option<u64>,
    driver: DriverTime,
    last_ns: Option<u64>,
    /// min(read − driver) so far.
    offset_ns: Option<i128>,
    /// read − driver of the connection's first frame: driver time → reader's clock.
    base_ns: Option<i128>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DriverTime {
    /// Not yet known (fewer than two frames).
    Unknown,
    /// The driver's timestamps grow: use them.
    Used,
    /// They do not: the read time is used.
    Fallback,
}

impl FrameClock {
    /// A clock for a camera delivering a frame every `period_ns` (None: unknown, no drop count).
    pub fn new(period_ns: Option<u64>) -> Self {
        Self {
            period_ns: period_ns.filter(|p| *p > 0),
            driver: DriverTime::Unknown,
            last_ns: None,
            offset_ns: None,
            base_ns: None,
        }
    }

    /// Whether the driver's timestamps are used (None: not decided yet).
    pub fn uses_driver_time(&self) -> Option<bool> {
        match self.driver {
            DriverTime::Unknown => None,
            DriverTime::Used => Some(true),
            DriverTime::Fallback => Some(false),
        }
    }

    /// Stamps a frame the driver timed `driver_ms` (if it did) that was read at `read_ns`.
    pub fn stamp(&mut self, driver_ms: Option<f64>, read_ns: u64) -> Stamp {
        let driver_ns = driver_ms
            .filter(|t| t.is_finite() && *t >= 0.0 && *t < 1e15)
            .map(|t| (t * 1e6).round() as u64);
        self.driver = match (self.driver, driver_ns, self.last_ns) {
            (DriverTime::Fallback, _, _) | (_, None, _) => DriverTime::Fallback,
            (state, Some(_), None) => state,
            (DriverTime::Unknown | DriverTime::Used, Some(t), Some(last)) if t > last => {
                DriverTime::Used
            }
            (DriverTime::Unknown, Some(_), Some(_)) => DriverTime::Fallback,
            // Used, but this one does not grow: a reordered or repeated buffer; keep using it.
            (DriverTime::Used, Some(_), Some(_)) => DriverTime::Used,
        };
        let fallback = Stamp {
            timestamp_ns: read_ns,
            from_driver: false,
            dropped_before: 0,
            capture_ns: read_ns,
            lag_ns: 0,
        };
        let Some(t) = driver_ns.filter(|_| self.driver != DriverTime::Fallback) else {
            self.last_ns = Some(read_ns);
            return fallback;
        };
        let dropped_before = match (self.period_ns, self.last_ns) {
            (Some(period), Some(last)) if self.driver == DriverTime::Used && t > last => {
                let gap = t - last;
                if 2 * gap > 3 * period {
                    ((gap as f64 / period as f64).round() as u64).saturating_sub(1)
                } else {
                    0
                }
            }
            _ => 0,
        };
        let offset = i128::from(read_ns) - i128::from(t);
        let min_offset = self.offset_ns.map_or(offset, |o| o.min(offset));
        self.offset_ns = Some(min_offset);
        let base = *self.base_ns.get_or_insert(offset);
        self.last_ns = Some(self.last_ns.map_or(t, |l| l.max(t)));
        let capture = (i128::from(t) + min_offset).clamp(0, i128::from(read_ns));
        Stamp {
            timestamp_ns: (i128::from(t) + base).max(0) as u64,
            from_driver: true,
            dropped_before,
            capture_ns: capture as u64,
            lag_ns: (offset - min_offset) as u64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn driver_timestamps_are_used_when_they_grow_and_gaps_count_as_drops() {
        let mut clock = FrameClock::new(Some(50 * MS));
        // Frames at 0, 50, 100, then 250 (two lost: 150, 200), then 300.
        let reads = [
            (0.0, 1000),
            (50.0, 1050),
            (100.0, 1100),
            (250.0, 1250),
            (300.0, 1300),
        ];
        let stamps: Vec<Stamp> = reads
            .iter()
            .map(|&(d, r)| clock.stamp(Some(d), r * MS))
            .collect();
        assert_eq!(clock.uses_driver_time(), Some(true));
        let dropped: Vec<u64> = stamps.iter().map(|s| s.dropped_before).collect();
        assert_eq!(dropped, [0, 0, 0, 2, 0]);
        // The driver's time, moved onto the reader's clock by the first frame's offset.
        assert_eq!(stamps[3].timestamp_ns, 1250 * MS);
        assert!(
            stamps
                .iter()
                .skip(1)
                .all(|s| s.from_driver && s.lag_ns == 0)
        );
        // Captured 1000 ms after the driver's zero on the reader's clock.
        assert_eq!(stamps[4].capture_ns, 1300 * MS);
    }

    #[test]
    fn a_frame_that_waited_longer_than_the_others_is_late_by_the_difference() {
        let mut clock = FrameClock::new(Some(50 * MS));
        clock.stamp(Some(0.0), 1000 * MS);
        clock.stamp(Some(50.0), 1050 * MS);
        // Read 120 ms after it would have been with the first frames' delay.
        let late = clock.stamp(Some(100.0), 1220 * MS);
        assert_eq!(late.lag_ns, 120 * MS);
        assert_eq!(late.capture_ns, 1100 * MS);
        // A frame that waited less than every earlier one resets the reference.
        let early = clock.stamp(Some(150.0), 1140 * MS);
        assert_eq!(early.lag_ns, 0);
        let next = clock.stamp(Some(200.0), 1190 * MS);
        assert_eq!(next.lag_ns, 0);
    }

    #[test]
    fn without_growing_driver_timestamps_the_read_time_is_used_and_no_drop_is_counted() {
        for driver in [None, Some(0.0), Some(f64::NAN)] {
            let mut clock = FrameClock::new(Some(50 * MS));
            let a = clock.stamp(driver, 10 * MS);
            let b = clock.stamp(driver, 400 * MS);
            assert_eq!(clock.uses_driver_time(), Some(false), "{driver:?}");
            assert_eq!((a.timestamp_ns, b.timestamp_ns), (10 * MS, 400 * MS));
            assert_eq!(b.dropped_before, 0);
            assert!(!b.from_driver);
        }
        // Decided once per connection: later growing values do not switch back.
        let mut clock = FrameClock::new(None);
        clock.stamp(Some(5.0), MS);
        clock.stamp(Some(5.0), 2 * MS);
        let c = clock.stamp(Some(10.0), 3 * MS);
        assert_eq!((c.from_driver, c.timestamp_ns), (false, 3 * MS));
    }

    #[test]
    fn without_a_period_gaps_are_not_counted() {
        let mut clock = FrameClock::new(None);
        clock.stamp(Some(0.0), 0);
        clock.stamp(Some(50.0), 50 * MS);
        assert_eq!(clock.stamp(Some(500.0), 500 * MS).dropped_before, 0);
    }
}
