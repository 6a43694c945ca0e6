//! Single-input dense kernels with explicit SIMD, for the per-call operations of [`crate::Mlp`]:
//! y = W x, y = Wᵀ g, the pair (W x, W t), one hidden layer's forward and backward step fused
//! into a single pass over W (VJP), Y = W X (+ P) for the Jacobian's few columns on a packed
//! copy of W (all of W's columns or a list of them), and dot products with and combinations of
//! a list of W's rows. Also the dispatch that compiles the elementwise loops of training (σ, σ', Adam) for the
//! same instruction set.
//!
//! W is row-major `m × n`. The matrix–vector products are bound by reading W (a 200 × 200 layer
//! is 320 kB, in L2), so the kernels stream each row once per call and keep everything else in
//! registers or L1; the fused step reads W from L2 once where a forward then a backward pass
//! would read it twice. The Jacobian's product (200 × 200 × 7) is bound by multiply–adds
//! instead: [`mat_mat_packed`] keeps 12 rows × 4 columns of Y in registers. SIMD goes through
//! `pulp`'s safe API: [`pulp::Arch::dispatch`] picks AVX2 + FMA (or the scalar fallback) at run
//! time, and every helper is `#[inline(always)]` so it is compiled inside the dispatched function
//! with those target features.
//!
//! Every output element of the matrix–vector kernels is computed by one fixed sequence of
//! operations that does not depend on how rows are grouped into register blocks: a row's dot
//! product is one vector accumulator over the full-width chunks of the row (fused multiply–adds,
//! in column order), summed across lanes, then the columns past the last full chunk added in
//! order; Wᵀg adds the rows' contributions to each element in row order, four rows at a time. So
//! [`fused_layer`] gives bit for bit the values of [`mat_vec`] followed by [`mat_t_vec`], and
//! `Mlp::vjp` equals `Mlp::forward` + `Mlp::vjp_cached`.
//!
//! Hand-written over `pulp` rather than left to faer's products because it measured faster on the
//! X decoder 6 → 200 → 200 → 49 (best of rounds, `crates/nn/README.md`): forward 9.1 → 5.6 µs,
//! VJP 14.9 → 7.9 µs, JVP 14.4 → 8.1 µs, Jacobian 25.4 → 17.7 µs.

use pulp::{Arch, Simd, WithSimd};

use simd_kernels::rows as simd;

use crate::Activation;

/// Rows per register block: eight independent dot products hide the fused multiply–add latency
/// (2 units × 4 cycles) while W is streamed.
const ROWS: usize = 8;

/// Rows per register block of the two-vector product: 2 × 4 accumulators, so that they and the
/// two input chunks stay in the 16 AVX2 registers (8 rows spilled to the stack).
const ROWS2: usize = 4;

/// Rows per block of Wᵀg and of the fused layer, whose loop carries 4 dot products of the next
/// block and the 4 gradient updates of the current one (11 registers).
const ROWS_T: usize = 4;

/// `row` split into its full-width SIMD chunks (exactly `chunks` of them) and the remaining
/// columns.
#[inline(always)]
fn split_row<S: Simd>(row: &[f64], chunks: usize) -> (&[S::f64s], &[f64]) {
    let (head, tail) = S::as_simd_f64s(row);
    (&head[..chunks], tail)
}

/// The dot products of the R rows of `w` (R × n, row-major) with x.
#[inline(always)]
fn dot_rows<S: Simd, const R: usize>(simd: S, w: &[f64], x: &[f64]) -> [f64; R] {
    let n = x.len();
    simd::dot_rows(simd, std::array::from_fn(|r| &w[r * n..(r + 1) * n]), x)
}

/// The dot products of the R rows of `w` with x and with t, sharing the loads of W. Each of
/// the two results is computed exactly as [`dot_rows`] computes it.
#[inline(always)]
fn dot2_rows<S: Simd, const R: usize>(
    simd: S,
    w: &[f64],
    x: &[f64],
    t: &[f64],
) -> ([f64; R], [f64; R]) {
    let n = x.len();
    let (xv, xt) = S::as_simd_f64s(x);
    let chunks = xv.len();
    let (tv, tt) = split_row::<S>(t, chunks);
    let rows: [(&[S::f64s], &[f64]); R] =
        std::array::from_fn(|r| split_row::<S>(&w[r * n..(r + 1) * n], chunks));
    let mut acc = [simd.splat_f64s(0.0); R];
    let mut tan = [simd.splat_f64s(0.0); R];
    for (k, (&x, &t)) in xv.iter().zip(tv).enumerate() {
        for r in 0..R {
            let w = rows[r].0[k];
            acc[r] = simd.mul_add_e_f64s(w, x, acc[r]);
            tan[r] = simd.mul_add_e_f64s(w, t, tan[r]);
        }
    }
    let finish = |acc: &[S::f64s; R], x: &[f64]| -> [f64; R] {
        std::array::from_fn(|r| {
            let mut s = simd.reduce_sum_f64s(acc[r]);
            for (w, x) in rows[r].1.iter().zip(x) {
                s += w * x;
            }
            s
        })
    };
    (finish(&acc, xt), finish(&tan, tt))
}

