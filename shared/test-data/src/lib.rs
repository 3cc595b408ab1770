//! Where tests and benches find real data, and small images with known content.
//!
//! The EuRoC excerpt (95 stereo frames of V1_01_easy, ASL layout) is found through the
//! environment variable [`EUROC_ENV`], else at `../shared/data/euroc/V1_01_easy_micro`
//! beside the workspace (where CI has it). A test that needs it and cannot find it fails
//! with a message saying where it looked; `cargo xtask test` leaves such tests out, and
//! says so, on machines without the folder. The Middlebury pairs and the KITTI raw drive
//! are found the same way ([`middlebury_dir`], [`kitti_raw_dir`]). [`CountingAllocator`]
//! counts heap allocations for the tests that check a hot path allocates nothing.
//! [`Scratch`] is a test's folder under the system temp folder, named for the test and
//! removed when the test ends.
#![warn(missing_docs)]

use std::path::{Path, PathBuf};

mod counting;
pub use counting::CountingAllocator;

/// Environment variable naming the EuRoC excerpt's sequence folder (the one holding `mav0/`).
pub const EUROC_ENV: &str = "LINETRACK_EUROC_DIR";

/// Name fragment shared by every test that needs the real data, so a runner can select or
/// leave them out (`cargo nextest run -E 'test(/real_data/)'`).
pub const REAL_DATA_TAG: &str = "real_data";

/// The EuRoC excerpt folder, or a message naming where it was looked for.
pub fn euroc_dir() -> Result<PathBuf, String> {
    locate(
        "EuRoC excerpt",
        EUROC_ENV,
        "shared/data/euroc/V1_01_easy_micro",
        Some("mav0/cam0/data.csv"),
    )
}

/// Environment variable naming the Middlebury folder (the one holding the scene folders).
pub const MIDDLEBURY_ENV: &str = "LINETRACK_MIDDLEBURY_DIR";

/// Environment variable naming the KITTI raw drive folder (the one holding `image_00/`).
pub const KITTI_RAW_ENV: &str = "LINETRACK_KITTI_RAW_DIR";

/// `$env`, else `default` (relative to `<workspace>/..`), when it is a folder holding
/// `marker` (if given); else a message naming `what` and where it was looked for.
fn locate(what: &str, env: &str, default: &str, marker: Option<&str>) -> Result<PathBuf, String> {
    let (dir, how) = match std::env::var_os(env) {
        Some(value) => (PathBuf::from(value), format!("${env}")),
        None => (
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../..")
                .join(default),
            format!("the default location (set ${env} to override)"),
        ),
    };
    match marker {
        None if dir.is_dir() => Ok(dir),
        Some(file) if dir.join(file).is_file() => Ok(dir),
        None => Err(format!("{what} not found at {} ({how})", dir.display())),
        Some(file) => Err(format!(
            "{what} not found at {} ({how}): no {file} there",
            dir.display()
        )),
    }
}

/// The Middlebury stereo pairs' folder (`$LINETRACK_MIDDLEBURY_DIR`, else
/// `../shared/data/middlebury` beside the workspace), or a message naming where it was
/// looked for.
pub fn middlebury_dir() -> Result<PathBuf, String> {
    locate(
        "Middlebury pairs",
        MIDDLEBURY_ENV,
        "shared/data/middlebury",
        None,
    )
}

/// The KITTI raw drive 2011_09_26_drive_0001 (`$LINETRACK_KITTI_RAW_DIR`, else
/// `../shared/data/kitti-raw/2011_09_26/2011_09_26_drive_0001_sync` beside the workspace;
/// its calibration files are in the parent folder), or a message naming where it was
/// looked for.
pub fn kitti_raw_dir() -> Result<PathBuf, String> {
    locate(
        "KITTI raw drive",
        KITTI_RAW_ENV,
        "shared/data/kitti-raw/2011_09_26/2011_09_26_drive_0001_sync",
        Some("image_00/timestamps.txt"),
    )
}

/// Left and right image files of the `index`-th frame listed in `cam0/data.csv`.
pub fn euroc_stereo_pair(index: usize) -> Result<(PathBuf, PathBuf), String> {
    let dir = euroc_dir()?;
    let csv_path = dir.join("mav0/cam0/data.csv");
    let csv =
        std::fs::read_to_string(&csv_path).map_err(|e| format!("{}: {e}", csv_path.display()))?;
    let name = csv
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .nth(index)
        .and_then(|l| l.split(',').nth(1))
        .map(str::trim)
        .ok_or_else(|| format!("{}: no frame {index}", csv_path.display()))?;
    Ok((
        dir.join("mav0/cam0/data").join(name),
        dir.join("mav0/cam1/data").join(name),
    ))
}

