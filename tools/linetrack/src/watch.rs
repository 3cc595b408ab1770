//! `linetrack watch`: the far side of the ground-station link (feature `link`).
//!
//! Connects to an onboard `linetrack-link` over zenoh (reconnecting whenever the link comes
//! back), prints the live status line `linetrack run` prints, and records what arrives the
//! way the onboard supervisor does, with the same code ([`Monitor`]): `frames.csv` (one row
//! per frame whose pose message arrived; at the end, `missing` rows for the frames between
//! that never did), `poses.tum`, `events.csv` (the stages' reports the supervisor turns
//! into events, and the link's own `link-up` / `link-down`), `summary.json`; and `link.json`,
//! the messages and bytes received per topic (rewritten every second).

use linetrack_ipc::Shutdown;
use linetrack_link::far::{Received, Receiver};
use linetrack_link::onboard::{LinkCounts, TopicCounts};
use linetrack_link::wire::Message;
use linetrack_pipeline_config::{MatcherPolicy, PipelineConfig};
use linetrack_run_record::RunEnd;
use linetrack_supervisor::monitor::Monitor;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// `linetrack watch`.
#[derive(Debug, clap::Args)]
pub struct WatchArgs {
    /// The onboard link's endpoint (its `[link] listen`).
    #[arg(long, default_value = "tcp/127.0.0.1:7447")]
    pub connect: String,
    /// The onboard link's `[link] key_prefix`.
    #[arg(long, default_value = "linetrack")]
    pub key_prefix: String,
    /// Where the records go (created; earlier records in it are replaced).
    #[arg(long, default_value = "out/watch")]
    pub out: PathBuf,
    /// A pipeline config for the budgets that mark deadline misses in frames.csv (default:
    /// the built-in defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// After the onboard source has finished, stop when nothing arrived for this long,
    /// seconds (frames lost on the link never come).
    #[arg(long, default_value_t = 3.0)]
    pub idle_exit: f64,
    /// Live status period, milliseconds (0: none).
    #[arg(long, default_value_t = 1000)]
    pub status_every_ms: u64,
}

/// How long one wait for a message lasts (the loop then checks the link and the signals).
const TICK: Duration = Duration::from_millis(100);

/// What has arrived, before and after the records start (at the first frame's pose).
struct Watch {
    config: PipelineConfig,
    out: PathBuf,
    monitor: Option<Monitor>,
    /// Events before the first pose: recorded once the records start.
    early_events: Vec<(&'static str, String)>,
    received: LinkCounts,
    undecodable: u64,
    last_message: Instant,
}

impl Watch {
    fn event(&mut self, kind: &'static str, detail: String) {
        match &mut self.monitor {
            Some(m) => m.event(kind, "link", None, detail),
            None => {
                tracing::info!("{kind}: {detail}");
                self.early_events.push((kind, detail));
            }
        }
    }

    fn take(&mut self, message: Message, bytes: usize) -> anyhow::Result<()> {
        let counts: &mut TopicCounts = self
            .received
            .topics
            .entry(message.topic().to_string())
            .or_default();
        counts.sent += 1;
        counts.bytes += bytes as u64;
        self.last_message = Instant::now();
        match message {
            Message::Pose { header, pose } => {
                self.received.frames += 1;
                if self.monitor.is_none() {
                    let mut monitor = Monitor::new(&self.config, header.frame.frame_id, &self.out)?;
                    for (kind, detail) in self.early_events.drain(..) {
                        monitor.event(kind, "link", None, detail);
                    }
                    self.monitor = Some(monitor);
                }
                if let Some(m) = &mut self.monitor {
                    // The onboard supervisor decides the matcher mode: the watch only
                    // records (its own policy is fixed, so it never decides a switch).
                    let _ = m.on_pose(&header, &pose);
                }
            }
            Message::Status { report, .. } => {
                if let (Some(m), Some(stage)) = (&mut self.monitor, report.stage.get().ok()) {
                    m.on_report(&report, stage, &self.config.camera);
                }
            }
            Message::Segments { .. } | Message::Tracks { .. } | Message::Image { .. } => {}
        }
        Ok(())
    }