/// y += Σ_r g_r W[r, :] over the R rows of `w` (R × n, row-major), rows in order.
#[inline(always)]
fn add_rows<S: Simd, const R: usize>(simd: S, y: &mut [f64], w: &[f64], g: &[f64; R]) {
    let n = y.len();
    simd::add_combination(simd, y, *g, std::array::from_fn(|r| &w[r * n..(r + 1) * n]));
}

/// The dot products of the R rows of `w_next` with x (exactly as [`dot_rows`]) and, in the same
/// sweep over the columns, y += Σ_r g_r W[r, :] over the R rows of `w` (exactly as
/// [`add_rows`]): the streaming of the next rows from L2 overlaps the update from the current
/// rows, which are in L1.
#[inline(always)]
fn dot_add_rows<S: Simd, const R: usize>(
    simd: S,
    w_next: &[f64],
    x: &[f64],
    y: &mut [f64],
    w: &[f64],
    g: &[f64; R],
) -> [f64; R] {
    let n = x.len();
    let (xv, xt) = S::as_simd_f64s(x);
    let chunks = xv.len();
    let (yv, yt) = S::as_mut_simd_f64s(y);
    let yv = &mut yv[..chunks];
    let next: [(&[S::f64s], &[f64]); R] =
        std::array::from_fn(|r| split_row::<S>(&w_next[r * n..(r + 1) * n], chunks));
    let rows: [(&[S::f64s], &[f64]); R] =
        std::array::from_fn(|r| split_row::<S>(&w[r * n..(r + 1) * n], chunks));
    let gs = g.map(|g| simd.splat_f64s(g));
    let mut acc = [simd.splat_f64s(0.0); R];
    for (k, (&x, y)) in xv.iter().zip(yv).enumerate() {
        let mut sum = *y;
        for r in 0..R {
            acc[r] = simd.mul_add_e_f64s(next[r].0[k], x, acc[r]);
            sum = simd.mul_add_e_f64s(gs[r], rows[r].0[k], sum);
        }
        *y = sum;
    }
    for (j, y) in yt.iter_mut().enumerate() {
        for r in 0..R {
            *y += g[r] * rows[r].1[j];
        }
    }
    std::array::from_fn(|r| {
        let mut s = simd.reduce_sum_f64s(acc[r]);
        for (w, x) in next[r].1.iter().zip(xt) {
            s += w * x;
        }
        s
    })
}

struct MatVec<'a> {
    y: &'a mut [f64],
    w: &'a [f64],
    x: &'a [f64],
}

impl WithSimd for MatVec<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { y, w, x } = self;
        let (m, n) = (y.len(), x.len());
        let full = m - m % ROWS;
        for i in (0..full).step_by(ROWS) {
            y[i..i + ROWS].copy_from_slice(&dot_rows::<S, ROWS>(
                simd,
                &w[i * n..(i + ROWS) * n],
                x,
            ));
        }
        for i in full..m {
            y[i] = dot_rows::<S, 1>(simd, &w[i * n..(i + 1) * n], x)[0];
        }
    }
}

/// y (m) = W (m × n, row-major) · x (n).
pub(crate) fn mat_vec(y: &mut [f64], w: &[f64], x: &[f64], m: usize, n: usize) {
    Arch::new().dispatch(MatVec {
        y: &mut y[..m],
        w: &w[..m * n],
        x: &x[..n],
    });
}

struct DenseLayer<'a> {
    act: Activation,
    h: &'a mut [f64],
    pre: Option<&'a mut [f64]>,
    w: &'a [f64],
    b: &'a [f64],
    x: &'a [f64],
}

impl WithSimd for DenseLayer<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self {
            act,
            h,
            pre,
            w,
            b,
            x,
        } = self;
        MatVec { y: h, w, x }.with_simd(simd);
        if let Some(pre) = pre {
            pre.iter_mut()
                .zip(h.iter().zip(b))
                .for_each(|(a, (h, b))| *a = h + b);
        }
        act.apply_biased(h, b);
    }
}

