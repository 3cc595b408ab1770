//! Progress of the long command-line tools (`linetrack-eval`, `linetrack-synth`,
//! `linetrack-vo`, `linetrack-stereo-bench`) on stderr, the same way in each:
//!
//! - stderr is a terminal: an [`indicatif`] bar, `what [=====>    ] done/total (p %)
//!   elapsed, ETA`, with the current step after it; notes are printed above the bar;
//! - stderr is not a terminal (a log file, CI): a plain line at each tenth of the work and
//!   at the end, `what: done/total (p %), s elapsed, ~s left — step`, and the notes;
//! - `--quiet` ([`Progress::quiet`]): nothing at all (errors are the tool's to print).
//!
//! The estimate of the time left assumes the rest goes at the pace so far.
#![warn(missing_docs)]

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::Instant;

/// The paragraph on progress for a tool's `--help`, the work counted in `$units` (a macro so
/// that `concat!` can join it to the tool's own text).
#[macro_export]
macro_rules! progress_help {
    ($units:literal) => {
        concat!(
            "PROGRESS: a bar with the time left on stderr when it is a terminal, otherwise a line per\ntenth of the ",
            $units,
            "; --quiet for none."
        )
    };
}

/// The bar's layout on a terminal.
const BAR_TEMPLATE: &str =
    "{prefix} [{bar:30}] {pos}/{len} ({percent} %) {elapsed} elapsed, ETA {eta} {wide_msg}";

/// Progress of one piece of work counted in units (frames, pairs, …).
pub struct Progress {
    kind: Kind,
}

enum Kind {
    Bar(ProgressBar),
    Lines(Mutex<Lines>),
    Quiet,
}

/// The plain-line reporter: a line per tenth of the work.
struct Lines {
    what: String,
    total: u64,
    done: u64,
    step: String,
    started: Instant,
    /// Tenths of the work reported so far.
    tenths: u64,
    out: Box<dyn Write + Send>,
}

impl Lines {
    fn report(&mut self) {
        let tenths = (self.done * 10).checked_div(self.total).unwrap_or(10);
        if tenths > self.tenths || self.done == self.total {
            self.tenths = tenths;
            let line = plain_line(
                &self.what,
                self.done,
                self.total,
                self.started.elapsed().as_secs_f64(),
                &self.step,
            );
            let _ = writeln!(self.out, "{line}");
        }
    }
}

/// `what: done/total (p %), s elapsed, ~s left — step` (no time left before any progress).
pub fn plain_line(what: &str, done: u64, total: u64, elapsed_s: f64, step: &str) -> String {
    let percent = (100 * done).checked_div(total).unwrap_or(100);
    let mut line = format!("{what}: {done}/{total} ({percent} %), {elapsed_s:.0} s elapsed");
    if done > 0 && done < total {
        let left_s = elapsed_s / done as f64 * (total - done) as f64;
        line.push_str(&format!(", ~{left_s:.0} s left"));
    }
    if !step.is_empty() {
        line.push_str(" — ");
        line.push_str(step);
    }
    line
}

impl Progress {
    /// Progress of `total` units of `what` on stderr: a bar on a terminal, plain lines
    /// otherwise, nothing when `quiet`.
    pub fn new(what: &str, total: u64, quiet: bool) -> Self {
        if quiet {
            return Self::quiet();
        }
        if !std::io::stderr().is_terminal() {
            return Self::lines(what, total, Box::new(std::io::stderr()));
        }
        let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
        if let Ok(style) = ProgressStyle::with_template(BAR_TEMPLATE) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_prefix(what.to_string());
        Self {
            kind: Kind::Bar(bar),
        }
    }

    /// Plain lines to `out` (what [`Progress::new`] does when stderr is not a terminal).
    pub fn lines(what: &str, total: u64, out: Box<dyn Write + Send>) -> Self {
        Self {
            kind: Kind::Lines(Mutex::new(Lines {
                what: what.to_string(),
                total,
                done: 0,
                step: String::new(),
                started: Instant::now(),
                tenths: 0,
                out,
            })),
        }
    }

