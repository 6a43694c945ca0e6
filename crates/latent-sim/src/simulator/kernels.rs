//! The SIMD kernels of the reduced step (under `pulp` dispatch): Bᵀ A B, U J on the element
//! rows, G B, B_e q, A R and one element's Gauss–Newton term in z.

use pulp::{Arch, Simd, WithSimd};
use simd_kernels::rows::{add_combination, dot_rows};

use crate::reduced::PANEL;

/// out = Bᵀ A B for a symmetric A (k×k) and B (k×d), column-major; `ab` is k×d scratch.
pub(crate) fn sandwich(a: &[f64], b: &[f64], k: usize, d: usize, ab: &mut [f64], out: &mut [f64]) {
    Arch::new().dispatch(Sandwich {
        a: &a[..k * k],
        b: &b[..k * d],
        k,
        d,
        ab: &mut ab[..k * d],
        out: &mut out[..d * d],
    });
}

/// Bᵀ A B under SIMD dispatch: A B column by column as combinations of four columns of A at a
/// time (groups of four zero coefficients skipped: B = I for a linear subspace), then Bᵀ(A B) on
/// and below the diagonal by dot products of four columns of B at a time, mirrored, so the
/// result is exactly symmetric.
pub(super) struct Sandwich<'a> {
    pub(super) a: &'a [f64],
    pub(super) b: &'a [f64],
    pub(super) k: usize,
    pub(super) d: usize,
    pub(super) ab: &'a mut [f64],
    pub(super) out: &'a mut [f64],
}

impl WithSimd for Sandwich<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self {
            a,
            b,
            k,
            d,
            ab,
            out,
        } = self;
        fn column(m: &[f64], k: usize, j: usize) -> &[f64] {
            &m[j * k..(j + 1) * k]
        }
        for (bj, abj) in b.chunks_exact(k).zip(ab.chunks_exact_mut(k)) {
            abj.fill(0.0);
            let mut l = 0;
            while l + 4 <= k {
                let c = [bj[l], bj[l + 1], bj[l + 2], bj[l + 3]];
                if c != [0.0; 4] {
                    add_combination(simd, abj, c, std::array::from_fn(|t| column(a, k, l + t)));
                }
                l += 4;
            }
            for l in l..k {
                if bj[l] != 0.0 {
                    add_combination(simd, abj, [bj[l]], [column(a, k, l)]);
                }
            }
        }
        let ab: &[f64] = ab;
        for j in 0..d {
            let abj = column(ab, k, j);
            let mut i = j;
            while i + 4 <= d {
                let r: [f64; 4] = dot_rows(simd, std::array::from_fn(|t| column(b, k, i + t)), abj);
                for (t, &x) in r.iter().enumerate() {
                    out[j * d + i + t] = x;
                    out[(i + t) * d + j] = x;
                }
                i += 4;
            }
            for i in i..d {
                let x = dot_rows(simd, [column(b, k, i)], abj)[0];
                out[j * d + i] = x;
                out[i * d + j] = x;
            }
        }
    }
}

/// U J on the rows of the element vertices (3·n × d, row-major) from the packed rows of U (panels
/// of [`PANEL`] rows) and J (k×d, column-major): four columns of J per pass over a panel, a
/// PANEL × 4 block of accumulators in registers. Exactly J's entries when J = I.
pub(super) struct PanelsTimesJacobian<'a> {
    pub(super) panels: std::slice::ChunksExact<'a, f64>,
    pub(super) rows: usize,
    pub(super) jac: &'a [f64],
    pub(super) k: usize,
    pub(super) d: usize,
    pub(super) uj: &'a mut [f64],
}

impl WithSimd for PanelsTimesJacobian<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let Self {
            panels,
            rows: m,
            jac,
            k,
            d,
            uj,
        } = self;
        for (p, panel) in panels.enumerate() {
            let r0 = p * PANEL;
            if r0 >= m {
                break;
            }
            let rows = PANEL.min(m - r0);
            let mut j = 0;
            while j + 4 <= d {
                panel_columns::<4>(panel, jac, k, j, r0, rows, d, uj);
                j += 4;
            }
            for j in j..d {
                panel_columns::<1>(panel, jac, k, j, r0, rows, d, uj);
            }
        }
    }
}

/// Columns j..j + C of U J on one panel's `rows` rows (from row r0): a PANEL × C block of
/// accumulators over the panel's columns.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn panel_columns<const C: usize>(
    panel: &[f64],
    jac: &[f64],
    k: usize,
    j: usize,
    r0: usize,
    rows: usize,
    d: usize,
    uj: &mut [f64],
) {
    let cols: [&[f64]; C] = std::array::from_fn(|t| &jac[(j + t) * k..(j + t + 1) * k]);
    let mut acc = [[0.0f64; PANEL]; C];
    for (l, c) in panel.chunks_exact(PANEL).enumerate() {
        for t in 0..C {
            let jl = cols[t][l];
            for i in 0..PANEL {
                acc[t][i] += c[i] * jl;
            }
        }
    }
    for i in 0..rows {
        for t in 0..C {
            uj[(r0 + i) * d + j + t] = acc[t][i];
        }
    }
}

/// G B (9×d, row-major) from B = U_e J (12×d, row-major): row 3j + i is Σ_a g_a[j] B[3a + i].
pub(super) struct VertexRowsToF<'a> {
    pub(super) b: &'a [f64],
    pub(super) g: [[f64; 3]; 4],
    pub(super) d: usize,
    pub(super) fb: &'a mut [f64],
}

impl WithSimd for VertexRowsToF<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { b, g, d, fb } = self;
        for j in 0..3 {
            for i in 0..3 {
                let rows = std::array::from_fn(|v| &b[(3 * v + i) * d..(3 * v + i + 1) * d]);
                let out = &mut fb[(3 * j + i) * d..(3 * j + i + 1) * d];
                out.fill(0.0);
                add_combination(simd, out, g.map(|gv| gv[j]), rows);
            }
        }
    }
}

/// vec(F − I) = B_e q on the element-basis path, from the element's 9 basis rows (of `stride`
/// entries, k of them used).
pub(super) struct BasisTimesQ<'a> {
    pub(super) basis: &'a [f64],
    pub(super) stride: usize,
    pub(super) q: &'a [f64],
}

impl WithSimd for BasisTimesQ<'_> {
    type Output = [f64; 9];

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) -> [f64; 9] {
        let Self { basis, stride, q } = self;
        let k = q.len();
        let rows: [&[f64]; 9] = std::array::from_fn(|r| &basis[r * stride..r * stride + k]);
        dot_rows(simd, rows, q)
    }
}

/// The 9 rows of A R into `out` (9 × n, row-major), A a 9×9 stress derivative (column-major)
/// and R 9 rows of length n: each row one fused linear combination of the rows of R.
pub(super) struct StressTimesRows<'a> {
    pub(super) a: &'a [f64; 81],
    pub(super) rows: [&'a [f64]; 9],
    pub(super) out: &'a mut [f64],
}

impl WithSimd for StressTimesRows<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { a, rows, out } = self;
        let n = rows[0].len();
        for (r, out) in out.chunks_exact_mut(n).enumerate() {
            out.fill(0.0);
            add_combination(simd, out, std::array::from_fn(|c| a[c * 9 + r]), rows);
        }
    }
}