/// h (m) = σ(W x + b) with W (m × n, row-major): [`mat_vec`] and [`Activation::apply_biased`]
/// in one dispatch, so that σ is compiled with the SIMD target features too; also the
/// pre-activation W x + b into `pre` when given.
pub(crate) fn dense_layer(
    act: Activation,
    h: &mut [f64],
    pre: Option<&mut [f64]>,
    w: &[f64],
    b: &[f64],
    x: &[f64],
) {
    let (m, n) = (b.len(), x.len());
    Arch::new().dispatch(DenseLayer {
        act,
        h: &mut h[..m],
        pre: pre.map(|p| &mut p[..m]),
        w: &w[..m * n],
        b,
        x,
    });
}

/// Elementwise work run by [`vectorized`].
pub(crate) trait Elementwise {
    /// The loops; `#[inline(always)]` in every implementation, and everything they call too.
    fn run(self);
}

struct Vectorized<E>(E);

impl<E: Elementwise> WithSimd for Vectorized<E> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        self.0.run();
    }
}

/// Runs elementwise loops that the compiler vectorises (σ, σ', Adam) compiled with the SIMD
/// target features [`Arch::dispatch`] picks (AVX2 + FMA here), which doubles their width over
/// the baseline SSE2. The arithmetic is the same IEEE operations, so the results are identical.
/// (A closure is not enough: it is compiled as a function of its own, without the features.)
pub(crate) fn vectorized(work: impl Elementwise) {
    Arch::new().dispatch(Vectorized(work));
}

/// x ← σ(x + b) for every column x of a block, see [`Activation::apply_biased`].
pub(crate) struct ApplyBiased<'a>(pub Activation, pub &'a mut [f64], pub &'a [f64]);

impl Elementwise for ApplyBiased<'_> {
    #[inline(always)]
    fn run(self) {
        self.0.apply_biased(self.1, self.2);
    }
}

/// g ← σ'(a) ⊙ g given h = σ(a), see [`Activation::scale_by_derivative`].
pub(crate) struct ScaleByDerivative<'a>(pub Activation, pub &'a [f64], pub &'a mut [f64]);

impl Elementwise for ScaleByDerivative<'_> {
    #[inline(always)]
    fn run(self) {
        self.0.scale_by_derivative(self.1, self.2);
    }
}

struct Activate<'a> {
    act: Activation,
    h: &'a mut [f64],
    b: &'a [f64],
    d: &'a mut [f64],
}

impl WithSimd for Activate<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let Self { act, h, b, d } = self;
        act.apply_biased(h, b);
        d.fill(1.0);
        act.scale_by_derivative(h, d);
    }
}

/// h ← σ(h + b) and d = σ'(h), compiled with the SIMD target features (σ is the bulk of the
/// work outside the matrix products).
pub(crate) fn activate(act: Activation, h: &mut [f64], b: &[f64], d: &mut [f64]) {
    let n = b.len();
    Arch::new().dispatch(Activate {
        act,
        h: &mut h[..n],
        b,
        d: &mut d[..n],
    });
}

struct MatVec2<'a> {
    y: &'a mut [f64],
    s: &'a mut [f64],
    w: &'a [f64],
    x: &'a [f64],
    t: &'a [f64],
}

impl WithSimd for MatVec2<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { y, s, w, x, t } = self;
        let (m, n) = (y.len(), x.len());
        let full = m - m % ROWS2;
        for i in (0..full).step_by(ROWS2) {
            let (a, b) = dot2_rows::<S, ROWS2>(simd, &w[i * n..(i + ROWS2) * n], x, t);
            y[i..i + ROWS2].copy_from_slice(&a);
            s[i..i + ROWS2].copy_from_slice(&b);
        }
        for i in full..m {
            let (a, b) = dot2_rows::<S, 1>(simd, &w[i * n..(i + 1) * n], x, t);
            (y[i], s[i]) = (a[0], b[0]);
        }
    }
}

/// y = W x and s = W t (W m × n, row-major) in one pass over W; y is bit-identical to
/// [`mat_vec`]'s.
pub(crate) fn mat_vec2(
    y: &mut [f64],
    s: &mut [f64],
    w: &[f64],
    x: &[f64],
    t: &[f64],
    m: usize,
    n: usize,
) {
    Arch::new().dispatch(MatVec2 {
        y: &mut y[..m],
        s: &mut s[..m],
        w: &w[..m * n],
        x: &x[..n],
        t: &t[..n],
    });
}

struct MatTVec<'a> {
    y: &'a mut [f64],
    w: &'a [f64],
    g: &'a [f64],
}

