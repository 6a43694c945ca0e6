//! How a supernodal factor's values are stored, f64, f32 or 16-bit halves (each column scaled by
//! its own power of two), and widened to f64 as the solves read them.
//!
//! The 16-bit store halves the f32 factor's memory traffic in the solves, which stream the whole
//! factor twice: 15 % faster preconditioner solves on a 6.9 M-value factor (beam6k, 7.2 → 6.1 ms),
//! not 50 %, as the kernels are also bound by their own arithmetic; L-BFGS iterations within 3 %
//! of the f32 factor's on every scene.

/// How L's values are stored: f64, rounded to f32, or to 16 bits (widened to f64 as they are
/// read).
pub(super) trait Stored: Copy {
    /// The value as f64.
    fn widen(self) -> f64;

    /// Four consecutive values as f64 lanes.
    #[cfg(target_arch = "x86_64")]
    fn load4(v3: pulp::x86::V3, v: &[Self]) -> pulp::f64x4;
}

impl Stored for f64 {
    #[inline(always)]
    fn widen(self) -> f64 {
        self
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(_: pulp::x86::V3, v: &[f64]) -> pulp::f64x4 {
        let v: &[f64; 4] = v[..4].try_into().expect("four values");
        pulp::cast(*v)
    }
}

impl Stored for f32 {
    #[inline(always)]
    fn widen(self) -> f64 {
        self.into()
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(v3: pulp::x86::V3, v: &[f32]) -> pulp::f64x4 {
        let v: &[f32; 4] = v[..4].try_into().expect("four values");
        v3.convert_f32x4_to_f64x4(pulp::cast(*v))
    }
}

/// An IEEE half-precision bit pattern read as 2⁻¹¹² times its value, the factor of a 16-bit
/// preconditioner.
///
/// Widening shifts the half's exponent and mantissa into an f32's fields, which rebiases the
/// exponent by −112 for free (three integer operations and one conversion per four values); the
/// solve undoes that and each column's own scaling between its two passes. Encoding flushes
/// halves below the normal range (2⁻¹⁴) to zero, so every widened value is a normal f32.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct Half(pub(super) u16);

impl Half {
    /// Largest value encoded: max|v|·c lands in (2¹⁴, 2¹⁵] for the power-of-two scale c, below
    /// the half range's 65504.
    const TOP_EXPONENT: i32 = 15;

    /// Rounds one column of L into `out`, scaled by the power of two c that puts its largest
    /// value in (2¹⁴, 2¹⁵], to nearest even; values below 2⁻¹⁴ after scaling (2⁻²⁹ of the
    /// column's largest) become zero. Widened, the halves are σ = c·2⁻¹¹² times the values;
    /// returns σ², or None when a value is not finite. An all-zero column gets c = 1.
    pub(super) fn encode_column(values: &[f32], out: &mut [Half]) -> Option<f64> {
        // The bits of |v| order like |v| for finite values, and the non-finite ones (infinity,
        // NaN) lie above all of them: one branch-free maximum over integers, which vectorises,
        // finds the largest value and any non-finite one (the encoding is a pass over the whole
        // factor after each factorisation).
        let top = values
            .iter()
            .fold(0u32, |m, v| m.max(v.to_bits() & 0x7fff_ffff));
        if top >= f32::INFINITY.to_bits() {
            return None;
        }
        let max = f32::from_bits(top);
        let k = if max > 0.0 {
            (Self::TOP_EXPONENT - f64::from(max).log2().ceil() as i32).min(127)
        } else {
            0
        };
        let c = 2f32.powi(k);
        for (o, &v) in out.iter_mut().zip(values) {
            *o = Half::round(v * c);
        }
        let sigma = f64::from(c) * 2f64.powi(-112);
        Some(sigma * sigma)
    }

    /// The half nearest `v` (ties to even), zero below 2⁻¹⁴; `v` below 65504 in magnitude.
    fn round(v: f32) -> Half {
        let bits = v.to_bits();
        let sign = ((bits >> 16) & 0x8000) as u16;
        let magnitude = bits & 0x7fff_ffff;
        // Round the 23-bit mantissa to 10 bits (a carry into the exponent is right), then
        // rebias the exponent from 127 to 15. Computed for every value and then selected, so
        // that the encoding loop has no branch and vectorises; below 2⁻¹⁴ the rebias wraps
        // and the value is flushed to zero.
        let rounded = (magnitude + 0x0fff + ((magnitude >> 13) & 1)) >> 13;
        let half = sign | rounded.wrapping_sub(112 << 10) as u16;
        Half(if magnitude < 0x3880_0000 { 0 } else { half })
    }

