//! Every chart the project draws, with [plotters] into PNG files, in one look: a title,
//! axes labelled with their units, a legend beside the plot, white background.
//!
//! - [`Chart`]: series over shared axes — lines (broken where a value is missing), points,
//!   or a rug of ticks along the top (things without a value, such as dropped frames) —
//!   with dashed vertical event lines and horizontal reference lines (budgets). The
//!   evaluation report's curves and trajectories and the pipeline's latency timeline.
//!   [`lines`] and [`scatter`] are the short forms.
//! - [`Distributions`]: one row per group of values (a pipeline stage) on a shared axis,
//!   logarithmic when the spread asks for it, each row a histogram with marked values
//!   (p50, p99) and a limit (the budget).
//! - [`Tracks`]: intervals on parallel tracks over time (spans of processes), coloured by
//!   group (frame), with each group's intervals joined across tracks (a frame's path).
//!
//! Text is set in DejaVu Sans, embedded (`fonts/`, with its licence): no system fonts are
//! needed. Non-finite values are left out; a chart without any data is still written, with
//! its axes and a "no data" note.

#![warn(missing_docs)]

mod axis;

pub use axis::{LOG_SPREAD, Scale};

mod canvas;
mod chart;
mod distributions;
mod tracks;

pub use canvas::{Marker, PALETTE};
pub use chart::{Chart, EventLine, Reference, Series, Style, lines, scatter};
pub use distributions::{Distribution, Distributions};
pub use tracks::{Bar, Link, Tracks};

use canvas::BitMapBackendError;
use plotters::prelude::DrawingAreaErrorKind;
use std::path::PathBuf;

/// Plotting errors.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// plotters could not draw the chart.
    #[error("cannot draw {}", path.display())]
    Draw {
        /// The chart's file.
        path: PathBuf,
        /// What plotters reported.
        #[source]
        source: DrawingAreaErrorKind<BitMapBackendError>,
    },
    /// The PNG could not be encoded or written.
    #[error("cannot write {}", path.display())]
    Write {
        /// The chart's file.
        path: PathBuf,
        /// Why.
        #[source]
        source: image::ImageError,
    },
    /// The embedded font did not load (a broken build).
    #[error("the embedded font cannot be read")]
    Font,
}

#[cfg(test)]
mod tests;
