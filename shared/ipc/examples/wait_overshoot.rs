//! How late a timed wait returns with nothing to wake it: iceoryx2's own listener wait,
//! this crate's [`Wake::wait`] over shared memory and over local channels. A real-time source
//! waits like this for its next frame's time, and publishes that late.
//!
//! `cargo run --release -p linetrack-ipc --example wait_overshoot`

use iceoryx2::prelude::*;
use linetrack_ipc::{Bus, Scope};
use linetrack_msgs::StageKind;
use std::time::{Duration, Instant};

/// Timeouts of 3 to 19 ms, 40 waits: how much later than asked each returned, ms.
fn overshoot(mut wait: impl FnMut(Duration)) -> Vec<f64> {
    let mut late: Vec<f64> = (0..40u64)
        .map(|k| {
            let timeout = Duration::from_micros(3000 + 1000 * (k % 17));
            let began = Instant::now();
            wait(timeout);
            (began.elapsed().as_secs_f64() - timeout.as_secs_f64()) * 1e3
        })
        .collect();
    late.sort_by(f64::total_cmp);
    late
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()?;
    let name = format!("linetrack-wait-overshoot-{}", std::process::id());
    let service = node
        .service_builder(&name.as_str().try_into()?)
        .event()
        .open_or_create()?;
    let listener = service.listener_builder().create()?;
    let scope = Scope::new(&format!("overshoot{}", std::process::id()));
    let shm = Bus::shared_memory(&scope, "overshoot")?.wake(StageKind::FrameSource)?;
    // The bus is kept: a wake whose bus is gone has nobody to wait for and returns at once.
    let local_bus = Bus::local();
    let local = local_bus.wake(StageKind::FrameSource)?;
    let runs: [(&str, Vec<f64>); 3] = [
        (
            "iceoryx2 Listener::timed_wait",
            overshoot(|t| {
                let _ = listener.timed_wait(|_| {}, t);
            }),
        ),
        (
            "Wake::wait, shared memory",
            overshoot(|t| shm.wait(t).unwrap_or(())),
        ),
        (
            "Wake::wait, local",
            overshoot(|t| local.wait(t).unwrap_or(())),
        ),
    ];
    println!("late after the timeout, ms (40 waits of 3-19 ms)");
    for (what, late) in runs {
        println!(
            "{what:32} p10 {:.2}  p50 {:.2}  p90 {:.2}  max {:.2}",
            late[4], late[20], late[36], late[39]
        );
    }
    Ok(())
}