/// A generated grayscale test card, row-major: a dark background with bright and mid-grey
/// axis-aligned and slanted quadrilaterals whose edges are long straight lines at known
/// places ([`test_card_edges`]), plus mild deterministic texture.
pub fn test_card(width: usize, height: usize) -> Vec<u8> {
    let mut pixels = vec![0u8; width * height];
    let shapes = test_card_shapes(width, height);
    for y in 0..height {
        for x in 0..width {
            // Faint texture so descriptors have something to see besides the edges.
            let texture = ((x * 7 + y * 13) % 17) as u8;
            let inside = shapes
                .iter()
                .rev()
                .find(|(shape, _)| contains(shape, x as f64 + 0.5, y as f64 + 0.5));
            pixels[y * width + x] = match inside {
                Some((_, level)) => level.saturating_add(texture),
                None => 30 + texture,
            };
        }
    }
    pixels
}

/// The straight edges of [`test_card`], as `(x0, y0, x1, y1)`.
pub fn test_card_edges(width: usize, height: usize) -> Vec<[f64; 4]> {
    let mut edges = Vec::new();
    for (shape, _) in test_card_shapes(width, height) {
        for k in 0..4 {
            let (a, b) = (shape[k], shape[(k + 1) % 4]);
            edges.push([a.0, a.1, b.0, b.1]);
        }
    }
    edges
}

type Quad = [(f64, f64); 4];

/// Convex quadrilaterals (corners clockwise in image coordinates) and their grey level.
fn test_card_shapes(width: usize, height: usize) -> Vec<(Quad, u8)> {
    let (w, h) = (width as f64, height as f64);
    let rect = |x0: f64, y0: f64, x1: f64, y1: f64| {
        [
            (x0 * w, y0 * h),
            (x1 * w, y0 * h),
            (x1 * w, y1 * h),
            (x0 * w, y1 * h),
        ]
    };
    vec![
        (rect(0.08, 0.10, 0.30, 0.80), 200),
        (rect(0.40, 0.15, 0.55, 0.45), 140),
        (rect(0.62, 0.55, 0.92, 0.90), 220),
        (rect(0.36, 0.60, 0.52, 0.92), 110),
        // A slanted parallelogram.
        (
            [
                (0.62 * w, 0.08 * h),
                (0.80 * w, 0.08 * h),
                (0.90 * w, 0.45 * h),
                (0.72 * w, 0.45 * h),
            ],
            170,
        ),
    ]
}

/// Whether (x, y) is inside the convex quadrilateral (corners clockwise in image axes).
fn contains(q: &Quad, x: f64, y: f64) -> bool {
    (0..4).all(|k| {
        let (a, b) = (q[k], q[(k + 1) % 4]);
        (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0) >= 0.0
    })
}

/// `pixels` shifted left by `shift` columns (the view of a camera `shift` px of
/// disparity to the right), the uncovered right border filled with the background level.
pub fn shift_left(pixels: &[u8], width: usize, shift: usize) -> Vec<u8> {
    let mut out = vec![30u8; pixels.len()];
    for (row_in, row_out) in pixels.chunks_exact(width).zip(out.chunks_exact_mut(width)) {
        if shift < width {
            row_out[..width - shift].copy_from_slice(&row_in[shift..]);
        }
    }
    out
}

/// A copy of the KITTI raw drive, in `dir`, as a rig whose disparities all read `pixels`
/// short would see it: its right images moved `pixels` columns to the right (a whole
/// number moves them without resampling; a fraction interpolates linearly between the two
/// columns around, rounding half to even; the first column repeated), everything else
/// linked to the real drive's files. Returns the copy's drive folder.
pub fn kitti_raw_with_right_images_moved(dir: &Path, pixels: f64) -> Result<PathBuf, String> {
    if !(0.0..=64.0).contains(&pixels) {
        return Err(format!(
            "moving the right images by {pixels} px: 0 to 64 px only"
        ));
    }
    let real = kitti_raw_dir()?;
    let named = |path: &Path| -> Result<PathBuf, String> {
        path.file_name()
            .map(PathBuf::from)
            .ok_or_else(|| format!("{}: no file name", path.display()))
    };
    fn io(path: &Path) -> impl Fn(std::io::Error) -> String + '_ {
        move |e| format!("{}: {e}", path.display())
    }
    let date = real
        .parent()
        .ok_or_else(|| format!("{}: no parent folder", real.display()))?;
    let copy_date = dir.join(named(date)?);
    let copy = copy_date.join(named(&real)?);
    let right = copy.join("image_01/data");
    std::fs::create_dir_all(&right).map_err(io(&right))?;
    let link = |from: PathBuf, to: PathBuf| std::os::unix::fs::symlink(&from, &to).map_err(io(&to));
    for entry in std::fs::read_dir(date).map_err(io(date))? {
        let path = entry.map_err(io(date))?.path();
        if path.is_file() {
            link(path.clone(), copy_date.join(named(&path)?))?;
        }
    }
    for name in [
        "image_00",
        "oxts",
        "poses_cam0_rect_from_oxts.txt",
        "image_01/timestamps.txt",
    ] {
        link(real.join(name), copy.join(name))?;
    }
    let source = real.join("image_01/data");
    let (whole, fraction) = (pixels.trunc() as u32, pixels.fract());
    for entry in std::fs::read_dir(&source).map_err(io(&source))? {
        let path = entry.map_err(io(&source))?.path();
        let image = image::open(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .into_luma8();
        let moved = image::GrayImage::from_fn(image.width(), image.height(), |x, y| {
            let near = f64::from(image.get_pixel(x.saturating_sub(whole), y)[0]);
            let far = f64::from(image.get_pixel(x.saturating_sub(whole + 1), y)[0]);
            image::Luma([((1.0 - fraction) * near + fraction * far).round_ties_even() as u8])
        });
        let out = right.join(named(&path)?);
        moved
            .save(&out)
            .map_err(|e| format!("{}: {e}", out.display()))?;
    }
    Ok(copy)
}

