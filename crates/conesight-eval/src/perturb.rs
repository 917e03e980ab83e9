//! Seeded box perturbation (the paper's robustness experiment): every edge of a box moves by a
//! uniform random fraction in `[-level, +level]` of the box's width (left, right edges) or
//! height (top, bottom edges). Draws depend only on the seed and the cone's identity, so a
//! subset of the evaluation reproduces the same boxes.

use conesight_vision::PixelBox;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Identity of one cone of the held-out set and one perturbation level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DrawKey {
    /// Frame seed.
    pub seed: u64,
    /// Frame index.
    pub index: u64,
    /// Index of the true cone in the frame's labels.
    pub truth_index: usize,
    /// Index of the level in the level list.
    pub level_index: usize,
}

fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `draws` perturbed copies of `bbox` at `level` (fraction of the box size), seeded by
/// `base_seed` and `key`. Boxes stay valid: an edge never crosses the opposite one.
pub fn perturbed_boxes(
    bbox: &PixelBox,
    level: f64,
    draws: usize,
    base_seed: u64,
    key: DrawKey,
) -> Vec<PixelBox> {
    let stream = [
        key.seed,
        key.index,
        key.truth_index as u64,
        key.level_index as u64,
    ]
    .iter()
    .fold(mix(base_seed), |acc, v| mix(acc ^ v));
    let mut rng = ChaCha8Rng::seed_from_u64(stream);
    let level = level.abs().min(0.45);
    (0..draws)
        .map(|_| {
            let fractions: [f64; 4] = std::array::from_fn(|_| {
                if level > 0.0 {
                    rng.random_range(-level..=level)
                } else {
                    0.0
                }
            });
            bbox.jittered(fractions)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(truth_index: usize) -> DrawKey {
        DrawKey {
            seed: 100,
            index: 3,
            truth_index,
            level_index: 2,
        }
    }

    #[test]
    fn draws_are_seeded_bounded_and_distinct_per_cone() {
        let bbox = PixelBox {
            x_min_px: 100.0,
            y_min_px: 200.0,
            x_max_px: 140.0,
            y_max_px: 260.0,
        };
        let a = perturbed_boxes(&bbox, 0.1, 50, 7, key(1));
        assert_eq!(
            a,
            perturbed_boxes(&bbox, 0.1, 50, 7, key(1)),
            "same seed, same draws"
        );
        assert_ne!(a, perturbed_boxes(&bbox, 0.1, 50, 7, key(2)));
        assert_ne!(a, perturbed_boxes(&bbox, 0.1, 50, 8, key(1)));
        for b in &a {
            assert!(b.is_valid());
            assert!((b.x_min_px - 100.0).abs() <= 4.0 + 1e-9);
            assert!((b.x_max_px - 140.0).abs() <= 4.0 + 1e-9);
            assert!((b.y_min_px - 200.0).abs() <= 6.0 + 1e-9);
            assert!((b.y_max_px - 260.0).abs() <= 6.0 + 1e-9);
        }
        // Uniform in [-10 %, +10 %]: some edge moves by more than 5 % of the size.
        assert!(a.iter().any(|b| (b.x_min_px - 100.0).abs() > 2.0));
        assert!(
            perturbed_boxes(&bbox, 0.0, 3, 7, key(1))
                .iter()
                .all(|b| *b == bbox)
        );
    }
}
