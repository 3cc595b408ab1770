//! Simulated illumination changes, applied to the right image only: the two views of a
//! pair then differ as they do when a light changes or auto-exposure reacts between them.

use linetrack_vision::{GrayImage, VisionError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// One illumination condition of the benchmark.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Condition {
    /// Both images as photographed (one light).
    AsIs,
    /// The paper's protocol: `clamp(α·I + β)` with α ~ U(0.5, 2.5), β ~ U(0, 20), drawn
    /// per pair from a fixed seed.
    GainBias,
    /// Over-exposure with clipping: `clamp(2.2·I + 20)`.
    OverExposed,
    /// Under-exposure: `0.35·I` (about 90 grey levels left).
    UnderExposed,
    /// A tone curve: `255·(I/255)^0.45`.
    Gamma,
    /// A non-uniform light field: radial vignetting (−60 % in the corners) times a
    /// left-to-right ramp (0.7 → 1.3).
    Vignetting,
}

impl Condition {
    /// Every condition, in report order.
    pub const ALL: [Condition; 6] = [
        Condition::AsIs,
        Condition::GainBias,
        Condition::OverExposed,
        Condition::UnderExposed,
        Condition::Gamma,
        Condition::Vignetting,
    ];

    /// Short name (tables, CSV, command line).
    pub fn name(self) -> &'static str {
        match self {
            Condition::AsIs => "as-is",
            Condition::GainBias => "gain-bias",
            Condition::OverExposed => "over-exposed",
            Condition::UnderExposed => "under-exposed",
            Condition::Gamma => "gamma",
            Condition::Vignetting => "vignetting",
        }
    }

    /// What the condition does, for the report.
    pub fn description(self) -> &'static str {
        match self {
            Condition::AsIs => "both images as photographed",
            Condition::GainBias => {
                "right image clamp(α·I + β), α ~ U(0.5, 2.5), β ~ U(0, 20) per pair"
            }
            Condition::OverExposed => "right image clamp(2.2·I + 20)",
            Condition::UnderExposed => "right image 0.35·I",
            Condition::Gamma => "right image 255·(I/255)^0.45",
            Condition::Vignetting => {
                "right image × (1 − 0.6·r²) × (0.7 + 0.6·x/w), r = distance from the centre / half-diagonal"
            }
        }
    }

    /// The right image under this condition; `pair_index` seeds the gain/bias draw.
    pub fn apply(self, image: &GrayImage, pair_index: usize) -> Result<GrayImage, VisionError> {
        let (w, h) = (image.width() as usize, image.height() as usize);
        let pixels = image.pixels().ok_or_else(|| VisionError::RawSize {
            origin: image.origin().to_string(),
            len: 0,
            width: w,
            height: h,
        })?;
        let (gain, bias) = match self {
            Condition::AsIs => return Ok(image.clone()),
            Condition::GainBias => {
                let mut rng = ChaCha8Rng::seed_from_u64(0x5eed_0000 + pair_index as u64);
                (rng.random_range(0.5..2.5), rng.random_range(0.0..20.0))
            }
            Condition::OverExposed => (2.2, 20.0),
            Condition::UnderExposed => (0.35, 0.0),
            Condition::Gamma | Condition::Vignetting => (1.0, 0.0),
        };
        let (cx, cy) = (0.5 * (w as f64 - 1.0), 0.5 * (h as f64 - 1.0));
        let half_diagonal_sq = cx * cx + cy * cy;
        let out: Vec<u8> = pixels
            .iter()
            .enumerate()
            .map(|(k, &p)| {
                let v = f64::from(p);
                let changed = match self {
                    Condition::Gamma => 255.0 * (v / 255.0).powf(0.45),
                    Condition::Vignetting => {
                        let (x, y) = ((k % w) as f64, (k / w) as f64);
                        let r_sq =
                            ((x - cx).powi(2) + (y - cy).powi(2)) / half_diagonal_sq.max(1.0);
                        v * (1.0 - 0.6 * r_sq) * (0.7 + 0.6 * x / (w as f64).max(1.0))
                    }
                    _ => gain * v + bias,
                };
                changed.round().clamp(0.0, 255.0) as u8
            })
            .collect();
        GrayImage::from_pixels(w, h, &out, &format!("{} ({})", image.origin(), self.name()))
    }
}

impl std::str::FromStr for Condition {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|c| c.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|c| c.name()).collect();
                format!(
                    "unknown condition {s:?}: expected one of {}",
                    names.join(", ")
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> GrayImage {
        let pixels: Vec<u8> = (0..40 * 30).map(|k| ((k % 40) * 6) as u8).collect();
        GrayImage::from_pixels(40, 30, &pixels, "ramp").unwrap()
    }

    #[test]
    fn each_condition_changes_the_image_as_described() {
        let image = ramp();
        let at = |img: &GrayImage, x: usize, y: usize| img.pixels().unwrap()[y * 40 + x];
        let over = Condition::OverExposed.apply(&image, 0).unwrap();
        assert_eq!(at(&over, 10, 5), 152, "2.2·60 + 20");
        assert_eq!(at(&over, 30, 5), 255, "clipped");
        let under = Condition::UnderExposed.apply(&image, 0).unwrap();
        assert_eq!(at(&under, 10, 5), 21, "0.35·60");
        let gamma = Condition::Gamma.apply(&image, 0).unwrap();
        assert_eq!(at(&gamma, 10, 5), 133, "255·(60/255)^0.45");
        let vignette = Condition::Vignetting.apply(&image, 0).unwrap();
        assert!(at(&vignette, 0, 0) < at(&image, 0, 0).max(1));
        assert!(
            at(&vignette, 39, 0) < at(&vignette, 39, 15),
            "darker in the corner"
        );
        assert_eq!(
            Condition::AsIs.apply(&image, 0).unwrap().pixels(),
            image.pixels()
        );
    }

    #[test]
    fn gain_and_bias_are_drawn_per_pair_reproducibly_within_the_protocol() {
        let image = GrayImage::from_pixels(4, 1, &[0, 10, 20, 40], "steps").unwrap();
        let a = Condition::GainBias.apply(&image, 3).unwrap();
        let b = Condition::GainBias.apply(&image, 3).unwrap();
        assert_eq!(a.pixels(), b.pixels());
        let p = a.pixels().unwrap();
        // I = 0 gives β ∈ [0, 20]; the step 10 → 20 gives 10·α ∈ [5, 25].
        assert!(p[0] <= 20);
        let step = f64::from(p[2]) - f64::from(p[1]);
        assert!((4.0..=26.0).contains(&step), "{p:?}");
        let other = Condition::GainBias.apply(&image, 4).unwrap();
        assert_ne!(other.pixels(), a.pixels());
    }
}