/// A test's scratch folder under the system temp folder, removed with everything in it
/// when the guard is dropped (a passing test or a panicking one alike: the panic unwinds
/// through the drop).
///
/// Its name is `linetrack-<owner>-<name>-<random>`, so a folder left behind (a test
/// killed, or one that [`Scratch::keep`]s it) still says whose it is. Where the code under
/// test must create a path itself, give it one inside: `scratch.join("out")`. Where the
/// test starts processes that write into the folder, keep the guard until they are joined.
#[derive(Debug)]
pub struct Scratch {
    dir: tempfile::TempDir,
}

impl Scratch {
    /// An empty new folder for `owner`'s (the crate's) test `name`.
    ///
    /// # Panics
    /// When the folder cannot be created, naming the temp folder and the reason: a test
    /// cannot go on without it.
    #[track_caller]
    pub fn new(owner: &str, name: &str) -> Self {
        let prefix = format!("linetrack-{owner}-{name}-");
        match tempfile::Builder::new().prefix(&prefix).tempdir() {
            Ok(dir) => Self { dir },
            Err(e) => panic!(
                "creating a scratch folder {prefix}* in {}: {e}",
                std::env::temp_dir().display()
            ),
        }
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// `relative` inside the folder (not created).
    pub fn join(&self, relative: impl AsRef<Path>) -> PathBuf {
        self.dir.path().join(relative)
    }

    /// Keeps the folder past the guard (for looking at after a test), returning its path.
    pub fn keep(self) -> PathBuf {
        self.dir.keep()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.path()
    }
}

/// For `Command::arg` and `env`, as a `PathBuf`.
impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.path().as_os_str()
    }
}

/// The folder's path, as a `PathBuf` gives its own: `&scratch` goes where a `&Path` does.
impl std::ops::Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        self.path()
    }
}

#[cfg(test)]
mod tests {
    use super::Scratch;

    #[test]
    fn a_scratch_folder_is_named_for_its_test_and_removed_on_drop() {
        let scratch = Scratch::new("test-data", "drop");
        let path = scratch.path().to_path_buf();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        assert!(name.starts_with("linetrack-test-data-drop-"), "{name}");
        assert!(path.is_dir());
        std::fs::create_dir_all(scratch.join("a/b")).unwrap();
        std::fs::write(scratch.join("a/b/c.txt"), "x").unwrap();
        drop(scratch);
        assert!(!path.exists(), "{} is still there", path.display());
    }

    #[test]
    fn two_guards_of_one_name_get_two_folders() {
        let (a, b) = (
            Scratch::new("test-data", "twice"),
            Scratch::new("test-data", "twice"),
        );
        assert_ne!(a.path(), b.path());
        assert!(!a.join("out").exists(), "join only names a path");
    }

    #[test]
    fn a_panicking_test_still_removes_its_folder() {
        let scratch = Scratch::new("test-data", "panic");
        let path = scratch.path().to_path_buf();
        let unwound = std::panic::catch_unwind(move || {
            let _scratch = scratch;
            panic!("the test failed");
        });
        assert!(unwound.is_err());
        assert!(!path.exists(), "{} is still there", path.display());
    }

    #[test]
    fn a_kept_folder_outlives_its_guard() {
        let kept = Scratch::new("test-data", "keep").keep();
        assert!(kept.is_dir());
        std::fs::remove_dir(&kept).unwrap();
    }
}
