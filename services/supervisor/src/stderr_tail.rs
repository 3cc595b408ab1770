//! The last lines a stage process wrote to stderr, kept so that its death can be explained.
//!
//! A stage's stderr is a pipe read by a thread of the supervisor: each line is passed on to
//! the supervisor's own stderr as it comes (the user still sees every line live) and the
//! last [`TAIL_LINES`] are kept, each cut at [`MAX_LINE_CHARS`]. When the stage dies, its
//! tail goes into the `crash` event and into the error that ends the run, so a stage that
//! dies while starting says why.

use std::collections::VecDeque;
use std::io::{BufRead as _, BufReader, Read, Write as _};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// Lines kept.
pub const TAIL_LINES: usize = 12;
/// Characters kept of one line (a longer one is cut, marked with `…`).
pub const MAX_LINE_CHARS: usize = 400;
/// Bytes read of one line at most (the rest of a longer line is skipped).
const READ_LINE_BYTES: u64 = 64 * 1024;

#[derive(Default)]
struct Shared {
    lines: VecDeque<String>,
    /// The pipe reached its end (the process and every holder of the pipe are gone).
    ended: bool,
}

/// The kept tail of one process's stderr.
#[derive(Clone)]
pub struct StderrTail {
    shared: Arc<(Mutex<Shared>, Condvar)>,
}

impl StderrTail {
    /// Follows `stderr` on a thread named after `name` until its end.
    pub fn follow(name: &str, stderr: impl Read + Send + 'static) -> std::io::Result<Self> {
        let tail = Self {
            shared: Arc::default(),
        };
        let shared = Arc::clone(&tail.shared);
        std::thread::Builder::new()
            .name(format!("{name}-stderr"))
            .spawn(move || read_lines(stderr, &shared))?;
        Ok(tail)
    }

    /// The kept lines, oldest first, after waiting up to `wait` for the pipe's end (the
    /// last lines of a process that just died may still be on their way).
    pub fn lines(&self, wait: Duration) -> Vec<String> {
        let (lock, ended) = &*self.shared;
        let Ok(guard) = lock.lock() else {
            return Vec::new();
        };
        let guard = ended
            .wait_timeout_while(guard, wait, |s| !s.ended)
            .map(|(guard, _)| guard);
        guard
            .map(|s| s.lines.iter().cloned().collect())
            .unwrap_or_default()
    }
}

fn read_lines(stderr: impl Read, shared: &(Mutex<Shared>, Condvar)) {
    let mut reader = BufReader::new(stderr);
    let mut line = Vec::new();
    loop {
        line.clear();
        let read = (&mut reader)
            .take(READ_LINE_BYTES)
            .read_until(b'\n', &mut line);
        match read {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
        if !line.ends_with(b"\n") {
            // A line longer than what is read at once: skip to its end.
            let mut rest = Vec::new();
            let _ = reader.read_until(b'\n', &mut rest);
            line.push(b'\n');
        }
        let _ = std::io::stderr().lock().write_all(&line);
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end();
        let kept = match text.char_indices().nth(MAX_LINE_CHARS) {
            Some((cut, _)) if text.len() > MAX_LINE_CHARS => format!("{}…", &text[..cut]),
            _ => text.to_string(),
        };
        if let Ok(mut s) = shared.0.lock() {
            if s.lines.len() == TAIL_LINES {
                s.lines.pop_front();
            }
            s.lines.push_back(kept);
        }
    }
    if let Ok(mut s) = shared.0.lock() {
        s.ended = true;
    }
    shared.1.notify_all();
}

/// `lines` as the words after a death: `; its last words on stderr: a | b`, or that it
/// wrote nothing.
pub fn last_words(lines: &[String]) -> String {
    let said: Vec<&str> = lines
        .iter()
        .map(|l| l.trim())
        .filter(|l| !l.is_empty())
        .collect();
    if said.is_empty() {
        "; it wrote nothing on stderr".to_string()
    } else {
        format!("; its last words on stderr: {}", said.join(" | "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_lines_are_kept_and_cut_and_the_end_is_awaited() {
        let long = "x".repeat(MAX_LINE_CHARS * 3);
        let mut text = String::new();
        for k in 0..20 {
            text.push_str(&format!("line {k}\n"));
        }
        text.push_str(&long);
        text.push_str("\nERROR cannot open the device: no such file\nno end of line");
        let tail = StderrTail::follow("test", std::io::Cursor::new(text.into_bytes()))
            .unwrap_or_else(|e| panic!("{e}"));
        // Waits for the end of the pipe (a cursor ends at once; a minute is never reached).
        let lines = tail.lines(Duration::from_secs(60));
        assert_eq!(lines.len(), TAIL_LINES);
        assert_eq!(lines[0], "line 11");
        assert_eq!(
            lines[TAIL_LINES - 3].chars().count(),
            MAX_LINE_CHARS + 1,
            "cut, with a mark"
        );
        assert_eq!(lines[TAIL_LINES - 1], "no end of line");
        let words = last_words(&lines[TAIL_LINES - 2..]);
        assert_eq!(
            words,
            "; its last words on stderr: ERROR cannot open the device: no such file | no end of line"
        );
        assert_eq!(last_words(&[]), "; it wrote nothing on stderr");
    }
}
