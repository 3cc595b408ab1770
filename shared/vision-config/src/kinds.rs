//! The line detectors and segment matchers that can be chosen by name, in configs and on
//! the command line.

use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// The detectors that can be chosen by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetectorKind {
    /// Line Segment Detector (von Gioi et al.), OpenCV imgproc.
    Lsd,
    /// Fast Line Detector (Lee et al.), OpenCV ximgproc.
    Fld,
    /// Our own edge-drawing detector with line fitting while drawing (`linetrack-edge-lines`,
    /// no OpenCV).
    #[serde(rename = "edgelines")]
    EdgeLines,
}

impl DetectorKind {
    /// Every kind, in a fixed order.
    pub const ALL: [DetectorKind; 3] = [
        DetectorKind::Lsd,
        DetectorKind::Fld,
        DetectorKind::EdgeLines,
    ];

    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DetectorKind::Lsd => "lsd",
            DetectorKind::Fld => "fld",
            DetectorKind::EdgeLines => "edgelines",
        }
    }
}

impl FromStr for DetectorKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown detector {s:?}: expected one of lsd, fld, edgelines"))
    }
}

/// The segment matchers that can be chosen by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MatcherKind {
    /// LBD descriptors, mutual best + ratio test.
    Lbd,
    /// The geometric ℓ1 matcher.
    L1,
}

impl MatcherKind {
    /// Every kind, in a fixed order.
    pub const ALL: [MatcherKind; 2] = [MatcherKind::Lbd, MatcherKind::L1];

    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MatcherKind::Lbd => "lbd",
            MatcherKind::L1 => "l1",
        }
    }
}

impl FromStr for MatcherKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown matcher {s:?}: expected one of lbd, l1"))
    }
}
