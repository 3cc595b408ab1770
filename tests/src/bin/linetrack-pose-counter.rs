//! The pose counter of `tests/added_node.rs` as a process: an observer node added to the
//! pipeline's declaration by the test (`linetrack_e2e::pose_counter`).

fn main() -> std::process::ExitCode {
    linetrack_stage_runtime::stage_main(
        linetrack_msgs::StageKind::Observer,
        linetrack_e2e::pose_counter::run,
    )
}
