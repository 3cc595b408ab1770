//! Config input a user (or a mistake) can hand `linetrack run --config`: a FIFO nobody
//! writes (reading it would block forever), `/dev/zero` (endless), a file over the size
//! cap, a 900 KB value (echoed three times before), and `[output] run_dir = ""` (the
//! current folder). Each is refused before any stage starts, naming the file or the key,
//! with an error of bounded size that quotes the value at most once.

use linetrack_e2e::*;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Long enough for any machine; only a blocked read reaches it.
const DEADLINE: Duration = Duration::from_secs(60);

/// `linetrack run --config config`: its stderr, after checking it failed (killed and
/// failed when it has not ended by the deadline).
fn refused(config: &Path) -> String {
    let mut child = Command::new(bin_dir().join("linetrack"))
        .args(["run", "--quiet", "--config"])
        .arg(config)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("linetrack: {e}"));
    let until = Instant::now() + DEADLINE;
    let status = loop {
        if let Ok(Some(status)) = child.try_wait() {
            break status;
        }
        if Instant::now() > until {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "--config {}: still running after {DEADLINE:?}",
                config.display()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    if let Some(mut pipe) = child.stderr.take() {
        use std::io::Read as _;
        let _ = pipe.read_to_string(&mut stderr);
    }
    assert!(
        !status.success(),
        "--config {} was accepted",
        config.display()
    );
    assert!(!stderr.contains("started"), "a stage started:\n{stderr}");
    stderr
}

#[test]
fn a_fifo_a_device_a_huge_file_a_huge_value_and_an_empty_run_dir_are_refused_at_once() {
    let dir = scratch("config-input");
    let fifo = dir.join("fifo.toml");
    let made = Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap_or_else(|e| panic!("mkfifo: {e}"));
    assert!(made.success());
    let err = refused(&fifo);
    assert!(
        err.contains("fifo.toml: is a FIFO, not a regular file"),
        "{err}"
    );
    let err = refused(Path::new("/dev/zero"));
    assert!(err.contains("/dev/zero: is a character device"), "{err}");
    let big = dir.join("big.toml");
    std::fs::write(&big, vec![b'#'; 2 * 1024 * 1024]).unwrap_or_else(|e| panic!("{e}"));
    let err = refused(&big);
    assert!(
        err.contains("big.toml: is 2097152 bytes, more than a config's 1048576"),
        "{err}"
    );
    let value = "v".repeat(900_000);
    let long = dir.join("long.toml");
    std::fs::write(&long, format!("detector = \"{value}\"\n")).unwrap_or_else(|e| panic!("{e}"));
    let err = refused(&long);
    assert!(err.contains("long.toml: line 1, column"), "{err}");
    assert!(err.len() < 4096, "{} bytes on stderr", err.len());
    assert_eq!(err.matches(&"v".repeat(80)).count(), 1, "{err}");
    let empty = dir.join("empty.toml");
    std::fs::write(&empty, "[output]\nrun_dir = \"\"\n").unwrap_or_else(|e| panic!("{e}"));
    let err = refused(&empty);
    assert!(err.contains("output.run_dir = \"\""), "{err}");
}
