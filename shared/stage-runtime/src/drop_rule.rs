//! The budget policy a stage applies to each frame it takes (`[budget]`): whether the frame
//! is dropped instead of processed, and why. The one place the rule lives.
//!
//! With `drop_late` (else every frame is processed):
//! - a frame with a newer one queued behind it is dropped `behind`: with `behind =
//!   "newest"` always; with `behind = "deadline"` (default) only when it cannot make the
//!   end-to-end budget, its age plus what the pipeline still needs for it over
//!   `end_to_end_ms`. What it still needs is this stage's recent time a frame
//!   ([`WorkTime`]) times the processing stages left, this one included: the stage knows
//!   its own time, not the others'. Near saturation a moment's jitter (another process's
//!   time slice) queues two frames; the older one often still has the time, and dropping it
//!   loses a frame the average capacity could carry;
//! - a frame already over `end_to_end_ms` is dropped `late`.

use linetrack_msgs::{FrameHeader, FrameStatus, StageKind};
use linetrack_pipeline_config::{BehindRule, BudgetConfig};

/// The weight of a frame's time in [`WorkTime`]'s running mean: the last eight frames or so
/// make the estimate, so one slow frame moves it an eighth of the way.
const NEWEST_WEIGHT: f64 = 0.125;

/// A stage's recent wall time a frame, from taking the frame to its result: an exponential
/// running mean of the frames it processed (dropped frames take no time).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WorkTime {
    mean_ms: Option<f64>,
}

impl WorkTime {
    /// Takes the time of one more processed frame, milliseconds.
    pub fn observe(&mut self, ms: f64) {
        self.mean_ms = Some(match self.mean_ms {
            Some(mean) => mean + NEWEST_WEIGHT * (ms - mean),
            None => ms,
        });
    }

    /// The running mean, milliseconds (`None` before the first frame).
    pub fn mean_ms(&self) -> Option<f64> {
        self.mean_ms
    }
}

/// A stage's recent time a frame kept apart for the two kinds of frame a stage that prepares
/// ahead ([`Stage::prepare`](crate::Stage::prepare)) takes: those whose images it prepared
/// while it waited (the pose estimator's corners found: a few milliseconds left) and those
/// it did not (the whole work). One mean of both would overestimate what a prepared frame
/// still needs, and drop it behind when it could make the budget, and underestimate an
/// unprepared one. A stage that does not prepare has only the second kind.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WorkTimes {
    prepared: WorkTime,
    unprepared: WorkTime,
}

impl WorkTimes {
    /// Takes the time of one more processed frame of its kind, milliseconds.
    pub fn observe(&mut self, prepared: bool, ms: f64) {
        if prepared {
            self.prepared.observe(ms);
        } else {
            self.unprepared.observe(ms);
        }
    }

    /// What to expect for a frame of this kind: its kind's mean. Before a prepared frame was
    /// timed, the unprepared frames' mean (the whole work: never less than the frame needs);
    /// before an unprepared one was, no estimate (newest wins, as before any frame).
    pub fn expected(&self, prepared: bool) -> &WorkTime {
        if prepared && self.prepared.mean_ms().is_some() {
            &self.prepared
        } else {
            &self.unprepared
        }
    }
}

/// The processing stages from `stage` to the end of the pipeline, `stage` included (1 for a
/// node that is not a processing stage).
pub fn stages_left(stage: StageKind) -> usize {
    let all = StageKind::PROCESSING;
    all.iter()
        .position(|&s| s == stage)
        .map_or(1, |at| all.len() - at)
}

