//! Config input with bounds: what `--config` names is read only when it is a regular file
//! of at most [`MAX_CONFIG_BYTES`] (a FIFO, a device such as `/dev/zero` or a folder is
//! refused without being read: the file is opened non-blocking and judged by `fstat`), and
//! an error quotes a value at most once, cut to [`QUOTE_CHARS`] characters.

use crate::ConfigError;
use std::io::Read as _;
use std::os::unix::fs::{FileTypeExt as _, OpenOptionsExt as _};
use std::path::Path;

/// The largest config file read (the shipped one is 12 KiB).
pub const MAX_CONFIG_BYTES: u64 = 1024 * 1024;
/// Characters of a quoted value kept in an error message.
pub const QUOTE_CHARS: usize = 80;
/// Characters of unquoted text kept between quotes in an error message.
const TEXT_CHARS: usize = 1000;

/// The text of the config file `path`, refused (naming it) unless it is a regular file of at
/// most [`MAX_CONFIG_BYTES`] in UTF-8.
pub fn read_bounded(path: &Path) -> Result<String, ConfigError> {
    let read_error = |source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    };
    let refuse = |message: String| ConfigError::Invalid {
        origin: path.display().to_string(),
        message,
    };
    // Non-blocking: opening a FIFO for reading would otherwise wait for a writer.
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(path)
        .map_err(read_error)?;
    let meta = file.metadata().map_err(read_error)?;
    let kind = meta.file_type();
    if !kind.is_file() {
        let what = if kind.is_dir() {
            "a folder"
        } else if kind.is_fifo() {
            "a FIFO"
        } else if kind.is_char_device() {
            "a character device"
        } else if kind.is_block_device() {
            "a block device"
        } else if kind.is_socket() {
            "a socket"
        } else {
            "not a file"
        };
        return Err(refuse(format!(
            "is {what}, not a regular file: a config is read from a file"
        )));
    }
    let too_big = |size: u64| {
        refuse(format!(
            "is {size} bytes, more than a config's {MAX_CONFIG_BYTES}"
        ))
    };
    if meta.len() > MAX_CONFIG_BYTES {
        return Err(too_big(meta.len()));
    }
    // A file growing while it is read is still cut at the limit.
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(MAX_CONFIG_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(read_error)?;
    if bytes.len() as u64 > MAX_CONFIG_BYTES {
        return Err(too_big(bytes.len() as u64));
    }
    String::from_utf8(bytes).map_err(|e| {
        refuse(format!(
            "is not UTF-8 text (byte {} is not)",
            e.utf8_error().valid_up_to()
        ))
    })
}

/// `e` for `text` as `line L, column C: message`, with quoted values cut ([`cut_quotes`]):
/// the parser's own rendering repeats the offending line, and with it the value.
pub fn parse_message(e: &toml::de::Error, text: &str) -> String {
    let message = cut_quotes(e.message().trim_end());
    match e.span() {
        Some(span) => {
            let before = &text.as_bytes()[..span.start.min(text.len())];
            let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
            let column = before.iter().rev().take_while(|&&b| b != b'\n').count() + 1;
            format!("line {line}, column {column}: {message}")
        }
        None => message,
    }
}

/// `message` with every quoted part (between `` ` `` or `"`) longer than [`QUOTE_CHARS`]
/// characters cut to that many, saying how much was left out; unquoted text (the message's
/// own words) is cut past [`TEXT_CHARS`].
pub fn cut_quotes(message: &str) -> String {
    let mut out = String::with_capacity(message.len().min(4 * QUOTE_CHARS));
    let mut rest = message;
    while let Some(open) = rest.find(['`', '"']) {
        let quote = rest[open..].chars().next().unwrap_or('"');
        out.push_str(&cut(&rest[..open], TEXT_CHARS));
        out.push(quote);
        let inside = &rest[open + 1..];
        let (quoted, after) = match inside.find(quote) {
            Some(close) => (&inside[..close], &inside[close..]),
            None => (inside, ""),
        };
        out.push_str(&cut(quoted, QUOTE_CHARS));
        rest = after;
        if let Some(close) = rest.chars().next() {
            out.push(close);
            rest = &rest[close.len_utf8()..];
        }
    }
    out.push_str(&cut(rest, TEXT_CHARS));
    out
}

/// `text` cut to `chars` characters, saying how many bytes were left out.
fn cut(text: &str, chars: usize) -> String {
    match text.char_indices().nth(chars) {
        Some((at, _)) => format!("{}… ({} more bytes)", &text[..at], text.len() - at),
        None => text.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refusal(path: &Path) -> String {
        read_bounded(path)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_else(|| format!("{} was read", path.display()))
    }

    #[test]
    fn only_a_regular_file_of_bounded_size_is_read() {
        let scratch = linetrack_test_data::Scratch::new("pipeline-config", "input");
        let dir = scratch.path();
        // A FIFO with no writer: reading it would block forever; it is refused unread.
        let fifo = dir.join("fifo.toml");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap_or_else(|e| panic!("mkfifo: {e}"));
        assert!(made.success());
        let err = refusal(&fifo);
        assert!(err.contains("fifo.toml") && err.contains("a FIFO"), "{err}");
        let err = refusal(Path::new("/dev/zero"));
        assert!(
            err.contains("/dev/zero") && err.contains("character device"),
            "{err}"
        );
        assert!(refusal(dir).contains("a folder"));
        let big = dir.join("big.toml");
        std::fs::write(&big, vec![b'#'; MAX_CONFIG_BYTES as usize + 1])
            .unwrap_or_else(|e| panic!("{e}"));
        let err = refusal(&big);
        assert!(
            err.contains("big.toml") && err.contains("1048577 bytes"),
            "{err}"
        );
        let fine = dir.join("fine.toml");
        std::fs::write(&fine, "detector = \"fld\"\n").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            read_bounded(&fine).ok().as_deref(),
            Some("detector = \"fld\"\n")
        );
    }

    #[test]
    fn a_long_value_is_quoted_once_and_cut() {
        let value = "x".repeat(900_000);
        let text = format!("[source]\npacing = \"{value}\"\n");
        let err = crate::PipelineConfig::from_toml_str(&text, "big.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.len() < 1000, "{} bytes of error", err.len());
        assert!(err.starts_with("big.toml: line 2, column"), "{err}");
        assert_eq!(err.matches(&"x".repeat(QUOTE_CHARS)).count(), 1, "{err}");
        assert!(err.contains("more bytes"), "{err}");
        assert_eq!(
            cut_quotes("a `short` and \"also short\""),
            "a `short` and \"also short\""
        );
    }
}
