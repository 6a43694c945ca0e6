//! The substitutions' inner loops, y += a·x for one and for four columns and a dot product, over
//! values stored in any precision ([`Stored`]): scalar loops, and four-lane fused multiply–adds
//! through `pulp`'s AVX2 + FMA level where the CPU has it (chosen at run time).
//!
//! The AVX2 loops widen 16-bit values four at a time with integer shifts (`Stored::load4`), at
//! the speed of the memory they save; the portable loops do not, so factors are stored in 16 bits
//! only where the AVX2 loops run ([`half_kernels`]).

use super::storage::Stored;

/// Whether 16-bit factors are worth storing: only the AVX2 kernels widen them at the speed of
/// the memory they save.
pub(super) fn half_kernels() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        pulp::x86::V3::try_new().is_some()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The substitution's inner loops: `y += a·x` for one and for four columns, and a dot product.
pub(super) trait Lanes: Copy {
    fn axpy<V: Stored>(self, y: &mut [f64], x: &[V], a: f64);
    fn axpy4<V: Stored>(self, y: &mut [f64], x: [&[V]; 4], a: [f64; 4]);
    fn dot<V: Stored>(self, a: &[V], b: &[f64]) -> f64;
}

/// Scalar loops, for CPUs without AVX2.
#[derive(Clone, Copy)]
pub(super) struct Portable;

impl Lanes for Portable {
    #[inline(always)]
    fn axpy<V: Stored>(self, y: &mut [f64], x: &[V], a: f64) {
        for (y, &x) in y.iter_mut().zip(x) {
            *y += x.widen() * a;
        }
    }

    #[inline(always)]
    fn axpy4<V: Stored>(self, y: &mut [f64], x: [&[V]; 4], a: [f64; 4]) {
        for (i, y) in y.iter_mut().enumerate() {
            *y += x[0][i].widen() * a[0]
                + x[1][i].widen() * a[1]
                + x[2][i].widen() * a[2]
                + x[3][i].widen() * a[3];
        }
    }

    #[inline(always)]
    fn dot<V: Stored>(self, a: &[V], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(&a, &b)| a.widen() * b).sum()
    }
}

/// Four-lane fused multiply–adds; only built inside [`pulp::x86::V3::vectorize`].
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx2(pub(super) pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    #[inline(always)]
    fn axpy<V: Stored>(self, y: &mut [f64], x: &[V], a: f64) {
        let v3 = self.0;
        let n = y.len() / 4 * 4;
        let av = v3.splat_f64x4(a);
        let (yv, yt) = y.split_at_mut(n);
        for (yc, xc) in yv.chunks_exact_mut(4).zip(x.chunks_exact(4)) {
            let yc: &mut [f64; 4] = yc.try_into().expect("four values");
            *yc = pulp::cast(v3.mul_add_f64x4(V::load4(v3, xc), av, pulp::cast(*yc)));
        }
        for (y, &x) in yt.iter_mut().zip(&x[n..]) {
            *y = x.widen().mul_add(a, *y);
        }
    }

    #[inline(always)]
    fn axpy4<V: Stored>(self, y: &mut [f64], x: [&[V]; 4], a: [f64; 4]) {
        let v3 = self.0;
        let n = y.len() / 4 * 4;
        let av = a.map(|a| v3.splat_f64x4(a));
        let (yv, yt) = y.split_at_mut(n);
        for (c, yc) in yv.chunks_exact_mut(4).enumerate() {
            let yc: &mut [f64; 4] = yc.try_into().expect("four values");
            let i = 4 * c;
            let mut acc = pulp::cast(*yc);
            for k in 0..4 {
                acc = v3.mul_add_f64x4(V::load4(v3, &x[k][i..]), av[k], acc);
            }
            *yc = pulp::cast(acc);
        }
        for (i, y) in yt.iter_mut().enumerate() {
            for k in 0..4 {
                *y = x[k][n + i].widen().mul_add(a[k], *y);
            }
        }
    }

    #[inline(always)]
    fn dot<V: Stored>(self, a: &[V], b: &[f64]) -> f64 {
        let v3 = self.0;
        let n = a.len() / 8 * 8;
        let mut acc = [v3.splat_f64x4(0.0); 2];
        for (ac, bc) in a[..n].chunks_exact(8).zip(b[..n].chunks_exact(8)) {
            for h in 0..2 {
                let bv: &[f64; 4] = bc[4 * h..4 * h + 4].try_into().expect("four values");
                acc[h] = v3.mul_add_f64x4(V::load4(v3, &ac[4 * h..]), pulp::cast(*bv), acc[h]);
            }
        }
        let mut s = pulp::Simd::reduce_sum_f64s(v3, v3.add_f64x4(acc[0], acc[1]));
        for (&a, &b) in a[n..].iter().zip(&b[n..]) {
            s = a.widen().mul_add(b, s);
        }
        s
    }
}