    fn status_line(&self, connected: bool) -> String {
        let link = format!(
            "link {}  rx {} kB",
            if connected { "up" } else { "down" },
            self.received.topics.values().map(|c| c.bytes).sum::<u64>() / 1000
        );
        match &self.monitor {
            Some(m) => format!("{}  {link}", m.status_line(None)),
            None => format!("waiting for the first frame  {link}"),
        }
    }
}

/// `linetrack watch`.
pub fn watch(args: &WatchArgs) -> anyhow::Result<()> {
    let _logs = linetrack_telemetry::init("watch", "info,zenoh=warn", None)?;
    let mut config = match &args.config {
        Some(path) => PipelineConfig::from_file(path)?,
        None => PipelineConfig::default(),
    };
    if config.matcher.mode == MatcherPolicy::Auto {
        config.matcher.mode = MatcherPolicy::Lbd;
    }
    anyhow::ensure!(
        args.idle_exit.is_finite() && args.idle_exit >= 0.0,
        "--idle-exit {}: expected seconds, 0 or more",
        args.idle_exit
    );
    std::fs::create_dir_all(&args.out)
        .map_err(|e| anyhow::anyhow!("--out {}: {e}", args.out.display()))?;
    let shutdown = Shutdown::on_signals()?;
    let receiver = Receiver::connect(&args.connect, &args.key_prefix)?;
    println!(
        "linetrack watch: {} (keys {}/**), records in {}",
        args.connect,
        args.key_prefix,
        args.out.display()
    );
    let mut w = Watch {
        config,
        out: args.out.clone(),
        monitor: None,
        early_events: Vec::new(),
        received: LinkCounts::default(),
        undecodable: 0,
        last_message: Instant::now(),
    };
    let idle = Duration::from_secs_f64(args.idle_exit);
    let status_every = Duration::from_millis(args.status_every_ms);
    let mut next_status = Instant::now() + status_every;
    let mut next_check = Instant::now();
    let mut connected = false;
    let link_json = args.out.join("link.json");
    let mut next_counts = Instant::now();
    let end = loop {
        if shutdown.requested() {
            break RunEnd::Interrupted;
        }
        match receiver.next(TICK) {
            Some(Received::Message(message, bytes)) => w.take(message, bytes)?,
            Some(Received::Undecodable(e)) => {
                w.undecodable += 1;
                if w.undecodable == 1 {
                    tracing::warn!("{e} (further ones are counted in link.json)");
                }
            }
            None => {}
        }
        let now = Instant::now();
        if now >= next_check {
            let up = receiver.connected();
            if up != connected {
                connected = up;
                let (kind, detail) = if up {
                    ("link-up", format!("connected to {}", args.connect))
                } else {
                    ("link-down", format!("{} lost; reconnecting", args.connect))
                };
                w.event(kind, detail);
            }
            next_check = now + Duration::from_millis(200);
        }
        if now >= next_counts {
            if let Err(e) = w.received.write(&link_json) {
                tracing::warn!("{e}");
            }
            next_counts = now + Duration::from_secs(1);
        }
        if let Some(m) = &w.monitor
            && m.source_done()
            && (m.complete() || w.last_message.elapsed() >= idle)
        {
            break RunEnd::Completed;
        }
        if status_every > Duration::ZERO && now >= next_status {
            println!("{}", w.status_line(connected));
            next_status = now + status_every;
        }
    };
    w.received.write(&link_json)?;
    let Some(monitor) = w.monitor.take() else {
        println!("linetrack watch: no frame arrived");
        return Ok(());
    };
    let report = monitor.finish(end, None)?;
    let missing = report
        .drops
        .iter()
        .find(|(outcome, _)| outcome == "missing")
        .map_or(0, |(_, n)| *n);
    println!(
        "linetrack watch: {} frames, {} tracked, {missing} never arrived over the link, {} undecodable samples; records in {}",
        report.frames,
        report.poses,
        w.undecodable,
        args.out.display()
    );
    Ok(())
}
