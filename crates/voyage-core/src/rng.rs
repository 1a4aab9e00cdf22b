//! Deterministic randomness without a `rand` dependency.
//!
//! Two kinds: a sequential [`Rng`] (SplitMix64) for the few hundred choices that shape a
//! phantom (fold spacing, polyp angles ...), drawn in a fixed order on one thread; and a
//! counter-based [`voxel_noise`] for the per-voxel CT noise, a pure function of
//! (seed, voxel index), so the volume is bit-identical whatever the number of threads.

/// The SplitMix64 output function (Steele, Lea & Flood 2014): a bijective 64-bit mixer.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// A key for one independent stream of a seed (`stream` names what the numbers are for).
pub fn stream_key(seed: u64, stream: u64) -> u64 {
    mix64(seed.wrapping_mul(GOLDEN) ^ mix64(stream.wrapping_add(GOLDEN)))
}

/// Sequential SplitMix64 generator.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
}

impl Rng {
    pub fn new(seed: u64, stream: u64) -> Self {
        Rng {
            state: stream_key(seed, stream),
        }
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN);
        mix64(self.state)
    }

    /// Uniform in [0, 1), 53 bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box–Muller; only used for the few shape choices).
    pub fn gauss(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Zero-mean, unit-variance noise for voxel `index`: a pure function of (key, index).
///
/// The SplitMix64 counter at position `index` is split into four 16-bit uniforms whose sum
/// (Irwin–Hall, n = 4) is rescaled to unit variance. That is Gaussian to within a few per
/// cent in the body of the distribution, bounded at ±3.46 σ, and costs one hash per voxel
/// instead of a logarithm and a cosine — it matters for 10⁸ voxels.
#[inline]
pub fn voxel_noise(key: u64, index: u64) -> f32 {
    let h = mix64(key.wrapping_add(index.wrapping_add(1).wrapping_mul(GOLDEN)));
    let sum = (h & 0xFFFF) + ((h >> 16) & 0xFFFF) + ((h >> 32) & 0xFFFF) + (h >> 48);
    // Each 16-bit value has mean 32767.5 and variance (65536² − 1)/12.
    const MEAN: f32 = 4.0 * 32767.5;
    const INV_SD: f32 = 1.0 / 37837.23; // sqrt(4 · (65536² − 1) / 12)
    (sum as f32 - MEAN) * INV_SD
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxel_noise_has_unit_variance() {
        let key = stream_key(7, 1);
        let n = 200_000u64;
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for i in 0..n {
            let v = voxel_noise(key, i) as f64;
            s += v;
            s2 += v * v;
        }
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.02, "variance {var}");
    }

    #[test]
    fn rng_is_deterministic_and_streams_differ() {
        let a: Vec<u64> = (0..4)
            .map({
                let mut r = Rng::new(3, 9);
                move |_| r.next_u64()
            })
            .collect();
        let mut r = Rng::new(3, 9);
        assert_eq!(a, (0..4).map(|_| r.next_u64()).collect::<Vec<_>>());
        assert_ne!(Rng::new(3, 9).next_u64(), Rng::new(3, 10).next_u64());
        assert_ne!(Rng::new(3, 9).next_u64(), Rng::new(4, 9).next_u64());
    }
}