impl WithSimd for MatTVec<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { y, w, g } = self;
        let n = y.len();
        y.fill(0.0);
        let mut blocks = g.chunks_exact(ROWS_T);
        for (g, w) in (&mut blocks).zip(w.chunks_exact(ROWS_T * n)) {
            let g: &[f64; ROWS_T] = g.try_into().expect("a block of ROWS_T gradients");
            add_rows::<S, ROWS_T>(simd, y, w, g);
        }
        let done = g.len() - blocks.remainder().len();
        for (i, &g) in g.iter().enumerate().skip(done) {
            add_rows::<S, 1>(simd, y, &w[i * n..(i + 1) * n], &[g]);
        }
    }
}

/// y (n) = Wᵀ g (g of length m), with W stored as (m × n) row-major.
pub(crate) fn mat_t_vec(y: &mut [f64], w: &[f64], g: &[f64], m: usize, n: usize) {
    Arch::new().dispatch(MatTVec {
        y: &mut y[..n],
        w: &w[..m * n],
        g: &g[..m],
    });
}

/// The rows `rows` of a row-major W with rows of length `n`.
#[inline(always)]
fn listed<'a, const R: usize>(w: &'a [f64], n: usize, rows: &[u32]) -> [&'a [f64]; R] {
    std::array::from_fn(|r| {
        let i = rows[r] as usize;
        &w[i * n..(i + 1) * n]
    })
}

struct ListedRowsVec<'a> {
    t: &'a mut [f64],
    w: &'a [f64],
    rows: &'a [u32],
    x: &'a [f64],
}

impl WithSimd for ListedRowsVec<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { t, w, rows, x } = self;
        let n = x.len();
        let mut blocks = rows.chunks_exact(ROWS);
        for (rows, t) in (&mut blocks).zip(t.chunks_exact_mut(ROWS)) {
            t.copy_from_slice(&simd::dot_rows(simd, listed::<ROWS>(w, n, rows), x));
        }
        let done = rows.len() - blocks.remainder().len();
        for (r, t) in rows[done..].iter().zip(&mut t[done..]) {
            *t = simd::dot_rows(simd, listed::<1>(w, n, &[*r]), x)[0];
        }
    }
}

/// t_r = W[rows_r, :] · x for every listed row of W (row-major, rows of length `x.len()`),
/// each computed as [`mat_vec`] computes a row.
pub(crate) fn listed_rows_vec(t: &mut [f64], w: &[f64], rows: &[u32], x: &[f64]) {
    Arch::new().dispatch(ListedRowsVec {
        t: &mut t[..rows.len()],
        w,
        rows,
        x,
    });
}

struct AddListedRows<'a> {
    y: &'a mut [f64],
    w: &'a [f64],
    rows: &'a [u32],
    g: &'a [f64],
}

impl WithSimd for AddListedRows<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { y, w, rows, g } = self;
        let n = y.len();
        let mut blocks = rows.chunks_exact(ROWS_T);
        for (rows, g) in (&mut blocks).zip(g.chunks_exact(ROWS_T)) {
            let g: [f64; ROWS_T] = g.try_into().expect("a block of ROWS_T coefficients");
            simd::add_combination(simd, y, g, listed::<ROWS_T>(w, n, rows));
        }
        let done = rows.len() - blocks.remainder().len();
        for (r, &g) in rows[done..].iter().zip(&g[done..]) {
            simd::add_combination(simd, y, [g], listed::<1>(w, n, &[*r]));
        }
    }
}

/// y += Σ_r g_r W[rows_r, :] over the listed rows of W (row-major, rows of length `y.len()`),
/// in list order.
pub(crate) fn add_listed_rows(y: &mut [f64], w: &[f64], rows: &[u32], g: &[f64]) {
    Arch::new().dispatch(AddListedRows {
        y,
        w,
        rows,
        g: &g[..rows.len()],
    });
}

/// One hidden layer's forward and backward step, see [`fused_layer`].
struct FusedLayer<'a> {
    act: Activation,
    w: &'a [f64],
    b: &'a [f64],
    x: &'a [f64],
    u: &'a [f64],
    h: &'a mut [f64],
    gx: &'a mut [f64],
}

