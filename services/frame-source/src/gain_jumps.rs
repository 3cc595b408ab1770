//! The paper's illumination protocol on a data set's images (`[source] gain_jumps_s`): every
//! period of the sequence's time a new gain and bias on both images, drawn as
//! `linetrack-vo --gain-jumps` draws them, so a pipeline run and an odometry run see the
//! same images.

use linetrack_scene_render::IlluminationConfig;

/// The draws and the two images' buffers, reused from frame to frame.
pub(crate) struct GainJumps {
    illumination: IlluminationConfig,
    /// The sequence's first timestamp: time 0 of the protocol.
    origin_ns: u64,
    buffers: [Vec<u8>; 2],
}

impl GainJumps {
    /// Jumps every `period_s` seconds after `origin_ns`, drawn from `seed`; `None` when the
    /// period is 0 (off).
    pub(crate) fn new(period_s: f64, seed: u64, origin_ns: u64) -> Option<Self> {
        (period_s > 0.0).then(|| Self {
            illumination: IlluminationConfig {
                seed,
                gain_jump_period_s: Some(period_s),
                ..IlluminationConfig::default()
            },
            origin_ns,
            buffers: [Vec::new(), Vec::new()],
        })
    }

    /// The frame at `timestamp_ns` as the protocol shows it: `I' = clamp(gain·I + bias)`,
    /// as OpenCV's saturating conversion in `linetrack-vo` computes it ([`level`]; in
    /// double precision 2 of 512,000 values came out a level apart, and a run's
    /// trajectory parted from `linetrack-vo`'s).
    pub(crate) fn apply(&mut self, timestamp_ns: u64, images: [&[u8]; 2]) -> [&[u8]; 2] {
        let t = timestamp_ns.saturating_sub(self.origin_ns) as f64 * 1e-9;
        let seen = self.illumination.at(t, 0);
        for (side, (source, buffer)) in images.iter().zip(&mut self.buffers).enumerate() {
            let (gain, bias) = (seen.gain[side], seen.bias[side]);
            let table: [u8; 256] = std::array::from_fn(|v| level(v as u8, gain, bias));
            buffer.clear();
            buffer.extend(source.iter().map(|&v| table[usize::from(v)]));
        }
        let [left, right] = &self.buffers;
        [left, right]
    }
}

/// `gain·v + bias` as OpenCV's `convertTo` from 8 bits to 8 bits computes it here (4.6,
/// x86-64 with FMA): single precision, the product and the sum fused, rounded half to
/// even, saturated. Unfused, one level in a million differed.
#[allow(clippy::cast_possible_truncation)]
fn level(v: u8, gain: f64, bias: f64) -> u8 {
    f32::from(v)
        .mul_add(gain as f32, bias as f32)
        .round_ties_even()
        .clamp(0.0, 255.0) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_level_is_what_linetrack_vo_s_perturbation_gives() {
        // linetrack-vo perturbs with OpenCV; the same draws must give the same images.
        let levels: Vec<u8> = (0..=255).collect();
        let image = linetrack_vision::GrayImage::from_pixels(256, 1, &levels, "levels")
            .unwrap_or_else(|e| panic!("{e}"));
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1_u64 << 53) as f64
        };
        let mut differ = 0;
        for _ in 0..4000 {
            let (gain, bias) = (0.5 + 2.0 * uniform(), 20.0 * uniform());
            let want =
                linetrack_vision::perturb(&image, gain, bias).unwrap_or_else(|e| panic!("{e}"));
            let want = want.pixels().unwrap_or_else(|| panic!("continuous"));
            differ += levels
                .iter()
                .zip(want)
                .filter(|(v, w)| level(**v, gain, bias) != **w)
                .count();
        }
        assert_eq!(differ, 0, "levels unlike OpenCV's of 1,024,000");
    }

    #[test]
    fn the_first_period_is_untouched_and_later_ones_jump_and_clamp() {
        let mut jumps = GainJumps::new(0.5, 3, 1_000).unwrap();
        let image: Vec<u8> = (0..=255).collect();
        let [left, right] = jumps.apply(1_000 + 400_000_000, [&image, &image]);
        assert_eq!((left, right), (&image[..], &image[..]));
        // Periods 1, 2, ...: both images share one gain and bias, drawn from the seed.
        let expected = IlluminationConfig {
            seed: 3,
            gain_jump_period_s: Some(0.5),
            ..IlluminationConfig::default()
        }
        .at(1.2, 0);
        let [left, right] = jumps.apply(1_000 + 1_200_000_000, [&image, &image]);
        assert_eq!(left, right);
        let (gain, bias) = (expected.gain[0], expected.bias[0]);
        assert!((0.5..2.5).contains(&gain) && (0.0..20.0).contains(&bias));
        for (&v, &seen) in image.iter().zip(left) {
            let want = (gain * f64::from(v) + bias).clamp(0.0, 255.0);
            assert!(
                (f64::from(seen) - want).abs() <= 0.5,
                "{v} -> {seen}, want {want}"
            );
        }
        assert_ne!(left, &image[..]);
    }

    #[test]
    fn a_zero_period_is_off() {
        assert!(GainJumps::new(0.0, 1, 0).is_none());
    }
}