/// The budget policy for a frame `stage` is about to take: `Some(status)` when it must be
/// dropped instead. `newer_waiting` says whether a newer frame is already queued behind it;
/// `work` is the stage's recent time a frame; `now_ns` is the stage's clock.
pub fn late_drop(
    header: &FrameHeader,
    newer_waiting: bool,
    budget: &BudgetConfig,
    stage: StageKind,
    work: &WorkTime,
    now_ns: u64,
) -> Option<FrameStatus> {
    if !budget.drop_late {
        return None;
    }
    let age_ms = header.age_ms(now_ns);
    if newer_waiting {
        let makes_it = match budget.behind {
            BehindRule::Newest => false,
            BehindRule::Deadline => work
                .mean_ms()
                .is_some_and(|ms| age_ms + ms * stages_left(stage) as f64 <= budget.end_to_end_ms),
        };
        if !makes_it {
            return Some(FrameStatus::DroppedBehind);
        }
    }
    (age_ms > budget.end_to_end_ms).then_some(FrameStatus::DroppedLate)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW_NS: u64 = 10_000_000_000;

    /// A frame `age_ms` old at [`NOW_NS`].
    fn aged(age_ms: u64) -> FrameHeader {
        FrameHeader::new(1, 0, NOW_NS - age_ms * 1_000_000)
    }

    fn budget(behind: BehindRule) -> BudgetConfig {
        BudgetConfig {
            end_to_end_ms: 100.0,
            behind,
            ..BudgetConfig::default()
        }
    }

    fn timed(ms: f64) -> WorkTime {
        let mut work = WorkTime::default();
        work.observe(ms);
        work
    }

    #[test]
    fn prepared_and_unprepared_frames_are_timed_apart() {
        let mut times = WorkTimes::default();
        assert_eq!(times.expected(false).mean_ms(), None);
        assert_eq!(times.expected(true).mean_ms(), None);
        times.observe(false, 40.0);
        assert_eq!(
            times.expected(true).mean_ms(),
            Some(40.0),
            "no prepared frame timed yet: the whole work"
        );
        times.observe(true, 2.0);
        times.observe(false, 48.0);
        assert_eq!(times.expected(true).mean_ms(), Some(2.0));
        assert_eq!(times.expected(false).mean_ms(), Some(41.0));
        let mut only_prepared = WorkTimes::default();
        only_prepared.observe(true, 2.0);
        assert_eq!(
            only_prepared.expected(false).mean_ms(),
            None,
            "a prepared frame's time says nothing of the whole work"
        );
    }

    #[test]
    fn the_stages_left_count_the_stage_itself_and_those_after_it() {
        assert_eq!(stages_left(StageKind::FrameSource), 4);
        assert_eq!(stages_left(StageKind::LineDetector), 3);
        assert_eq!(stages_left(StageKind::Matcher), 2);
        assert_eq!(stages_left(StageKind::PoseEstimator), 1);
        assert_eq!(stages_left(StageKind::Supervisor), 1);
    }

    #[test]
    fn the_work_time_follows_the_recent_frames() {
        let mut work = WorkTime::default();
        assert_eq!(work.mean_ms(), None);
        work.observe(8.0);
        assert_eq!(work.mean_ms(), Some(8.0), "the first frame is the estimate");
        work.observe(16.0);
        assert_eq!(
            work.mean_ms(),
            Some(9.0),
            "an eighth of the way to a slow frame"
        );
        for _ in 0..100 {
            work.observe(20.0);
        }
        assert!(work.mean_ms().is_some_and(|ms| (ms - 20.0).abs() < 1e-3));
    }

    /// Newest wins: an older frame with a newer one behind it is dropped however young.
    #[test]
    fn newest_drops_every_frame_with_a_newer_one_behind() {
        let budget = budget(BehindRule::Newest);
        let fast = timed(1.0);
        let drop = |newer_waiting| {
            late_drop(
                &aged(1),
                newer_waiting,
                &budget,
                StageKind::PoseEstimator,
                &fast,
                NOW_NS,
            )
        };
        assert_eq!(drop(true), Some(FrameStatus::DroppedBehind));
        assert_eq!(drop(false), None);
    }

    /// Deadline: the older frame is kept while its age plus the stage's time for each stage
    /// left fits the budget, and dropped behind from the first millisecond it does not.
    #[test]
    fn deadline_drops_an_older_frame_only_when_it_cannot_make_the_budget() {
        let budget = budget(BehindRule::Deadline);
        let work = timed(20.0);
        let drop = |stage, age_ms| late_drop(&aged(age_ms), true, &budget, stage, &work, NOW_NS);
        // Pose estimator: 1 stage left, 20 ms: room up to 80 ms of age.
        assert_eq!(drop(StageKind::PoseEstimator, 80), None);
        assert_eq!(
            drop(StageKind::PoseEstimator, 81),
            Some(FrameStatus::DroppedBehind)
        );
        // Line detector: 3 stages left at its 20 ms: room up to 40 ms.
        assert_eq!(drop(StageKind::LineDetector, 40), None);
        assert_eq!(
            drop(StageKind::LineDetector, 41),
            Some(FrameStatus::DroppedBehind)
        );
        // Before the stage has timed a frame it does not know what is left: newest wins.
        assert_eq!(
            late_drop(
                &aged(1),
                true,
                &budget,
                StageKind::PoseEstimator,
                &WorkTime::default(),
                NOW_NS
            ),
            Some(FrameStatus::DroppedBehind)
        );
    }

    /// Over the budget is late whatever the rule, unless the newer frame behind makes it a
    /// drop behind (as before the deadline rule); `drop_late = false` keeps every frame.
    #[test]
    fn late_frames_are_dropped_only_under_the_policy() {
        for behind in [BehindRule::Deadline, BehindRule::Newest] {
            let budget = budget(behind);
            let work = timed(0.5);
            let stage = StageKind::Matcher;
            assert_eq!(
                late_drop(&aged(99), false, &budget, stage, &work, NOW_NS),
                None
            );
            assert_eq!(
                late_drop(&aged(101), false, &budget, stage, &work, NOW_NS),
                Some(FrameStatus::DroppedLate)
            );
            assert_eq!(
                late_drop(&aged(101), true, &budget, stage, &work, NOW_NS),
                Some(FrameStatus::DroppedBehind)
            );
            let keep_all = BudgetConfig {
                drop_late: false,
                ..budget
            };
            assert_eq!(
                late_drop(&aged(500), true, &keep_all, stage, &work, NOW_NS),
                None
            );
        }
    }
}
