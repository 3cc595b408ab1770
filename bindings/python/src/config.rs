//! Settings from Python: keyword arguments and dicts read through the Rust crates' own
//! config types (`deny_unknown_fields`, defaults for what is left out, the same range
//! checks), so a key means what it means in `configs/frontend.toml` and
//! `configs/l1-matcher.toml`.

use linetrack_frontend_core::{EdgeLinesOptions, LineOptions};
use linetrack_l1_matcher::{ConfigError, MatcherConfig};
use pyo3::exceptions::{PyOSError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyString, PyTuple};
use serde::de::DeserializeOwned;
use std::path::PathBuf;

/// The keys of `detect_lines` that belong to `[lines]`; the others are `[edgelines]`'s.
const LINE_KEYS: [&str; 2] = ["max_segments", "min_length_px"];

/// A Python value as TOML: bool, int, float, str, and dicts and lists of them. `at` names
/// the value in errors.
fn to_toml(value: &Bound<'_, PyAny>, at: &str) -> PyResult<toml::Value> {
    if let Ok(b) = value.cast::<PyBool>() {
        return Ok(toml::Value::Boolean(b.is_true()));
    }
    if let Ok(s) = value.cast::<PyString>() {
        return Ok(toml::Value::String(s.to_cow()?.into_owned()));
    }
    if let Ok(dict) = value.cast::<PyDict>() {
        return dict_to_toml(dict, at).map(toml::Value::Table);
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items = value
            .try_iter()?
            .enumerate()
            .map(|(k, item)| to_toml(&item?, &format!("{at}[{k}]")))
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(toml::Value::Array(items));
    }
    if let Ok(i) = value.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = value.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    let type_name = value
        .get_type()
        .name()
        .map_or_else(|_| "?".to_string(), |n| n.to_string());
    Err(PyTypeError::new_err(format!(
        "{at}: a {type_name} is not a setting (expected bool, int, float, str, dict or list)"
    )))
}

fn dict_to_toml(dict: &Bound<'_, PyDict>, at: &str) -> PyResult<toml::Table> {
    let mut table = toml::Table::new();
    for (key, value) in dict.iter() {
        let key: String = key
            .extract()
            .map_err(|_| PyTypeError::new_err(format!("{at}: keys must be strings")))?;
        let name = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        table.insert(key, to_toml(&value, &name)?);
    }
    Ok(table)
}

/// Deserialises `table` as `T`; errors say `what` and serde's message (which names the
/// field, or lists the known ones for an unknown field), `more` after an unknown field's.
fn from_table<T: DeserializeOwned>(table: toml::Table, what: &str, more: &str) -> PyResult<T> {
    toml::Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| {
            let message = e.to_string().trim_end().replace('\n', " ");
            let more = if message.starts_with("unknown field") {
                more
            } else {
                ""
            };
            PyValueError::new_err(format!("{what}: {message}{more}"))
        })
}

/// The detector's settings from `detect_lines`' keyword arguments, checked.
pub fn detector_settings(
    max_segments: Option<&Bound<'_, PyAny>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<(EdgeLinesOptions, LineOptions)> {
    let mut all = match settings {
        Some(dict) => dict_to_toml(dict, "")?,
        None => toml::Table::new(),
    };
    if let Some(value) = max_segments.filter(|v| !v.is_none()) {
        all.insert("max_segments".to_string(), to_toml(value, "max_segments")?);
    }
    let (mut lines, mut edgelines) = (toml::Table::new(), toml::Table::new());
    for (key, value) in all {
        if LINE_KEYS.contains(&key.as_str()) {
            lines.insert(key, value);
        } else {
            edgelines.insert(key, value);
        }
    }
    let what = "detect_lines settings";
    let lines: LineOptions = from_table(lines, what, "")?;
    let more = ", or `max_segments`, `min_length_px`";
    let edgelines: EdgeLinesOptions = from_table(edgelines, what, more)?;
    lines
        .validate()
        .and_then(|()| edgelines.validate())
        .map_err(|e| PyValueError::new_err(format!("{what}: {e}")))?;
    Ok((edgelines, lines))
}

/// The matcher's configuration: the defaults (`None`), a dict with the keys of
/// `configs/l1-matcher.toml`, or the path of such a file.
pub fn matcher_config(config: Option<&Bound<'_, PyAny>>) -> PyResult<MatcherConfig> {
    let Some(config) = config.filter(|c| !c.is_none()) else {
        return Ok(MatcherConfig::default());
    };
    let parsed = if let Ok(dict) = config.cast::<PyDict>() {
        let parsed: MatcherConfig = from_table(dict_to_toml(dict, "")?, "config", "")?;
        parsed.validate().map(|()| parsed)
    } else if let Ok(path) = config.extract::<PathBuf>() {
        MatcherConfig::from_file(&path)
    } else {
        return Err(PyTypeError::new_err(
            "config must be None, a dict or the path of a TOML file (str or os.PathLike)",
        ));
    };
    parsed.map_err(|e| match e {
        ConfigError::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    })
}