    /// The f32 bit pattern of 2⁻¹¹² times the half's value: sign-extend, shift the exponent and
    /// mantissa into place, clear the three exponent bits the sign extension set.
    #[inline(always)]
    fn f32_bits(bits: i32) -> u32 {
        ((bits << 13) as u32) & 0x8fff_ffff
    }
}

impl Stored for Half {
    #[inline(always)]
    fn widen(self) -> f64 {
        f32::from_bits(Half::f32_bits(i32::from(self.0 as i16))).into()
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn load4(v3: pulp::x86::V3, v: &[Half]) -> pulp::f64x4 {
        let v: &[Half; 4] = v[..4].try_into().expect("four values");
        let lanes: [u16; 8] = [v[0].0, v[1].0, v[2].0, v[3].0, 0, 0, 0, 0];
        let wide = v3.sse4_1._mm_cvtepi16_epi32(pulp::cast(lanes));
        let shifted = v3.sse2._mm_slli_epi32::<13>(wide);
        let mask = v3.sse2._mm_set1_epi32(0x8fff_ffff_u32 as i32);
        let f = v3
            .sse2
            ._mm_castsi128_ps(v3.sse2._mm_and_si128(shifted, mask));
        pulp::cast(v3.avx._mm256_cvtps_pd(f))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_round_to_nearest_and_widen_exactly() {
        let scale = 2f64.powi(112);
        // Every finite normal half and zero: widening gives its value (times 2⁻¹¹²), and
        // rounding that value gives the half back.
        for bits in 0..=u16::MAX {
            let exponent = i32::from((bits >> 10) & 0x1f);
            if exponent == 0x1f || (exponent == 0 && bits & 0x3ff != 0) || bits == 0x8000 {
                continue;
            }
            let magnitude = if exponent == 0 {
                0.0
            } else {
                (1.0 + f64::from(bits & 0x3ff) / 1024.0) * 2f64.powi(exponent - 15)
            };
            let value = if bits & 0x8000 != 0 {
                -magnitude
            } else {
                magnitude
            };
            assert_eq!(Half(bits).widen() * scale, value, "{bits:#06x}");
            assert_eq!(Half::round(value as f32), Half(bits), "{bits:#06x}");
        }
        // Between two halves: the nearer one, and on a tie the one with an even mantissa.
        let one_ulp = 2f32.powi(-10);
        for (v, expected) in [
            (1.0 + 0.49 * one_ulp, 1.0),
            (1.0 + 0.51 * one_ulp, 1.0 + one_ulp),
            (1.0 + 0.5 * one_ulp, 1.0),
            (1.0 + 1.5 * one_ulp, 1.0 + 2.0 * one_ulp),
            (-(1.0 + 0.51 * one_ulp), -(1.0 + one_ulp)),
            (2047.5, 2048.0),
        ] {
            assert_eq!(Half::round(v).widen() * scale, f64::from(expected), "{v}");
        }
        // Below the normal range: zero.
        for v in [6.0e-5f32, -6.0e-5, 1e-30, 0.0] {
            assert_eq!(Half::round(v), Half(0), "{v}");
        }
    }

    #[test]
    fn encoding_scales_each_column_s_largest_value_to_the_top_of_the_half_range() {
        for max in [1e-20f32, 3.7e-3, 1.0, 631.0, 4.2e12] {
            let values = [max, -0.5 * max, 1e-3 * max, 1e-10 * max, 0.0];
            let mut out = [Half(0); 5];
            let scaling = Half::encode_column(&values, &mut out).unwrap();
            // Widened, the halves are σ times the values, and scaling is σ².
            let sigma = scaling.sqrt();
            for (v, h) in values.iter().zip(&out) {
                let back = h.widen() / sigma;
                let v = f64::from(*v);
                assert!(
                    (back - v).abs() <= 2f64.powi(-11) * v.abs() + 1e-9 * f64::from(max),
                    "max {max}: {v} → {back}"
                );
            }
            let top = out[0].widen() * 2f64.powi(112);
            assert!(
                top > 16384.0 && top <= 32768.0,
                "max {max}: scaled to {top}"
            );
        }
        let mut out = [Half(1); 2];
        assert!(Half::encode_column(&[0.0, 0.0], &mut out).is_some());
        assert_eq!(out, [Half(0); 2]);
        assert!(Half::encode_column(&[1.0, f32::INFINITY], &mut out).is_none());
        assert!(Half::encode_column(&[f32::NAN, 1.0], &mut out).is_none());
        assert!(Half::encode_column(&[1.0, -f32::INFINITY], &mut out).is_none());
        assert!(Half::encode_column(&[-f32::NAN, 1.0], &mut out).is_none());
    }

    #[test]
    fn the_simd_widening_of_halves_matches_the_scalar_one() {
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = pulp::x86::V3::try_new() {
            let all: Vec<Half> = (0..=u16::MAX)
                .map(Half)
                .filter(|h| (h.0 >> 10) & 0x1f != 0x1f)
                .collect();
            for chunk in all.chunks_exact(4) {
                let wide: [f64; 4] = pulp::cast(Half::load4(v3, chunk));
                for (w, h) in wide.iter().zip(chunk) {
                    assert_eq!(w.to_bits(), h.widen().to_bits(), "{:#06x}", h.0);
                }
            }
            return;
        }
        eprintln!("skipping: no AVX2 on this CPU");
    }
}
