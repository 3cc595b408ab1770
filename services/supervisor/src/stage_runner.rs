//! The stage runner: a command put before each stage binary the supervisor starts.
//!
//! Set `LINETRACK_STAGE_RUNNER` when the stage binaries cannot be executed directly, e.g.
//! aarch64 binaries on an x86 machine without binfmt_misc:
//! `LINETRACK_STAGE_RUNNER="qemu-aarch64-static -L /path/to/arm64-sysroot"`. The value is
//! split into words as a POSIX shell would (quotes keep spaces), and each stage is started
//! as `RUNNER… linetrack-<stage> ARGS…`. The runner must execute the binary in its own
//! process (qemu-user does), so that the pid the supervisor signals is the stage's.

use std::ffi::OsString;
use std::process::Command;

/// The environment variable naming the runner.
pub const STAGE_RUNNER_VAR: &str = "LINETRACK_STAGE_RUNNER";

/// Why the runner cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum StageRunnerError {
    /// The variable is not valid UTF-8.
    #[error("{STAGE_RUNNER_VAR} is not valid UTF-8: {0:?}")]
    NotUtf8(OsString),
    /// The variable's quoting is unbalanced (or it ends in a lone backslash).
    #[error("{STAGE_RUNNER_VAR}={0:?}: unbalanced quotes; write it as a shell command line")]
    Unbalanced(String),
}

/// A runner command (program and arguments), or none: stages are executed directly.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct StageRunner {
    words: Vec<String>,
}

impl StageRunner {
    /// The runner `LINETRACK_STAGE_RUNNER` names (none when unset or blank).
    pub fn from_env() -> Result<Self, StageRunnerError> {
        match std::env::var_os(STAGE_RUNNER_VAR) {
            None => Ok(Self::default()),
            Some(value) => Self::parse(
                value
                    .to_str()
                    .ok_or_else(|| StageRunnerError::NotUtf8(value.clone()))?,
            ),
        }
    }

    /// Splits a command line into the runner's words (none for a blank line).
    pub fn parse(line: &str) -> Result<Self, StageRunnerError> {
        let words =
            shlex::split(line).ok_or_else(|| StageRunnerError::Unbalanced(line.to_string()))?;
        Ok(Self { words })
    }

    /// Whether stages are executed directly.
    pub fn is_direct(&self) -> bool {
        self.words.is_empty()
    }

    /// The command that starts `program`: `program` itself, or the runner with `program` as
    /// its last argument so far.
    pub fn command(&self, program: &std::path::Path) -> Command {
        match self.words.split_first() {
            None => Command::new(program),
            Some((runner, args)) => {
                let mut command = Command::new(runner);
                command.args(args).arg(program);
                command
            }
        }
    }
}

impl std::fmt::Display for StageRunner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&shlex::try_join(self.words.iter().map(String::as_str)).unwrap_or_default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn argv(command: &Command) -> Vec<String> {
        std::iter::once(command.get_program())
            .chain(command.get_args())
            .map(|s| s.to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn no_runner_starts_the_binary_itself() {
        let runner = StageRunner::parse("  ").unwrap();
        assert!(runner.is_direct());
        let mut command = runner.command(Path::new("/bin/linetrack-matcher"));
        command.arg("--config");
        assert_eq!(argv(&command), ["/bin/linetrack-matcher", "--config"]);
    }

    #[test]
    fn a_runner_goes_before_the_binary_with_quoted_words_kept_whole() {
        let runner = StageRunner::parse("qemu-aarch64-static -L '/opt/arm 64/root'").unwrap();
        assert!(!runner.is_direct());
        let mut command = runner.command(Path::new("/b/linetrack-matcher"));
        command.arg("--config");
        assert_eq!(
            argv(&command),
            [
                "qemu-aarch64-static",
                "-L",
                "/opt/arm 64/root",
                "/b/linetrack-matcher",
                "--config"
            ]
        );
        assert_eq!(
            runner.to_string(),
            "qemu-aarch64-static -L '/opt/arm 64/root'"
        );
    }

    #[test]
    fn unbalanced_quotes_are_refused_naming_the_variable() {
        let error = StageRunner::parse("qemu-aarch64 -L '/opt").unwrap_err();
        assert!(error.to_string().contains(STAGE_RUNNER_VAR), "{error}");
    }
}
