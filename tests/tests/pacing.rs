//! `--pacing fastest` with `[budget] drop_late = false`: the source reads the sequence as
//! fast as it can but waits for the pipeline, so every frame is processed, none overwritten
//! in a stage's full queue (`skipped`) however slow the stages are next to the reading.
//! Nothing here depends on timing: the source outruns LSD on any machine without the wait.

use linetrack_e2e::*;
use std::time::Duration;

const FRAMES: usize = 40;
const RUN_TIMEOUT: Duration = Duration::from_secs(180);

#[test]
fn fastest_pacing_without_late_drops_records_every_frame_with_a_pose() {
    let dir = scratch("fastest-no-drops");
    let config = "[supervisor]\nstatus_every_ms = 0\ndrain_timeout_ms = 30000\n[budget]\ndrop_late = false\n";
    let run = start_with_args(
        &dir,
        &base_sequence(FRAMES),
        config,
        &["--pacing", "fastest"],
    );
    let (exit, out, records) = run.finish(RUN_TIMEOUT);
    assert!(exit.success(), "{exit}\n{out}");
    assert_ids_accounted(&records, FRAMES as u64, &[]);
    let not_posed: Vec<(u64, &str)> = records
        .frames
        .iter()
        .filter(|f| f.outcome != "pose")
        .map(|f| (f.frame_id, f.outcome.as_str()))
        .collect();
    assert!(
        not_posed.is_empty(),
        "frames without a pose: {not_posed:?}\n{out}"
    );
    let skipped = records.events_of("skipped");
    assert!(skipped.is_empty(), "{skipped:?}");
    assert_eq!(records.leftovers, linetrack_ipc::Resources::default());
}
