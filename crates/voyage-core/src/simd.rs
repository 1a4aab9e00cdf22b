//! Every intrinsic of the crate, each beside its scalar version, which gives the same bits.
//!
//! On x86_64 the vector versions are used (SSE2 is part of x86_64; AVX2 is detected at run
//! time), unless the crate's feature `scalar` is on: then every caller takes the scalar path
//! (CI runs voyage-core's tests so once). The tests below compare both paths bit for bit.

/// Whether the vector versions are compiled in and chosen.
const VECTOR: bool = cfg!(all(target_arch = "x86_64", not(feature = "scalar")));

/// A test on 16-bit values, for [`mask64`].
#[derive(Clone, Copy, Debug)]
pub(crate) enum Test {
    /// Below the threshold: air in a CT.
    Below(i16),
    /// At or above the threshold: tagged fluid (and bone).
    AtLeast(i16),
    /// Not 0: a mask's labels.
    NonZero,
}

impl Test {
    #[inline(always)]
    pub(crate) fn holds(self, v: i16) -> bool {
        match self {
            Test::Below(t) => v < t,
            Test::AtLeast(t) => v >= t,
            Test::NonZero => v != 0,
        }
    }
}

/// Bit b of the result: `test` holds for `v[b]`. SSE2: 16 values per compare.
#[inline(always)]
pub(crate) fn mask64(v: &[i16; 64], test: Test) -> u64 {
    #[cfg(all(target_arch = "x86_64", not(feature = "scalar")))]
    {
        mask64_sse2(v, test)
    }
    #[cfg(not(all(target_arch = "x86_64", not(feature = "scalar"))))]
    {
        mask64_scalar(v, test)
    }
}

// The vector build uses it only in its tests.
#[cfg_attr(all(target_arch = "x86_64", not(feature = "scalar")), allow(dead_code))]
#[inline(always)]
fn mask64_scalar(v: &[i16; 64], test: Test) -> u64 {
    v.iter()
        .enumerate()
        .fold(0u64, |w, (b, &x)| w | (test.holds(x) as u64) << b)
}

// The scalar build uses it only in its tests.
#[cfg(target_arch = "x86_64")]
#[cfg_attr(feature = "scalar", allow(dead_code))]
#[inline(always)]
fn mask64_sse2(v: &[i16; 64], test: Test) -> u64 {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64; each load reads 8 of the 64 values.
    unsafe {
        let (t, invert) = match test {
            Test::Below(t) => (_mm_set1_epi16(t), 0),
            Test::AtLeast(t) => (_mm_set1_epi16(t), 0xFFFF),
            Test::NonZero => (_mm_setzero_si128(), 0xFFFF),
        };
        let cmp = |at: usize| {
            let x = _mm_loadu_si128(v.as_ptr().add(at) as *const __m128i);
            match test {
                Test::NonZero => _mm_cmpeq_epi16(x, t),
                _ => _mm_cmplt_epi16(x, t),
            }
        };
        (0..4).fold(0u64, |w, q| {
            let m =
                _mm_movemask_epi8(_mm_packs_epi16(cmp(16 * q), cmp(16 * q + 8))) as u32 ^ invert;
            w | (m as u64) << (16 * q)
        })
    }
}

/// Bit l of the result: `du + len[l] < d[l]` (four lanes; SSE).
#[inline(always)]
pub(crate) fn lanes_improved(d: &[f32], du: f32, len: &[f32; 4]) -> u32 {
    let d = &d[..4];
    #[cfg(all(target_arch = "x86_64", not(feature = "scalar")))]
    {
        use std::arch::x86_64::{
            _mm_add_ps, _mm_cmplt_ps, _mm_loadu_ps, _mm_movemask_ps, _mm_set1_ps,
        };
        // SAFETY: SSE is part of x86_64; `d` and `len` hold four floats.
        unsafe {
            let c = _mm_add_ps(_mm_set1_ps(du), _mm_loadu_ps(len.as_ptr()));
            _mm_movemask_ps(_mm_cmplt_ps(c, _mm_loadu_ps(d.as_ptr()))) as u32
        }
    }
    #[cfg(not(all(target_arch = "x86_64", not(feature = "scalar"))))]
    {
        (0..4)
            .filter(|&l| du + len[l] < d[l])
            .fold(0u32, |m, l| m | 1 << l)
    }
}

/// Bit l of the result: `du + len[l] · 0.5 · (wu + w[l]) < d[l]` (four lanes; SSE), the
/// products in that order.
#[inline(always)]
pub(crate) fn weighted_lanes_improved(
    d: &[f32],
    du: f32,
    wu: f32,
    w: &[f32; 4],
    len: &[f32; 4],
) -> u32 {
    let d = &d[..4];
    #[cfg(all(target_arch = "x86_64", not(feature = "scalar")))]
    {
        use std::arch::x86_64::{
            _mm_add_ps, _mm_cmplt_ps, _mm_loadu_ps, _mm_movemask_ps, _mm_mul_ps, _mm_set1_ps,
        };
        // SAFETY: SSE is part of x86_64; `d`, `w` and `len` hold four floats.
        unsafe {
            let half_len = _mm_mul_ps(_mm_loadu_ps(len.as_ptr()), _mm_set1_ps(0.5));
            let c = _mm_add_ps(
                _mm_set1_ps(du),
                _mm_mul_ps(
                    half_len,
                    _mm_add_ps(_mm_set1_ps(wu), _mm_loadu_ps(w.as_ptr())),
                ),
            );
            _mm_movemask_ps(_mm_cmplt_ps(c, _mm_loadu_ps(d.as_ptr()))) as u32
        }
    }
    #[cfg(not(all(target_arch = "x86_64", not(feature = "scalar"))))]
    {
        (0..4)
            .filter(|&l| du + len[l] * 0.5 * (wu + w[l]) < d[l])
            .fold(0u32, |m, l| m | 1 << l)
    }
}