impl FusedLayer<'_> {
    /// h = σ(a + b) and g = σ'(h) ⊙ u for rows `i..i + R` with pre-activations W x = `a`.
    /// On a fixed-size array, so that σ vectorises (on a slice of unknown length the compiler
    /// left it scalar).
    #[inline(always)]
    fn activate<const R: usize>(&mut self, i: usize, a: [f64; R]) -> [f64; R] {
        let mut h: [f64; R] = std::array::from_fn(|r| a[r] + self.b[i + r]);
        self.act.apply_in_place(&mut h);
        self.h[i..i + R].copy_from_slice(&h);
        let mut g: [f64; R] = self.u[i..i + R].try_into().expect("R cotangents");
        self.act.scale_by_derivative(&h, &mut g);
        g
    }
}

impl WithSimd for FusedLayer<'_> {
    type Output = ();

    /// A software pipeline over blocks of [`ROWS_T`] rows: block i's gradient update runs in
    /// the same sweep as block i + 1's dot products. The remaining rows go one at a time.
    #[inline(always)]
    fn with_simd<S: Simd>(mut self, simd: S) {
        const R: usize = ROWS_T;
        let (m, n) = (self.h.len(), self.x.len());
        let (w, x) = (self.w, self.x);
        self.gx.fill(0.0);
        let full = m - m % R;
        if full > 0 {
            let mut a = dot_rows::<S, R>(simd, &w[..R * n], x);
            for i in (0..full).step_by(R) {
                let g = self.activate(i, a);
                let rows = &w[i * n..(i + R) * n];
                if i + R < full {
                    let next = &w[(i + R) * n..(i + 2 * R) * n];
                    a = dot_add_rows::<S, R>(simd, next, x, self.gx, rows, &g);
                } else {
                    add_rows::<S, R>(simd, self.gx, rows, &g);
                }
            }
        }
        for i in full..m {
            let row = &w[i * n..(i + 1) * n];
            let a = dot_rows::<S, 1>(simd, row, x);
            let g = self.activate(i, a);
            add_rows::<S, 1>(simd, self.gx, row, &g);
        }
    }
}

/// One hidden layer h = σ(W x + b) (W m × n, row-major) and its backward step in one pass over
/// W: given u = ∂ℒ/∂h (length m), gx = Wᵀ (σ'(h) ⊙ u) = ∂ℒ/∂x (length n). h and gx are
/// bit-identical to [`mat_vec`], [`Activation::apply_biased`], [`Activation::scale_by_derivative`]
/// and [`mat_t_vec`] in sequence.
pub(crate) fn fused_layer(
    act: Activation,
    w: &[f64],
    b: &[f64],
    x: &[f64],
    u: &[f64],
    h: &mut [f64],
    gx: &mut [f64],
) {
    let (m, n) = (b.len(), x.len());
    Arch::new().dispatch(FusedLayer {
        act,
        w: &w[..m * n],
        b,
        x,
        u: &u[..m],
        h: &mut h[..m],
        gx: &mut gx[..n],
    });
}

pub(crate) use simd_kernels::lanes;

/// SIMD vectors of rows per panel of [`pack_rows`]: 3 × 4 accumulators per column group and the
/// three weight vectors fill 15 of the 16 AVX2 registers.
const PANEL: usize = 3;
/// Columns of X per register block of [`mat_mat_packed`].
const COLS: usize = 4;

/// m rounded up to a multiple of `lanes`: the rows a packed W (and its product) has.
pub(crate) fn padded_rows(m: usize, lanes: usize) -> usize {
    m.div_ceil(lanes) * lanes
}

/// The length of [`pack_rows`]' output for an `m × n` matrix.
pub(crate) fn packed_len(m: usize, n: usize, lanes: usize) -> usize {
    padded_rows(m, lanes) * n
}

/// Packs W (m × n, row-major) for [`mat_mat_packed`]: the rows, padded with zeros to a multiple
/// of `lanes`, in panels of up to [`PANEL`] × `lanes` rows; a panel of width p stores, for each
/// column j in order, its p entries W[i₀..i₀ + p, j] contiguously. So the kernel reads each panel
/// front to back, one SIMD vector of rows at a time.
pub(crate) fn pack_rows(dst: &mut [f64], w: &[f64], m: usize, n: usize, lanes: usize) {
    let mp = padded_rows(m, lanes);
    let dst = &mut dst[..mp * n];
    let mut start = 0;
    for i0 in (0..mp).step_by(PANEL * lanes) {
        let p = (PANEL * lanes).min(mp - i0);
        for (j, col) in dst[start..start + p * n].chunks_exact_mut(p).enumerate() {
            for (r, d) in col.iter_mut().enumerate() {
                let i = i0 + r;
                *d = if i < m { w[i * n + j] } else { 0.0 };
            }
        }
        start += p * n;
    }
}

