//! Thin SVD that forms only the leading left singular vectors a caller asks for.
//!
//! For a tall A (m × n, m ≥ n): A = QR (Householder), R = U_R Σ Vᵀ, so A = (Q U_R) Σ Vᵀ. This is
//! what faer's own thin SVD does, except that faer applies Q to all n columns of U_R, the most
//! expensive step for a 10⁴ × 2·10³ snapshot matrix, while PCA needs at most `max_dimension`
//! (≤ 300) of them. Here Q is kept in factored form and applied only to the columns asked for.
//! Wide matrices (more snapshots than rows) use faer's thin SVD directly: U is then at most n × n.
//!
//! Measured on 10,002 × 2,000 snapshots (`cargo run -p pca --release --example pca_fit_timing`,
//! 2 threads, two runs on a shared machine): a fit to 300 columns 4.7–6.4 s, faer's thin SVD
//! with its vectors 8.1–18.4 s.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::householder::{
    apply_block_householder_sequence_on_the_left_in_place_scratch,
    apply_block_householder_sequence_on_the_left_in_place_with_conj,
};
use faer::linalg::qr::no_pivoting::factor::{
    qr_in_place, qr_in_place_scratch, recommended_block_size,
};
use faer::{Conj, Mat, MatRef};

use crate::PcaError;

/// How the left singular vectors are held.
#[derive(Debug)]
enum Left {
    /// All thin left singular vectors, explicitly.
    Explicit(Mat<f64>),
    /// Q in Householder form (`qr` below its diagonal, block factors in `coeff`) and U_R.
    Factored {
        qr: Mat<f64>,
        coeff: Mat<f64>,
        u_r: Mat<f64>,
    },
}

/// A = U Σ Vᵀ with U formed on demand.
#[derive(Debug)]
pub(crate) struct ThinSvd {
    /// Singular values, non-increasing, min(m, n) of them.
    pub sigma: Vec<f64>,
    /// Right singular vectors, n × min(m, n).
    pub v: Mat<f64>,
    left: Left,
}

impl ThinSvd {
    /// Decomposes `a` (consumed: its storage holds the QR factors).
    pub fn new(a: Mat<f64>) -> Result<Self, PcaError> {
        let (m, n) = a.shape();
        if m < n {
            let svd = a.thin_svd().map_err(|_| PcaError::SvdNoConvergence)?;
            return Ok(Self {
                sigma: svd.S().column_vector().iter().copied().collect(),
                v: svd.V().to_owned(),
                left: Left::Explicit(svd.U().to_owned()),
            });
        }
        let par = faer::get_global_parallelism();
        let block = recommended_block_size::<f64>(m, n);
        let mut qr = a;
        let mut coeff = Mat::zeros(block, n);
        qr_in_place(
            qr.as_mut(),
            coeff.as_mut(),
            par,
            MemStack::new(&mut MemBuffer::new(qr_in_place_scratch::<f64>(
                m,
                n,
                block,
                par,
                Default::default(),
            ))),
            Default::default(),
        );
        let r = Mat::from_fn(n, n, |i, j| if i <= j { qr[(i, j)] } else { 0.0 });
        let svd = r.thin_svd().map_err(|_| PcaError::SvdNoConvergence)?;
        Ok(Self {
            sigma: svd.S().column_vector().iter().copied().collect(),
            v: svd.V().to_owned(),
            left: Left::Factored {
                qr,
                coeff,
                u_r: svd.U().to_owned(),
            },
        })
    }

    /// Left singular vectors `start..start + count`, m × `count`.
    pub fn left_vectors(&self, start: usize, count: usize) -> Mat<f64> {
        match &self.left {
            Left::Explicit(u) => u.get(.., start..start + count).to_owned(),
            Left::Factored { qr, coeff, u_r } => {
                let (m, n) = qr.shape();
                let mut u = Mat::zeros(m, count);
                u.get_mut(..n, ..)
                    .copy_from(u_r.get(.., start..start + count));
                let par = faer::get_global_parallelism();
                apply_block_householder_sequence_on_the_left_in_place_with_conj(
                    qr.as_ref(),
                    coeff.as_ref(),
                    Conj::No,
                    u.as_mut(),
                    par,
                    MemStack::new(&mut MemBuffer::new(
                        apply_block_householder_sequence_on_the_left_in_place_scratch::<f64>(
                            m,
                            coeff.nrows(),
                            count,
                        ),
                    )),
                );
                u
            }
        }
    }

    /// The right singular vectors V (n × min(m, n)).
    pub fn v(&self) -> MatRef<'_, f64> {
        self.v.as_ref()
    }
}
