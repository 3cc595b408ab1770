//! The sink role: a node that takes the pipeline's messages out of it (into a recording,
//! over a link, to another system) and publishes none of them. The runtime owns what every
//! sink shares: its wake-up (opened before the sink subscribes, so that no message comes
//! without one), the ready report once the sink is open, heartbeats counting what it took,
//! the supervisor's stop, one last pass over its queues on a stop, and closing it.
//!
//! A sink only says how it opens ([`run_sink`]'s `open`), what it does with everything
//! waiting ([`Sink::drain`]) and how it closes ([`Sink::finish`]).

use crate::{Reporter, StageContext, shutdown_ordered};
use linetrack_ipc::{Bus, Inlet, Shutdown};
use linetrack_msgs::{Control, StageKind, StatusKind, topics};
use std::time::Duration;

/// One sink's work.
pub trait Sink {
    /// Which node it is.
    const KIND: StageKind;
    /// Whose wake-ups it sleeps on (the consumers of the topics it takes are woken by their
    /// publishers: its own, or the supervisor's for a node that reads what the supervisor
    /// reads).
    const WAKES_WITH: StageKind;

    /// Takes every message waiting on its inputs.
    fn drain(&mut self) -> anyhow::Result<()>;

    /// What it took so far (its heartbeats carry it).
    fn count(&self) -> u64;

    /// The longest it sleeps without a wake-up (besides its heartbeat).
    fn max_sleep(&self) -> Duration {
        Duration::MAX
    }

    /// Closes it, after the last pass.
    fn finish(self) -> anyhow::Result<()>;
}

/// Runs the sink `open` makes on `bus` until a signal or the supervisor's stop; then takes
/// what its queues still hold and closes it, even after a failed pass (whose error is
/// returned unless closing fails).
pub fn run_sink<S: Sink>(
    ctx: &StageContext,
    bus: &Bus,
    shutdown: &Shutdown,
    open: impl FnOnce(&Bus) -> anyhow::Result<S>,
) -> anyhow::Result<()> {
    // Listening before subscribing: no message comes without its wake-up.
    let wake = bus.wake(S::WAKES_WITH)?;
    let mut control: Inlet<Control, ()> = bus.inlet(topics::CONTROL)?;
    let mut sink = open(bus)?;
    let mut reporter = Reporter::new(bus, ctx, 0)?;
    // Subscribed: the supervisor may start what it waits for.
    reporter.report(StatusKind::Ready, 0, 0);
    let mut result = Ok(());
    loop {
        let stop = shutdown.requested() || shutdown_ordered(&mut control, S::KIND, ctx.pid)?;
        // On a stop, one more pass takes what the queues still hold.
        if let Err(e) = sink.drain() {
            result = Err(e);
            break;
        }
        reporter.beat(sink.count());
        if stop {
            break;
        }
        let sleep = reporter
            .until_due()
            .max(Duration::from_millis(1))
            .min(sink.max_sleep());
        if let Err(e) = wake.wait(sleep) {
            result = Err(e.into());
            break;
        }
    }
    sink.finish()?;
    result
}