/// The operands of Y[:, y0..y0 + c] = W X[:, x0..x0 + c] (+ P) for [`mat_mat_packed`].
pub(crate) struct Product<'a> {
    /// Y, row-major with leading dimension `ldy` and m̃ = [`padded_rows`] rows (the padding
    /// rows get 0, or P's).
    pub y: &'a mut [f64],
    pub ldy: usize,
    /// The first column of Y written.
    pub y0: usize,
    /// W (m × n), packed by [`pack_rows`] with this machine's [`lanes`].
    pub packed: &'a [f64],
    pub m: usize,
    pub n: usize,
    /// X (n rows, or one per entry of `support`, × ≥ x0 + c), row-major with leading dimension
    /// `ldx`.
    pub x: &'a [f64],
    pub ldx: usize,
    /// The first column of X read.
    pub x0: usize,
    /// The number of columns.
    pub c: usize,
    /// The columns of W that X's rows multiply, in order (None: all n): Y = W[:, support] X,
    /// at c multiply–adds per row of Y and row of X.
    pub support: Option<&'a [u32]>,
    /// P, a matrix with Y's layout added to the product (None: nothing).
    pub plus: Option<&'a [f64]>,
}

/// The shape of one panel's product, shared by its column groups.
#[derive(Clone, Copy)]
struct Block<'a> {
    ldy: usize,
    y0: usize,
    row0: usize,
    x: &'a [f64],
    ldx: usize,
    x0: usize,
    support: Option<&'a [u32]>,
    plus: Option<&'a [f64]>,
}

/// Columns `col0..col0 + C` of one panel (V vectors of rows, from `row0`) of Y = W X.
#[inline(always)]
fn panel_block<S: Simd, const V: usize, const C: usize>(
    simd: S,
    y: &mut [f64],
    panel: &[S::f64s],
    b: Block<'_>,
    col0: usize,
) {
    // A function, not a closure: a closure that is not inlined is compiled without the
    // dispatch's target features, and this loop then ran 30× slower.
    #[inline(always)]
    fn step<S: Simd, const V: usize, const C: usize>(
        simd: S,
        acc: &mut [[S::f64s; V]; C],
        w: &[S::f64s],
        x: &[f64],
    ) {
        for c in 0..C {
            let s = simd.splat_f64s(x[c]);
            for v in 0..V {
                acc[c][v] = simd.mul_add_e_f64s(w[v], s, acc[c][v]);
            }
        }
    }
    let mut acc = [[simd.splat_f64s(0.0); V]; C];
    let first = b.x0 + col0;
    match b.support {
        None => {
            for (w, xr) in panel.chunks_exact(V).zip(b.x.chunks_exact(b.ldx)) {
                step::<S, V, C>(simd, &mut acc, w, &xr[first..first + C]);
            }
        }
        Some(cols) => {
            let (panel, _) = panel.as_chunks::<V>();
            for (&j, xr) in cols.iter().zip(b.x.chunks_exact(b.ldx)) {
                step::<S, V, C>(simd, &mut acc, &panel[j as usize], &xr[first..first + C]);
            }
        }
    }
    // Scattered to the rows of Y: a few stores per panel, against n·V·C multiply–adds.
    let lanes = S::F64_LANES;
    let mut buf = [0.0; 16];
    for c in 0..C {
        for v in 0..V {
            simd.partial_store_f64s(&mut buf[..lanes], acc[c][v]);
            for (r, &a) in buf[..lanes].iter().enumerate() {
                let at = (b.row0 + v * lanes + r) * b.ldy + b.y0 + col0 + c;
                y[at] = match b.plus {
                    Some(p) => a + p[at],
                    None => a,
                };
            }
        }
    }
}

/// All column groups of one panel of V vectors of rows.
#[inline(always)]
fn panel<S: Simd, const V: usize>(
    simd: S,
    y: &mut [f64],
    panel: &[S::f64s],
    b: Block<'_>,
    c: usize,
) {
    // Groups of 4 columns, but 3 + 3 for 6 and 3 + 2 for 5: a group of C columns has 3C
    // independent accumulators, and fewer than 9 cannot cover the multiply–add latency.
    let mut col0 = 0;
    while col0 < c {
        let group = match c - col0 {
            rest @ 1..=4 => rest,
            5 | 6 => 3,
            _ => COLS,
        };
        match group {
            1 => panel_block::<S, V, 1>(simd, y, panel, b, col0),
            2 => panel_block::<S, V, 2>(simd, y, panel, b, col0),
            3 => panel_block::<S, V, 3>(simd, y, panel, b, col0),
            _ => panel_block::<S, V, COLS>(simd, y, panel, b, col0),
        }
        col0 += group;
    }
}

