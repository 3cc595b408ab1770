//! An observer node that is in no shipped declaration: it counts the poses and, when it is
//! stopped, writes each pose's frame id (and the id it ran as) to `pose-counter.txt` in the
//! run folder. `tests/added_node.rs` adds it to the pipeline ([`NODE`], [`run`]) and runs
//! it through the real supervisor, as the process `linetrack-pose-counter` (this crate's
//! binary) and as a thread.

use linetrack_ipc::{Bus, Inlet, Shutdown};
use linetrack_msgs::pipeline::{NodeDecl, Restart, Role, Start};
use linetrack_msgs::{PoseRecord, StageKind, Topic, TracksHeader, topics};
use linetrack_stage_runtime::{Sink, StageContext, run_sink};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Duration;

/// Its entry in the declaration: started with the stages (the source waits for it to be
/// ready), restarted like them, reading the poses.
pub const NODE: NodeDecl = NodeDecl {
    reads: &[Topic::Poses],
    start: Start::WithStages,
    restart: Restart::Backoff,
    ..NodeDecl::new(
        StageKind::Observer,
        Role::Observer,
        "linetrack-pose-counter",
    )
};

/// The file it writes in the run folder.
pub const FILE: &str = "pose-counter.txt";

/// What it counted.
struct PoseCounter {
    poses: Inlet<PoseRecord, TracksHeader>,
    frame_ids: Vec<u64>,
    file: PathBuf,
    id: u32,
}

impl Sink for PoseCounter {
    const KIND: StageKind = StageKind::Observer;
    // An added node is woken by no publisher: it polls (see `max_sleep`).
    const WAKES_WITH: StageKind = StageKind::Observer;

    fn drain(&mut self) -> anyhow::Result<()> {
        for pose in self.poses.receive_all()? {
            self.frame_ids.push(pose.header().frame.frame_id);
        }
        Ok(())
    }

    fn count(&self) -> u64 {
        self.frame_ids.len() as u64
    }

    fn max_sleep(&self) -> Duration {
        Duration::from_millis(5)
    }

    fn finish(self) -> anyhow::Result<()> {
        let mut text = format!("id {}\n", self.id);
        for id in &self.frame_ids {
            let _ = writeln!(text, "{id}");
        }
        std::fs::write(&self.file, text)
            .map_err(|e| anyhow::anyhow!("{}: {e}", self.file.display()))
    }
}

/// The node's code: its binary's `main` and its thread run this.
pub fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    run_sink(ctx, bus, shutdown, |bus| {
        Ok(PoseCounter {
            poses: bus.inlet(topics::POSES)?,
            frame_ids: Vec::new(),
            file: ctx.args.run_dir.join(FILE),
            id: ctx.pid,
        })
    })
}