    /// No progress at all.
    pub fn quiet() -> Self {
        Self { kind: Kind::Quiet }
    }

    fn with_lines(&self, f: impl FnOnce(&mut Lines)) {
        if let Kind::Lines(lines) = &self.kind {
            // A panic elsewhere while holding the lock leaves counters that are still usable.
            let mut lines = lines
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            f(&mut lines);
        }
    }

    /// `units` more done.
    pub fn inc(&self, units: u64) {
        match &self.kind {
            Kind::Bar(bar) => bar.inc(units),
            Kind::Lines(_) => self.with_lines(|l| {
                l.done = (l.done + units).min(l.total);
                l.report();
            }),
            Kind::Quiet => {}
        }
    }

    /// `done` units done in all.
    pub fn set(&self, done: u64) {
        match &self.kind {
            Kind::Bar(bar) => bar.set_position(done),
            Kind::Lines(_) => self.with_lines(|l| {
                l.done = done.min(l.total);
                l.report();
            }),
            Kind::Quiet => {}
        }
    }

    /// What is being done now (shown after the bar, or at the end of the next line).
    pub fn step(&self, step: impl Into<String>) {
        let step = step.into();
        match &self.kind {
            Kind::Bar(bar) => bar.set_message(step),
            Kind::Lines(_) => self.with_lines(|l| l.step = step),
            Kind::Quiet => {}
        }
    }

    /// A line of its own (above the bar on a terminal); nothing when quiet.
    pub fn note(&self, text: &str) {
        match &self.kind {
            Kind::Bar(bar) => bar.println(text),
            Kind::Lines(_) => self.with_lines(|l| {
                let _ = writeln!(l.out, "{text}");
            }),
            Kind::Quiet => {}
        }
    }

    /// Prints `text` to stderr even when quiet (a warning), without breaking the bar.
    pub fn warn(&self, text: &str) {
        match &self.kind {
            Kind::Bar(bar) => bar.suspend(|| eprintln!("{text}")),
            Kind::Lines(_) => self.note(text),
            Kind::Quiet => eprintln!("{text}"),
        }
    }

    /// Ends the bar, leaving its last state on the terminal.
    pub fn finish(&self) {
        if let Kind::Bar(bar) = &self.kind {
            bar.finish();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if let Kind::Bar(bar) = &self.kind
            && !bar.is_finished()
        {
            bar.abandon();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A `Write` whose bytes the test can read.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            self.0
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .extend_from_slice(bytes);
            Ok(bytes.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Shared {
        fn text(&self) -> String {
            String::from_utf8_lossy(
                &self
                    .0
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner),
            )
            .into_owned()
        }
    }

    #[test]
    fn plain_lines_come_once_per_tenth_and_at_the_end() {
        let out = Shared::default();
        let progress = Progress::lines("rendering", 25, Box::new(out.clone()));
        progress.step("frame 1");
        for _ in 0..25 {
            progress.inc(1);
        }
        progress.note("wrote contact-sheet.png");
        let text = out.text();
        let lines: Vec<&str> = text.lines().collect();
        // 25 units: tenths reached at 3, 5, 8, 10, 13, 15, 18, 20, 23, 25.
        assert_eq!(lines.len(), 11, "{text}");
        assert!(lines[0].starts_with("rendering: 3/25 (12 %), "), "{text}");
        assert!(
            lines[0].contains("s left") && lines[0].ends_with(" — frame 1"),
            "{text}"
        );
        assert!(lines[9].starts_with("rendering: 25/25 (100 %)"), "{text}");
        assert!(!lines[9].contains("left"), "{text}");
        assert_eq!(lines[10], "wrote contact-sheet.png");
    }

    #[test]
    fn the_time_left_is_the_pace_so_far_times_the_work_left() {
        assert_eq!(
            plain_line("eval", 30, 120, 60.0, "tracking normal"),
            "eval: 30/120 (25 %), 60 s elapsed, ~180 s left — tracking normal"
        );
        assert_eq!(
            plain_line("eval", 0, 0, 0.0, ""),
            "eval: 0/0 (100 %), 0 s elapsed"
        );
    }
}