impl WithSimd for Product<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self {
            y,
            ldy,
            y0,
            packed,
            m,
            n,
            x,
            ldx,
            x0,
            c,
            support,
            plus,
        } = self;
        let lanes = S::F64_LANES;
        let mp = padded_rows(m, lanes);
        let (packed, _) = S::as_simd_f64s(&packed[..mp * n]);
        let x = &x[..support.map_or(n, <[u32]>::len) * ldx];
        let mut start = 0;
        for i0 in (0..mp).step_by(PANEL * lanes) {
            let v = PANEL.min((mp - i0) / lanes);
            let p = &packed[start..start + v * n];
            let b = Block {
                ldy,
                y0,
                row0: i0,
                x,
                ldx,
                x0,
                support,
                plus,
            };
            match v {
                1 => panel::<S, 1>(simd, y, p, b, c),
                2 => panel::<S, 2>(simd, y, p, b, c),
                _ => panel::<S, PANEL>(simd, y, p, b, c),
            }
            start += v * n;
        }
    }
}

/// Y[:, y0..y0 + c] = W X[:, x0..x0 + c] (+ P), see [`Product`]. The rows of W are in SIMD
/// lanes, so X is only broadcast and there is no horizontal sum: for the Jacobian's
/// 200 × 200 × 7 products this runs near the fused multiply–add throughput.
///
/// # Panics
/// If a leading dimension is too small for its columns, Y or P is too short for m̃ rows, X is
/// too short for its rows, or a listed column of W is not below n.
pub(crate) fn mat_mat_packed(product: Product<'_>) {
    let rows = padded_rows(product.m, lanes()) * product.ldy;
    assert!(
        product.ldy >= product.y0 + product.c && product.ldx >= product.x0 + product.c,
        "leading dimensions"
    );
    assert!(product.y.len() >= rows, "output length");
    assert!(product.plus.is_none_or(|p| p.len() >= rows), "P's length");
    assert!(
        product
            .support
            .is_none_or(|s| s.iter().all(|&j| (j as usize) < product.n)),
        "support columns"
    );
    Arch::new().dispatch(product);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SplitMix64;

    fn random(rng: &mut SplitMix64, n: usize) -> Vec<f64> {
        (0..n).map(|_| rng.range(-1.0, 1.0)).collect()
    }

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.iter()
            .zip(b)
            .all(|(a, b)| (a - b).abs() <= 1e-13 * (1.0 + a.abs().max(b.abs())))
    }

    /// Sizes around the SIMD width and the row block, including 1 and odd ones.
    const SIZES: [usize; 10] = [1, 2, 3, 5, 7, 8, 9, 17, 31, 200];

    #[test]
    fn kernels_match_plain_loops_on_odd_sizes() {
        let mut rng = SplitMix64::new(3);
        for m in SIZES {
            for n in SIZES {
                let w = random(&mut rng, m * n);
                let (x, t, g) = (
                    random(&mut rng, n),
                    random(&mut rng, n),
                    random(&mut rng, m),
                );
                let wx: Vec<f64> = (0..m)
                    .map(|i| (0..n).map(|j| w[i * n + j] * x[j]).sum())
                    .collect();
                let wt: Vec<f64> = (0..m)
                    .map(|i| (0..n).map(|j| w[i * n + j] * t[j]).sum())
                    .collect();
                let wtg: Vec<f64> = (0..n)
                    .map(|j| (0..m).map(|i| w[i * n + j] * g[i]).sum())
                    .collect();
                let mut y = vec![f64::NAN; m];
                mat_vec(&mut y, &w, &x, m, n);
                assert!(close(&y, &wx), "W x, {m} × {n}");
                let (mut y2, mut s) = (vec![f64::NAN; m], vec![f64::NAN; m]);
                mat_vec2(&mut y2, &mut s, &w, &x, &t, m, n);
                assert_eq!(y2, y, "W x beside W t, {m} × {n}");
                assert!(close(&s, &wt), "W t, {m} × {n}");
                let mut z = vec![f64::NAN; n];
                mat_t_vec(&mut z, &w, &g, m, n);
                assert!(close(&z, &wtg), "Wᵀ g, {m} × {n}");
            }
        }
    }

    #[test]
    fn fused_layer_is_bit_identical_to_the_separate_passes() {
        let mut rng = SplitMix64::new(4);
        for act in Activation::ALL {
            for m in SIZES {
                for n in SIZES {
                    let w = random(&mut rng, m * n);
                    let (b, x, u) = (
                        random(&mut rng, m),
                        random(&mut rng, n),
                        random(&mut rng, m),
                    );
                    let mut h = vec![f64::NAN; m];
                    mat_vec(&mut h, &w, &x, m, n);
                    act.apply_biased(&mut h, &b);
                    let mut g = u.clone();
                    act.scale_by_derivative(&h, &mut g);
                    let mut gx = vec![f64::NAN; n];
                    mat_t_vec(&mut gx, &w, &g, m, n);
                    // Against a plain loop too, so the shared pieces cannot both be wrong.
                    let plain: Vec<f64> = (0..n)
                        .map(|j| (0..m).map(|i| w[i * n + j] * g[i]).sum())
                        .collect();
                    assert!(close(&gx, &plain), "{act} {m} × {n}");
                    let mut h1 = vec![f64::NAN; m];
                    dense_layer(act, &mut h1, None, &w, &b, &x);
                    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&h1), bits(&h), "{act} dense layer, {m} × {n}");
                    let (mut h2, mut gx2) = (vec![f64::NAN; m], vec![f64::NAN; n]);
                    fused_layer(act, &w, &b, &x, &u, &mut h2, &mut gx2);
                    assert_eq!(bits(&h2), bits(&h), "{act} h, {m} × {n}");
                    assert_eq!(bits(&gx2), bits(&gx), "{act} gx, {m} × {n}");
                }
            }
        }
    }

    #[test]
    fn packed_product_matches_a_plain_loop_on_odd_sizes() {
        let mut rng = SplitMix64::new(5);
        let lanes = lanes();
        for m in SIZES {
            for n in [1, 3, 6, 17, 200] {
                for c in [1, 2, 3, 4, 5, 6, 7, 9] {
                    let w = random(&mut rng, m * n);
                    let mut packed = vec![f64::NAN; packed_len(m, n, lanes)];
                    pack_rows(&mut packed, &w, m, n, lanes);
                    // Leading dimensions and a first column beyond the minimum, to catch
                    // stride mistakes.
                    let (x0, ldx, ldy) = (1, c + 3, c + 2);
                    let x = random(&mut rng, n * ldx);
                    let mp = padded_rows(m, lanes);
                    let mut y = vec![f64::NAN; mp * ldy];
                    let product = |y, support, plus| Product {
                        y,
                        ldy,
                        y0: 1,
                        packed: &packed,
                        m,
                        n,
                        x: &x,
                        ldx,
                        x0,
                        c,
                        support,
                        plus,
                    };
                    mat_mat_packed(product(&mut y, None, None));
                    // Every third column of W, times those rows of X gathered, plus a P.
                    let rows: Vec<u32> = (0..n as u32).filter(|j| j % 3 == 1).collect();
                    let gathered: Vec<f64> = rows
                        .iter()
                        .flat_map(|&j| &x[j as usize * ldx..(j as usize + 1) * ldx])
                        .copied()
                        .collect();
                    let p = random(&mut rng, mp * ldy);
                    let mut y_sparse = vec![f64::NAN; mp * ldy];
                    mat_mat_packed(Product {
                        x: &gathered,
                        ..product(&mut y_sparse, Some(&rows), Some(&p))
                    });
                    for k in 0..c {
                        let plain = |j_used: &dyn Fn(usize) -> bool| -> Vec<f64> {
                            (0..m)
                                .map(|i| {
                                    (0..n)
                                        .filter(|&j| j_used(j))
                                        .map(|j| w[i * n + j] * x[j * ldx + x0 + k])
                                        .sum()
                                })
                                .collect()
                        };
                        let col = |y: &[f64]| -> Vec<f64> {
                            (0..mp).map(|i| y[i * ldy + 1 + k]).collect()
                        };
                        let dense = col(&y);
                        assert!(
                            close(&dense[..m], &plain(&|_| true)),
                            "{m} × {n} × {c}, column {k}"
                        );
                        assert!(dense[m..].iter().all(|&p| p == 0.0), "padding rows");
                        let sparse: Vec<f64> = plain(&|j| j % 3 == 1)
                            .iter()
                            .chain(&vec![0.0; mp - m])
                            .enumerate()
                            .map(|(i, s)| s + p[i * ldy + 1 + k])
                            .collect();
                        assert!(
                            close(&col(&y_sparse), &sparse),
                            "{m} × {n} × {c} on rows 1, 4, …, column {k}"
                        );
                    }
                    assert!(
                        y.chunks_exact(ldy)
                            .all(|r| r[0].is_nan() && r[c + 1].is_nan()),
                        "columns beside Y"
                    );
                }
            }
        }
    }
}
