//! The hot swap of a stage: a standby instance started, the running one asked to hand
//! over, the standby told to take over (or the swap abandoned when the standby dies first).

use super::{Action, Core, Log};
use linetrack_msgs::{Command, StageKind, StatusReport};
use linetrack_vision::DetectorKind;

/// Frames a standby of `stage` must have seen before the frame it takes over at: the
/// matcher matches each frame with the one before, so its standby first processes (without
/// publishing) the frame before the hand-over.
fn warm_up_frames(stage: StageKind) -> u64 {
    u64::from(stage == StageKind::Matcher)
}

impl Core {
    /// A standby of `stage` reported ready: the running instance is asked to hand over, or,
    /// with none running, the standby takes over at once.
    pub(super) fn on_standby_ready(
        &mut self,
        stage: StageKind,
        report: &StatusReport,
        actions: &mut Vec<Action>,
    ) {
        if let Some(old) = self
            .instances
            .iter()
            .find(|p| p.stage == stage && !p.standby && !p.retiring)
        {
            let old_pid = old.pid;
            actions.push(Action::Log(Log::Info(format!(
                "standby {stage} {} ready holding frames from {}; asking {old_pid} to hand over",
                report.pid, report.frame_id
            ))));
            actions.push(Action::Send {
                stage,
                pid: old_pid,
                command: Command::HandOver,
                value: 0,
                frame_id: report.frame_id + warm_up_frames(stage),
            });
        } else {
            // No running instance to hand over from: take over at once.
            actions.push(Action::Send {
                stage,
                pid: report.pid,
                command: Command::TakeOver,
                value: 0,
                frame_id: report.frame_id,
            });
            self.promote_standby(report.pid, report.frame_id, actions);
        }
    }

    /// The instance `report.pid` of `stage` (running `old_kind`) handed over: the standby
    /// takes over.
    pub(super) fn on_handed_over(
        &mut self,
        stage: StageKind,
        old_kind: Option<DetectorKind>,
        report: &StatusReport,
        actions: &mut Vec<Action>,
    ) {
        if let Some(new_pid) = self
            .instances
            .iter()
            .find(|p| p.standby && p.stage == stage)
            .map(|p| p.pid)
        {
            actions.push(Action::Send {
                stage,
                pid: new_pid,
                command: Command::TakeOver,
                value: 0,
                frame_id: report.frame_id,
            });
            self.promote_standby(new_pid, report.frame_id, actions);
            let detail = match old_kind {
                Some(from) => format!(
                    "{} (pid {}) -> {} (pid {new_pid})",
                    from.name(),
                    report.pid,
                    self.detector.name()
                ),
                None => format!("pid {} -> pid {new_pid}", report.pid),
            };
            actions.push(Action::Record {
                kind: "swap",
                stage: stage.name(),
                frame_id: Some(report.frame_id),
                detail,
            });
        }
    }

    pub(super) fn promote_standby(&mut self, pid: u32, frame_id: u64, actions: &mut Vec<Action>) {
        let mut stage = StageKind::LineDetector;
        if let Some(p) = self.instances.iter_mut().find(|p| p.pid == pid) {
            p.standby = false;
            stage = p.stage;
            if let Some(kind) = p.detector {
                self.detector = kind;
            }
        }
        self.swapping = None;
        self.swap_to = None;
        actions.push(Action::Log(Log::Info(format!(
            "{stage} {pid} takes over at frame {frame_id}"
        ))));
        actions.push(Action::WriteStatus);
    }

    pub(super) fn on_swap_request(&mut self, kind: DetectorKind, actions: &mut Vec<Action>) {
        if self.swapping.is_some() {
            actions.push(Action::Log(Log::Warn(format!(
                "swap to {} refused: a swap is in progress",
                kind.name()
            ))));
        } else if kind == self.detector {
            actions.push(Action::Log(Log::Info(format!(
                "swap to {} ignored: already running",
                kind.name()
            ))));
        } else {
            actions.push(Action::Record {
                kind: "swap-requested",
                stage: "line-detector",
                frame_id: None,
                detail: format!("{} -> {}", self.detector.name(), kind.name()),
            });
            self.start_swap(kind, actions);
        }
    }

    /// Starts a standby detector of `kind`; the running one hands over to it.
    pub(super) fn start_swap(&mut self, kind: DetectorKind, actions: &mut Vec<Action>) {
        self.swap_to = Some(kind);
        self.swapping = Some(StageKind::LineDetector);
        actions.push(self.spawn(StageKind::LineDetector, true));
    }

    /// A fresh instance of `stage` (the detector: of the running kind) to take over.
    pub(super) fn on_swap_stage(&mut self, stage: StageKind, actions: &mut Vec<Action>) {
        if let Some(swapping) = self.swapping {
            actions.push(Action::Log(Log::Warn(format!(
                "swap of the {stage} refused: a swap of the {swapping} is in progress"
            ))));
        } else if !self.hot_swappable(stage) {
            actions.push(Action::Log(Log::Warn(format!(
                "swap of the {stage} refused: it cannot be hot-swapped"
            ))));
        } else if stage == StageKind::LineDetector {
            actions.push(Action::Record {
                kind: "swap-requested",
                stage: stage.name(),
                frame_id: None,
                detail: format!("a fresh {}", self.detector.name()),
            });
            self.start_swap(self.detector, actions);
        } else {
            actions.push(Action::Record {
                kind: "swap-requested",
                stage: stage.name(),
                frame_id: None,
                detail: "a fresh instance".to_string(),
            });
            self.swapping = Some(stage);
            actions.push(self.spawn(stage, true));
        }
    }
}
