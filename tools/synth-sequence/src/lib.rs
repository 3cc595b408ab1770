//! Generates a synthetic indoor stereo sequence with exact ground truth (poses, depth maps,
//! 3-D segments, illumination per frame) in the EuRoC ASL layout, so the dataset loader
//! reads it like a real sequence. See `linetrack-scene-render` for what is rendered.
#![warn(missing_docs)]

use anyhow::Context;
use clap::Parser;
use linetrack_datasets::EurocWriter;
use linetrack_datasets::depth::DepthMap;
use linetrack_progress::Progress;
use linetrack_scene_render::{Preset, RenderedFrame, SequenceRenderer};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Command-line arguments.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "linetrack-synth",
    version,
    about = "Generate a synthetic indoor stereo sequence with exact ground truth, in the EuRoC layout.",
    after_help = concat!("PRESETS:
    normal                steady light, hand-held motion
    handheld-gain-jumps   gain α ~ U(0.5, 2.5) and bias β ~ U(0, 20) drawn every 2 s (the paper's protocol)
    drone-gain-jumps      the same with faster, wider drone-like motion
    hdr-flicker           1.6× over-exposure with 7 Hz flicker of depth 0.5
    hdr-saturation        2.2× over-exposure: saturated areas
    lights-switching      the two halves of the room's lights switch on and off
    left-right-mismatch   right camera at gain 0.5, bias +15

EXAMPLES:
    linetrack-synth --preset drone-gain-jumps --frames 200 --output out/sequences/drone
    linetrack-synth --preset hdr-flicker --seed 7

OUTPUT (<output>/): mav0/cam0|cam1 (images, sensor.yaml, data.csv), mav0/depth0|depth1
(16-bit PNG depth, metres × 5000, 0 = none), mav0/state_groundtruth_estimate0/data.csv (left
camera pose = body), mav0/scene/segments3d.csv (x0,y0,z0,x1,y1,z1 per 3-D segment, world),
mav0/scene/illumination.csv (per frame: gain and bias of each camera, light levels),
mav0/scene/config.json, and contact-sheet.png (six frames at half size).

", linetrack_progress::progress_help!("frames"))
)]
pub struct Args {
    /// Scene, motion and illumination preset.
    #[arg(long, default_value = "normal")]
    pub preset: Preset,
    /// Seed: the same seed and options give the same sequence.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of stereo frames (20 per second).
    #[arg(long, default_value_t = 60)]
    pub frames: usize,
    /// Output folder (default: out/sequences/<preset>-<seed>).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// No progress on stderr (by default a bar with the time left on a terminal, a line per
    /// tenth of the frames otherwise).
    #[arg(long)]
    pub quiet: bool,
}

/// Writes the sequence; returns the summary to print.
pub fn run(args: &Args) -> anyhow::Result<String> {
    let output = args.output.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "out/sequences/{}-{}",
            args.preset.name(),
            args.seed
        ))
    });
    generate(args.preset, args.seed, args.frames, &output, args.quiet)
}