/// Whether the AVX2 versions may run (detected once per call site by the standard library's
/// cache).
#[inline]
pub(crate) fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        VECTOR && std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `out[i] = min(out[i], min over sites s of (pos[i] − sp[s])² + sf[s])` for the first 8·B
/// entries, held in B AVX registers across the loop over the sites; returns 8·B. The scalar
/// version is the EDT's `direct_envelope_body`, with the same arithmetic.
///
/// # Safety
/// The CPU must have AVX2 ([`avx2`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn min_parabolas_avx2<const B: usize>(
    (sp, sf): (&[f32], &[f32]),
    pos: &[f32],
    out: &mut [f32],
) -> usize {
    use std::arch::x86_64::*;
    assert!(pos.len() >= 8 * B && out.len() >= 8 * B);
    // SAFETY (loads and stores): 8·B entries of each, asserted above.
    let p: [__m256; B] =
        std::array::from_fn(|b| unsafe { _mm256_loadu_ps(pos.as_ptr().add(8 * b)) });
    let mut acc: [__m256; B] =
        std::array::from_fn(|b| unsafe { _mm256_loadu_ps(out.as_ptr().add(8 * b)) });
    for (&pt, &ft) in sp.iter().zip(sf) {
        let (pt, ft) = (_mm256_set1_ps(pt), _mm256_set1_ps(ft));
        for b in 0..B {
            let d = _mm256_sub_ps(p[b], pt);
            acc[b] = _mm256_min_ps(_mm256_add_ps(_mm256_mul_ps(d, d), ft), acc[b]);
        }
    }
    for (b, a) in acc.iter().enumerate() {
        unsafe { _mm256_storeu_ps(out.as_mut_ptr().add(8 * b), *a) };
    }
    8 * B
}

/// Asks the cache for the line holding `p`. Any address will do: a prefetch never faults and
/// has no effect but on the cache. Nothing in the scalar build.
#[inline(always)]
pub(crate) fn prefetch_address<T>(p: *const T) {
    #[cfg(all(target_arch = "x86_64", not(feature = "scalar")))]
    // SAFETY: the prefetch instruction reads nothing and cannot fault.
    unsafe {
        std::arch::x86_64::_mm_prefetch(p as *const i8, std::arch::x86_64::_MM_HINT_T0)
    };
    #[cfg(not(all(target_arch = "x86_64", not(feature = "scalar"))))]
    let _ = p;
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn mask64_sse2_is_the_scalar_mask() {
        let mut rng = Rng::new(3, 1);
        for _ in 0..200 {
            let v: [i16; 64] = std::array::from_fn(|_| rng.range(-1100.0, 1100.0) as i16 / 4 * 4);
            let t = rng.range(-600.0, 600.0) as i16 / 4 * 4;
            for test in [Test::Below(t), Test::AtLeast(t), Test::NonZero] {
                assert_eq!(mask64_sse2(&v, test), mask64_scalar(&v, test), "{test:?}");
            }
        }
    }

    #[test]
    fn lanes_agree_with_their_scalar_definition() {
        let mut rng = Rng::new(5, 1);
        for _ in 0..2000 {
            let r = |rng: &mut Rng| rng.range(0.0, 8.0) as f32;
            let d: [f32; 4] = std::array::from_fn(|_| r(&mut rng));
            let w: [f32; 4] = std::array::from_fn(|_| r(&mut rng));
            let len = [r(&mut rng), r(&mut rng), r(&mut rng), f32::INFINITY];
            let (du, wu) = (r(&mut rng), r(&mut rng));
            let plain = (0..4)
                .filter(|&l| du + len[l] < d[l])
                .fold(0, |m, l| m | 1 << l);
            assert_eq!(lanes_improved(&d, du, &len), plain);
            let weighted = (0..4)
                .filter(|&l| du + len[l] * 0.5 * (wu + w[l]) < d[l])
                .fold(0, |m, l| m | 1 << l);
            assert_eq!(weighted_lanes_improved(&d, du, wu, &w, &len), weighted);
        }
    }

    #[test]
    fn min_parabolas_avx2_is_the_scalar_minimum() {
        if !avx2() {
            eprintln!("skipping: no AVX2 here (or the scalar build)");
            return;
        }
        let mut rng = Rng::new(9, 1);
        let sp: Vec<f32> = (0..37).map(|i| i as f32 * 0.7).collect();
        let sf: Vec<f32> = (0..37).map(|_| rng.range(0.0, 30.0) as f32).collect();
        let pos: Vec<f32> = (0..32).map(|i| i as f32 * 0.8 - 1.0).collect();
        let start: Vec<f32> = (0..32).map(|_| rng.range(0.0, 50.0) as f32).collect();
        let mut out = start.clone();
        // SAFETY: AVX2 is there (checked above).
        assert_eq!(
            unsafe { min_parabolas_avx2::<4>((&sp, &sf), &pos, &mut out) },
            32
        );
        for i in 0..32 {
            let want = sp.iter().zip(&sf).fold(start[i], |m, (&p, &f)| {
                let d = pos[i] - p;
                (d * d + f).min(m)
            });
            assert_eq!(out[i].to_bits(), want.to_bits(), "entry {i}");
        }
    }
}
