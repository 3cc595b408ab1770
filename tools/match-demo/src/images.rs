//! The demo on images: a stereo pair and a pair of consecutive frames of a dataset (or of
//! the default generated sequence), through the real front end, LBD against ℓ1.

use anyhow::Context;
use linetrack_datasets::StereoSequence;
use linetrack_geometry::MatchCase;
use linetrack_scene_render::Preset;
use linetrack_vision::{DetectorKind, FrontendConfig, GrayImage, LinePairMatcher, MatcherKind};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Where the default sequence is generated on first use.
pub const DEFAULT_SEQUENCE: &str = "out/sequences/default";
/// Frames of the default sequence (one second at 20 Hz).
const DEFAULT_FRAMES: usize = 20;

/// The dataset folder to use: `dataset`, or the default sequence, generated if missing.
fn dataset_or_default(dataset: Option<&Path>, text: &mut String) -> anyhow::Result<PathBuf> {
    if let Some(dir) = dataset {
        return Ok(dir.to_path_buf());
    }
    let dir = PathBuf::from(DEFAULT_SEQUENCE);
    if !dir.join("mav0/cam0/data.csv").is_file() {
        eprintln!(
            "generating the default sequence ({DEFAULT_FRAMES} frames, preset normal) in {} (first run only)",
            dir.display()
        );
        let summary = linetrack_synth::generate(Preset::Normal, 1, DEFAULT_FRAMES, &dir, false)?;
        writeln!(text, "{summary}")?;
    }
    Ok(dir)
}

/// Runs LSD or FLD with LBD and ℓ1 on frame `index` (stereo) and `index → index + 1`
/// (frame to frame); writes one picture per combination into `output`.
pub fn run(
    dataset: Option<&Path>,
    index: usize,
    detector: DetectorKind,
    output: &Path,
) -> anyhow::Result<String> {
    let mut text = String::new();
    let dir = dataset_or_default(dataset, &mut text)?;
    let sequence = StereoSequence::open(&dir)
        .with_context(|| format!("cannot open dataset {}", dir.display()))?;
    if sequence.frames.len() < 2 || index + 1 >= sequence.frames.len() {
        anyhow::bail!(
            "{}: frame {index} and the next are needed, the sequence has {} frames",
            dir.display(),
            sequence.frames.len()
        );
    }
    let frame = sequence
        .load_frame(index)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let next = sequence
        .load_frame(index + 1)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let rig = sequence.rig;
    writeln!(
        text,
        "images: {} ({}), frame {index}, {}×{}, f = {:.1} px, baseline {:.3} m{}",
        sequence.name,
        dir.display(),
        rig.width_px,
        rig.height_px,
        rig.focal_px,
        rig.baseline_m,
        if sequence.is_rectified_on_load() {
            ", rectified on load"
        } else {
            ""
        }
    )?;
    let config = FrontendConfig::default();
    let pairs: [(MatchCase, &str, &GrayImage, &GrayImage); 2] = [
        (MatchCase::Stereo, "stereo", &frame.left, &frame.right),
        (
            MatchCase::FrameToFrame,
            "frame-to-frame",
            &frame.left,
            &next.left,
        ),
    ];
    let mut pictures = Vec::new();
    for matcher in MatcherKind::ALL {
        let mut pair = LinePairMatcher::new(detector, matcher, &config)?;
        for (case, case_name, first, second) in pairs {
            let result = pair.run(case, first, second)?;
            let t = result.timings;
            writeln!(
                text,
                "{:>15}: {:>7} {:3} matches of {}|{} segments; detect {:.1}+{:.1} ms, describe {:.1}+{:.1} ms, match {:.3} ms",
                case_name,
                pair.name(),
                result.matches.len(),
                result.first.segments.len(),
                result.second.segments.len(),
                t.detect_ms[0],
                t.detect_ms[1],
                t.describe_ms[0],
                t.describe_ms[1],
                t.match_ms
            )?;
            let path = output.join(format!(
                "images-{case_name}-{}.png",
                pair.name().replace('+', "-")
            ));
            linetrack_draw::segment_matches(
                (rig.width_px, rig.height_px),
                [first.pixels(), second.pixels()],
                [&result.first.segments, &result.second.segments],
                result.matches.iter().map(|m| (m.query, m.train)),
            )
            .save(&path)
            .with_context(|| format!("cannot write {}", path.display()))?;
            pictures.push(path.display().to_string());
        }
    }
    writeln!(text, "wrote {}", pictures.join(", "))?;
    Ok(text)
}