/// Renders `frames` stereo frames of `preset` with `seed` into `output` (EuRoC layout,
/// depth, scene files, contact sheet), reporting progress on stderr unless `quiet`
/// (see `linetrack-progress`); returns a summary.
pub fn generate(
    preset: Preset,
    seed: u64,
    frames: usize,
    output: &Path,
    quiet: bool,
) -> anyhow::Result<String> {
    if frames == 0 {
        anyhow::bail!("--frames must be at least 1");
    }
    let args = Args {
        preset,
        seed,
        frames,
        output: Some(output.to_path_buf()),
        quiet,
    };
    let output = output.to_path_buf();
    let config = args.preset.config(args.seed, args.frames);
    let renderer = SequenceRenderer::new(config.clone());
    let mut writer = EurocWriter::create(&output, &config.rig, config.rate_hz)?;
    let scene_dir = output.join("mav0/scene");
    std::fs::create_dir_all(&scene_dir)
        .with_context(|| format!("cannot create {}", scene_dir.display()))?;
    write(
        &scene_dir.join("config.json"),
        &serde_json::to_string_pretty(&config)?,
    )?;
    let mut segments = String::from("# x0,y0,z0,x1,y1,z1 [m], world frame (z up)\n");
    for [a, b] in renderer.scene.segments() {
        writeln!(
            segments,
            "{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
            a.x, a.y, a.z, b.x, b.y, b.z
        )?;
    }
    write(&scene_dir.join("segments3d.csv"), &segments)?;

    let mut illumination =
        String::from("#timestamp [ns],gain_left,bias_left,gain_right,bias_right,light_levels…\n");
    let sheet_frames = sheet_indices(args.frames);
    let mut sheet = Vec::new();
    let started = Instant::now();
    let progress = Progress::new(
        &format!("rendering {} frames", args.preset.name()),
        args.frames as u64,
        args.quiet,
    );
    for index in 0..args.frames {
        let frame = renderer.render(index);
        let depth = |view: &linetrack_scene_render::View| DepthMap {
            width: view.width,
            height: view.height,
            metres: view.depth_m.clone(),
        };
        writer.write_frame(
            frame.timestamp_ns,
            [
                (&frame.left.pixels, frame.left.width, frame.left.height),
                (&frame.right.pixels, frame.right.width, frame.right.height),
            ],
            [&depth(&frame.left), &depth(&frame.right)],
            &frame.world_from_left,
        )?;
        let lights: Vec<String> = frame
            .illumination
            .lights
            .iter()
            .map(|l| format!("{l:.2}"))
            .collect();
        let il = &frame.illumination;
        writeln!(
            illumination,
            "{},{:.4},{:.3},{:.4},{:.3},{}",
            frame.timestamp_ns,
            il.gain[0],
            il.bias[0],
            il.gain[1],
            il.bias[1],
            lights.join(",")
        )?;
        if sheet_frames.contains(&index) {
            sheet.push(half_size(&frame));
        }
        progress.inc(1);
    }
    progress.finish();
    writer.finish()?;
    write(&scene_dir.join("illumination.csv"), &illumination)?;
    let sheet_path = output.join("contact-sheet.png");
    contact_sheet(&sheet, config.rig.width_px / 2, config.rig.height_px / 2)
        .save(&sheet_path)
        .with_context(|| format!("cannot write {}", sheet_path.display()))?;
    Ok(format!(
        "wrote {} stereo frames ({}, seed {}) to {} in {:.1} s; contact sheet {}",
        args.frames,
        args.preset.name(),
        args.seed,
        output.display(),
        started.elapsed().as_secs_f64(),
        sheet_path.display()
    ))
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Up to six evenly spread frame indices.
fn sheet_indices(frames: usize) -> Vec<usize> {
    let n = frames.min(6);
    (0..n)
        .map(|k| {
            if n == 1 {
                0
            } else {
                k * (frames - 1) / (n - 1)
            }
        })
        .collect()
}

/// The left image at half size (2×2 mean).
fn half_size(frame: &RenderedFrame) -> image::GrayImage {
    let view = &frame.left;
    let (w, h) = (view.width / 2, view.height / 2);
    image::GrayImage::from_fn(w as u32, h as u32, |x, y| {
        let (x, y) = (2 * x as usize, 2 * y as usize);
        let sum: u32 = [(0, 0), (1, 0), (0, 1), (1, 1)]
            .iter()
            .map(|(dx, dy)| u32::from(view.pixels[(y + dy) * view.width + x + dx]))
            .sum();
        image::Luma([(sum / 4) as u8])
    })
}

/// Tiles up to six images in a 3 × 2 grid with 4-pixel gaps.
fn contact_sheet(images: &[image::GrayImage], w: u32, h: u32) -> image::GrayImage {
    let gap = 4;
    let (cols, rows) = (3u32, images.len().div_ceil(3).max(1) as u32);
    let mut sheet = image::GrayImage::from_pixel(
        cols * (w + gap) - gap,
        rows * (h + gap) - gap,
        image::Luma([0]),
    );
    for (k, tile) in images.iter().enumerate() {
        let (cx, cy) = ((k as u32 % cols) * (w + gap), (k as u32 / cols) * (h + gap));
        image::imageops::overlay(&mut sheet, tile, i64::from(cx), i64::from(cy));
    }
    sheet
}
