//! The recorder: an optional process of the pipeline that subscribes to the frames,
//! segments, tracks, poses, status and rig topics and writes them into one MCAP file
//! (`linetrack-mcap`), started by the supervisor when the config says `[record] mcap = true`.
//!
//! It never holds the pipeline up: it sleeps on its own iceoryx2 event service, which the
//! publishers of the topics it records notify (a notification costs them no wait), and
//! empties its queues when woken; iceoryx2 overwrites the oldest message of a subscriber
//! whose queue is full, so a recorder that falls behind loses frames from its recording,
//! which it counts ([`linetrack_stage_runtime::GapWatch`]), and the stages go
//! on. On a shutdown (command or signal) it writes what its queues still hold, then closes
//! the file with its index and summary.

#[cfg(feature = "mcap")]
mod recorder;
#[cfg(feature = "mcap")]
pub use recorder::run;

/// Without the `mcap` feature there is no recorder: says so.
#[cfg(not(feature = "mcap"))]
pub fn run(
    _ctx: &linetrack_stage_runtime::StageContext,
    _bus: &linetrack_ipc::Bus,
    _shutdown: &linetrack_ipc::Shutdown,
) -> anyhow::Result<()> {
    anyhow::bail!("this build has no MCAP recorder: build with --features linetrack-recorder/mcap")
}
