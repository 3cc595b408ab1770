//! Learns the descriptor's sampling pattern ([`learn_pattern`], default settings) from the
//! corners of a set of images (1500 an image, the extractor's default pyramid) and writes
//! it as the crate's table, `src/learned_pattern.rs`. The table in the tree was made by:
//!
//! ```text
//! cargo run --release -p linetrack-corners --example learn_pattern -- \
//!     shared/corners/src/learned_pattern.rs \
//!     ../shared/data/middlebury/*/*/{view1,view5,imL,imR}.png
//! ```
//!
//! (56 images, 61 361 corners; about 5 minutes on one core.)

use linetrack_corners::{CornerExtractor, GrayView, LearnSettings, Params, Patch, learn_pattern};
use std::fmt::Write as _;
use std::path::PathBuf;

fn main() {
    if let Err(message) = run() {
        eprintln!("learn_pattern: {message}");
        std::process::exit(2);
    }
}

fn run() -> Result<(), String> {
    let mut args = std::env::args_os().skip(1).map(PathBuf::from);
    let output = args
        .next()
        .ok_or("usage: learn_pattern <output.rs> <image>...")?;
    let images: Vec<PathBuf> = args.collect();
    if images.is_empty() {
        return Err("no training images given".into());
    }
    let params = Params {
        max_corners: 1500,
        ..Params::default()
    };
    let mut extractor = CornerExtractor::new(params).map_err(|e| e.to_string())?;
    let mut patches: Vec<Patch> = Vec::new();
    for path in &images {
        let gray = image::open(path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .into_luma8();
        let (width, height) = (gray.width() as usize, gray.height() as usize);
        let view = GrayView::packed(gray.as_raw(), width, height)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        extractor.patches(view, &mut patches);
    }
    eprintln!("{} corners from {} images", patches.len(), images.len());
    let learned = learn_pattern(&patches, &LearnSettings::default()).map_err(|e| e.to_string())?;
    eprintln!("correlation bound {:.3}", learned.bound);
    let source = table_source(&learned.pairs, images.len(), patches.len(), learned.bound);
    std::fs::write(&output, source).map_err(|e| format!("{}: {e}", output.display()))?;
    eprintln!("wrote {}", output.display());
    Ok(())
}

/// The Rust source of the table.
fn table_source(pairs: &[[(i8, i8); 2]], images: usize, corners: usize, bound: f64) -> String {
    let mut out = String::new();
    let _ = write!(
        out,
        "//! The descriptor's sampling pattern, learned by `examples/learn_pattern.rs` (which wrote\n\
         //! this file; run it again rather than edit) from the corners of the Middlebury stereo\n\
         //! pairs, both views: {images} images, {corners} corners, correlation bound {bound:.3}.\n\
         \n\
         /// The 256 comparisons, unturned: `(dx, dy)` of the first point and of the second;\n\
         /// bit k of a descriptor is set when comparison k's first point is the darker.\n\
         #[rustfmt::skip]\n\
         pub(crate) const LEARNED_PAIRS: [[(i8, i8); 2]; {}] = [\n",
        pairs.len()
    );
    for row in pairs.chunks(4) {
        out.push_str("   ");
        for [(x1, y1), (x2, y2)] in row {
            let _ = write!(out, " [({x1}, {y1}), ({x2}, {y2})],");
        }
        out.push('\n');
    }
    out.push_str("];\n");
    out
}
