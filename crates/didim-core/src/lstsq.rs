//! QR least squares with covariance: the estimator of the paper's eqs. (11)-(15).
//!
//! The identification model is `Y = W χ + ρ` (eq. (11)), with `W` the `r × n`
//! (decimated) regressor, `Y` the `r` stacked measurements and `ρ` the error.
//! The estimate `χ̂` minimises `‖Y − W χ‖` (eq. (12)) and is computed with a
//! column-pivoted Householder QR factorisation of `W` (faer's
//! `linalg::qr::col_pivoting`); `WᵀW` is never formed.
//!
//! # Rank and base parameters
//!
//! Let `W P = Q R` be the pivoted factorisation (`|R_00| ≥ |R_11| ≥ …`). With the
//! relative tolerance `τ` of [`LstsqOptions::rank_tol`], the numerical rank `b` is
//! the number of leading pivots with `|R_kk| > τ·|R_00|`.
//!
//! When `b < n`, `b` independent columns — the *base columns*, whose parameters are
//! the base parameters — are kept and the others are regrouped onto them. The base
//! columns are chosen in **index order** (Gautier's convention for numerical base
//! parameters): column `j` is a base column when its distance to the span of the
//! base columns of lower index exceeds `τ·|R_00|`, so a dependent column is always
//! expressed through columns listed before it and the caller controls which
//! parameters are kept by ordering the columns. This selection is done on the small
//! `n × n` factor (`W = Q_thin R Pᵀ`, so the columns of `R Pᵀ` have exactly the
//! geometry of the columns of `W`), not on `W` itself. In the rare borderline case
//! where that index-order scan does not find exactly `b` columns (a column sitting
//! right at the tolerance), the first `b` pivot columns of the QR are used instead.
//! When `b == n` all columns are base columns.
//!
//! The estimate is the least-squares solution on the base columns (the dependent
//! parameters are set to zero and reported in [`LstsqSolution::dependencies`]), and
//! eqs. (13)-(15) are evaluated with the triangular factor `R_B` of the base columns:
//! `(W_BᵀW_B)⁻¹ = R_B⁻¹ R_B⁻ᵀ`.

use crate::error::{invalid, Error, Result};
use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::householder::{
    apply_block_householder_sequence_transpose_on_the_left_in_place_scratch,
    apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj,
};
use faer::linalg::qr::col_pivoting::factor::{qr_in_place, qr_in_place_scratch};
use faer::linalg::qr::no_pivoting::factor::recommended_block_size;
use faer::linalg::svd::{svd, svd_scratch, ComputeSvdVectors};
use faer::linalg::triangular_solve::solve_upper_triangular_in_place;
use faer::{Conj, Mat, MatRef, Par};

/// The QR factorisation and the application of `Qᵀ` run on one thread, whatever the size of
/// `W`: faer's parallel blocks round differently with each thread count, and a robot's DIDIM,
/// whose iterations wander within their tolerance, carried that to its results (a held-out
/// Panda's base fit at 3.32 % on one thread, 3.44 % on two; its validation record simulable on
/// one, not on the other). On a 7-joint arm's system (10,500 × 63) one thread took 13.6 ms,
/// two 23 ms (criterion, `benches/lstsq.rs`); the batches of simulations are where the threads
/// pay.
const PAR: Par = Par::Seq;

/// How the noise standard deviation `σ̂ρ` is estimated from the residual
/// `e = Y − W χ̂`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SigmaConvention {
    /// The paper's unbiased estimate, eq. (13): `σ̂ρ² = ‖e‖² / (r − b)`, with `r`
    /// the number of rows and `b` the rank (number of base parameters).
    #[default]
    Paper,
    /// Sample standard deviation of the residual with its mean removed and an
    /// `r − 1` denominator: `σ̂ρ² = Σ (e_i − ē)² / (r − 1)`, i.e. MATLAB's
    /// `std(e)`. Needed to reproduce the σ published with the EMPS benchmark.
    SampleStd,
}

/// Options of [`lstsq`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LstsqOptions {
    /// Relative rank tolerance `τ`: pivot `k` of the column-pivoted QR counts
    /// towards the rank when `|R_kk| > τ·|R_00|` (the rank is the number of leading
    /// pivots passing this test). The same absolute threshold `τ·|R_00|` decides
    /// which columns are base columns (see the module documentation).
    ///
    /// `None` (the default) means `τ = max(r, n)·f64::EPSILON`, the usual
    /// LAPACK/NumPy-style rule (`numpy.linalg.matrix_rank` uses
    /// `σ_max·max(r, n)·ε` on the singular values). `Some(τ)` must be finite and
    /// in `[0, 1)`.
    pub rank_tol: Option<f64>,
    /// Estimator of `σ̂ρ` used in eq. (14).
    pub sigma: SigmaConvention,
}

impl Default for LstsqOptions {
    /// `rank_tol: None` (i.e. `max(r, n)·ε`) and the paper's eq. (13) σ.
    fn default() -> Self {
        Self {
            rank_tol: None,
            sigma: SigmaConvention::Paper,
        }
    }
}

/// A non-base column expressed through the base columns:
/// `W[:, column] ≈ Σ coef · W[:, base_col]` over `combination`.
///
/// The coefficients are the least-squares coefficients of `W[:, column]` on the
/// base columns. Terms whose contribution `|coef|·‖W[:, base_col]‖` does not
/// exceed the rank threshold `τ·|R_00|` are numerically zero and omitted; an
/// empty combination means the column is (numerically) zero. Regrouping: since
/// `W χ = W_B (χ_B + Σ_d coef_d χ_d)`, the estimate of the base parameter of base
/// column `k` is an estimate of `χ_k + Σ_d coef_{d,k}·χ_d`, the sum running over
/// the dependencies `d` whose combination contains `k`.
#[derive(Debug, Clone, PartialEq)]
pub struct Dependency {
    /// Index of the dependent (non-base) column of `W`.
    pub column: usize,
    /// `(base column index, coefficient)` pairs, sorted by base column index.
    pub combination: Vec<(usize, f64)>,
}

/// Result of [`lstsq`]: estimate, covariance and quality indicators, eqs. (12)-(15).
#[derive(Debug, Clone, PartialEq)]
pub struct LstsqSolution {
    /// `χ̂`, length `n` (eq. (12)). Dependent (non-base) columns get `0.0` and are
    /// listed in [`dependencies`](Self::dependencies).
    pub params: Vec<f64>,
    /// `σ_i = sqrt(C_ii)` (eq. (15)), length `n`; `NaN` for non-base columns.
    pub std: Vec<f64>,
    /// `%σ_i = 100·σ_i/|χ̂_i|` (eq. (15)), length `n`; `NaN` for non-base
    /// columns; `f64::INFINITY` for a base column whose estimate is exactly `0.0`.
    pub rel_std_pct: Vec<f64>,
    /// `C = σ̂ρ² (W_BᵀW_B)⁻¹` (eq. (14)) as an `n × n` row-major matrix; the rows
    /// and columns of non-base columns are `0.0`. (Only when `σ_i²` itself exceeds
    /// `f64::MAX` — absurd units — do entries become infinite; `std` stays finite.)
    pub covariance: Vec<f64>,
    /// Sorted indices of the `b` base (independent) columns.
    pub base_columns: Vec<usize>,
    /// One entry per non-base column, sorted by column index.
    pub dependencies: Vec<Dependency>,
    /// Numerical rank `b` of `W` (number of base parameters).
    pub rank: usize,
    /// Number of rows `r` of `W`.
    pub rows: usize,
    /// `‖Y − W χ̂‖`.
    pub residual_norm: f64,
    /// `σ̂ρ` according to [`LstsqOptions::sigma`] (eq. (13) by default).
    pub sigma_rho: f64,
    /// `‖Y − W χ̂‖ / ‖Y‖`. `NaN` when `‖Y‖ = 0` (then `χ̂ = 0` and the relative
    /// error is undefined: there is nothing to explain).
    pub relative_error: f64,
    /// 2-norm condition number of the base-column regressor `W_B`:
    /// `σ_max(R_B)/σ_min(R_B)` from faer's SVD of the `b × b` factor. Equals
    /// `cond(W)` when `W` has full rank. `NaN` if the SVD fails to converge.
    pub condition_number: f64,
    /// `e = Y − W χ̂`, length `r`.
    pub residual: Vec<f64>,
}

/// Least-squares estimate with covariance of `Y = W χ + ρ` (paper eqs. (11)-(15)).
///
/// `w` is column-major (`rows` = `r` rows, `cols` = `n` columns, entry `(i, j)` at
/// `w[j*rows + i]`), as the decimation produces it; `y` has `rows` entries.
///
/// Uses faer's column-pivoted Householder QR; the rank `b`, the base columns and
/// the dependent columns are determined as described in the module documentation.
/// Returns the solution on the base columns with `σ̂ρ` (eq. (13), or the
/// [`SigmaConvention::SampleStd`] variant), `C = σ̂ρ² (W_BᵀW_B)⁻¹` (eq. (14)) from
/// `R_B⁻¹` (never forming `WᵀW`), `σ_i` and `%σ_i` (eq. (15)), the relative error
/// and the condition number. Rank deficiency is *not* an error: the dependent
/// columns are returned with their combinations of base columns (the Python layer
/// turns them into an identifiability error naming the parameters).
///
/// # Errors
/// [`Error::InvalidInput`] when `cols == 0`; `w.len() != rows·cols`;
/// `y.len() != rows`; `rows < cols + 1` (eq. (13) needs `r > b`); an entry of `W`
/// or `Y` is NaN or infinite (the message gives its row/column); `W` is
/// identically zero; `rank_tol` is not finite or outside `[0, 1)`; or the
/// estimate or residual is not representable in `f64` (e.g. `|W| ~ 1e-300` with
/// `|Y| ~ 1e300`: rescale `W` and `Y`). Inputs are internally rescaled by powers
/// of two, so merely huge or subnormal (but consistent) entries are fine.
/// [`Error::Identifiability`] only in the unreachable-in-practice case of an
/// exactly singular base factor. Never panics.
pub fn lstsq(w: &[f64], rows: usize, cols: usize, y: &[f64], opts: &LstsqOptions) -> Result<LstsqSolution> {
    validate(w, rows, cols, y)?;
    let tau = rank_tolerance(opts.rank_tol, rows, cols)?;
    let n = cols;
    // W and Y are scaled by exact powers of two (max |W| and max |Y| in [0.5, 1))
    // so that neither subnormal nor huge entries under/overflow inside the
    // factorisation; everything is mapped back to the caller's units below.
    let kw = pow2_exponent(w);
    let ky = pow2_exponent(y);
    let f = Factored::new(w, y, rows, cols, kw, ky)?;
    let thr = tau * f.r_fac[0].abs();
    let rank = f.rank(thr)?;
    let base = Base::choose(&f, rank, thr);
    let sol = base.solve(&f)?;

    let mut params = vec![0.0; n];
    for (k, &j) in base.qr.order.iter().enumerate() {
        params[j] = ldexp(sol.rhs[(k, 0)], kw - ky);
    }
    if params.iter().any(|v| !v.is_finite()) {
        return Err(overflow_error());
    }
    let fit = Fit::new(w, y, rows, &params, base.qr.order.len(), opts.sigma)?;
    let (covariance, std, rel_std_pct) = uncertainty(&base, &sol, &params, fit.sigma_rho, kw, ky);
    let dependencies = base.dependencies(&sol, thr);
    let mut base_columns = base.qr.order.clone();
    base_columns.sort_unstable();

    Ok(LstsqSolution {
        params,
        std,
        rel_std_pct,
        covariance,
        base_columns,
        dependencies,
        rank: base.qr.order.len(),
        rows,
        residual_norm: fit.residual_norm,
        sigma_rho: fit.sigma_rho,
        relative_error: fit.relative_error,
        condition_number: condition_number(sol.r_b.as_ref()),
        residual: fit.residual,
    })
}

/// A system with at least this many rows per column is first compressed to its `n × n`
/// triangular factor by an unpivoted blocked QR ([`compress`]): the column-pivoted QR
/// chooses each pivot from the norms of every remaining column and updates them at every
/// step, a matrix-vector product per column of a tall `W`, where the unpivoted QR works in
/// blocks of matrix products.
const COMPRESS_ROWS: usize = 4;

/// `(R₀, (Q₀ᵀ b)[..n])` of the unpivoted Householder QR `a = Q₀ R₀` (`rows × n`): the least
/// squares of `R₀ χ ≈ (Q₀ᵀ b)[..n]` are those of `a χ ≈ b`, since `‖aχ − b‖²` is
/// `‖R₀χ − (Q₀ᵀb)[..n]‖²` plus `‖(Q₀ᵀb)[n..]‖²`; and `R₀` has the singular values and the
/// column geometry of `a` (`aᵀa = R₀ᵀR₀`), so the pivoted QR of `R₀` makes the same rank and
/// base-column decisions.
fn compress(mut a: Mat<f64>, b: Mat<f64>) -> (Mat<f64>, Mat<f64>) {
    use faer::linalg::qr::no_pivoting::factor as plain;
    let (rows, n) = (a.nrows(), a.ncols());
    let block_size = recommended_block_size::<f64>(rows, n).max(1);
    let mut q_coeff = Mat::<f64>::zeros(block_size, n);
    {
        let mut mem = MemBuffer::new(plain::qr_in_place_scratch::<f64>(
            rows,
            n,
            block_size,
            PAR,
            Default::default(),
        ));
        plain::qr_in_place(
            a.as_mut(),
            q_coeff.as_mut(),
            PAR,
            MemStack::new(&mut mem),
            Default::default(),
        );
    }
    let r0 = Mat::<f64>::from_fn(n, n, |i, j| if i <= j { a[(i, j)] } else { 0.0 });
    let qtb = householder_qt(a, &q_coeff, b);
    let b0 = Mat::<f64>::from_fn(n, 1, |i, _| qtb[(i, 0)]);
    (r0, b0)
}

/// `Qᵀ b` for the Householder QR held in `factored` (faer's in-place factorisation, its `R`
/// already read out) and its block coefficients `q_coeff`: the basis is the unit lower
/// trapezoidal part of the factored matrix.
fn householder_qt(mut factored: Mat<f64>, q_coeff: &Mat<f64>, mut b: Mat<f64>) -> Mat<f64> {
    let (rows, n) = (factored.nrows(), factored.ncols());
    for j in 0..n {
        for i in 0..j {
            factored[(i, j)] = 0.0;
        }
        factored[(j, j)] = 1.0;
    }
    let mut mem = MemBuffer::new(
        apply_block_householder_sequence_transpose_on_the_left_in_place_scratch::<f64>(
            rows,
            q_coeff.nrows(),
            b.ncols(),
        ),
    );
    apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj(
        factored.as_ref(),
        q_coeff.as_ref(),
        Conj::No,
        b.as_mut(),
        PAR,
        MemStack::new(&mut mem),
    );
    b
}

/// Phase 1: the column-pivoted Householder QR of the scaled `W` (faer), `W P = Q R`,
/// and `Qᵀ Y` (a tall `W` compressed first: [`COMPRESS_ROWS`]).
struct Factored {
    /// `R` (n × n, upper triangular, pivoted column order), column-major.
    r_fac: Vec<f64>,
    /// `perm[k]`: original index of the k-th pivot column; `perm_inv` its inverse.
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    /// The first `n` entries of `Qᵀ Y`: the coordinates of `Y` in range(Q_thin).
    qty: Vec<f64>,
    n: usize,
}

impl Factored {
    fn new(w: &[f64], y: &[f64], rows: usize, cols: usize, kw: i32, ky: i32) -> Result<Self> {
        let a = Mat::<f64>::from_fn(rows, cols, |i, j| ldexp(w[j * rows + i], kw));
        let b = Mat::<f64>::from_fn(rows, 1, |i, _| ldexp(y[i], ky));
        let (a, b) = if rows >= COMPRESS_ROWS * cols {
            compress(a, b)
        } else {
            (a, b)
        };
        Self::pivoted(a, b)
    }

    /// The column-pivoted QR of `qr` (`rows × n`, scaled) and `Qᵀ y` of the scaled `y`.
    fn pivoted(mut qr: Mat<f64>, y: Mat<f64>) -> Result<Self> {
        let (rows, cols) = (qr.nrows(), qr.ncols());
        let n = cols;
        let par = PAR;
        let block_size = recommended_block_size::<f64>(rows, cols).max(1);
        let mut q_coeff = Mat::<f64>::zeros(block_size, n);
        let mut perm = vec![0usize; n];
        let mut perm_inv = vec![0usize; n];
        {
            let mut mem = MemBuffer::new(qr_in_place_scratch::<usize, f64>(
                rows,
                cols,
                block_size,
                par,
                Default::default(),
            ));
            qr_in_place(
                qr.as_mut(),
                q_coeff.as_mut(),
                &mut perm,
                &mut perm_inv,
                par,
                MemStack::new(&mut mem),
                Default::default(),
            );
        }
        let mut r_fac = vec![0.0; n * n];
        for j in 0..n {
            for i in 0..=j {
                r_fac[j * n + i] = qr[(i, j)];
            }
        }
        if r_fac.iter().any(|v| !v.is_finite()) {
            return Err(overflow_error());
        }
        let qty = householder_qt(qr, &q_coeff, y);
        Ok(Self {
            r_fac,
            perm,
            perm_inv,
            qty: (0..n).map(|i| qty[(i, 0)]).collect(),
            n,
        })
    }

    /// Phase 2: the numerical rank, the pivots of `R` above `thr = τ |R_00|`.
    fn rank(&self, thr: f64) -> Result<usize> {
        let n = self.n;
        let mut rank = 0;
        while rank < n && self.r_fac[rank * n + rank].abs() > thr {
            rank += 1;
        }
        if rank == 0 {
            // Unreachable for a nonzero W (|R_00| > 0 and τ < 1); kept so that no
            // division by zero can happen silently.
            return Err(Error::Identifiability(
                "lstsq: W has numerical rank 0; no parameter is identifiable".to_string(),
            ));
        }
        Ok(rank)
    }
}

/// Phase 3: the base columns, chosen on `M = R Pᵀ` (same column geometry as `W`:
/// column j of `W` is `Q_thin · m_cols[j]`), and the small QR of them.
struct Base {
    m_cols: Vec<Vec<f64>>,
    qr: SmallQr,
    dependents: Vec<usize>,
}

impl Base {
    fn choose(f: &Factored, rank: usize, thr: f64) -> Self {
        let n = f.n;
        let m_cols: Vec<Vec<f64>> = (0..n)
            .map(|j| {
                let p = f.perm_inv[j];
                (0..n)
                    .map(|i| if i <= p { f.r_fac[p * n + i] } else { 0.0 })
                    .collect()
            })
            .collect();
        let all: Vec<usize> = (0..n).collect();
        let qr = if rank == n {
            SmallQr::factor(&m_cols, &all, None)
        } else {
            let natural = SmallQr::factor(&m_cols, &all, Some(thr));
            if natural.order.len() == rank {
                natural
            } else {
                SmallQr::factor(&m_cols, &f.perm[..rank], None)
            }
        };
        let mut is_base = vec![false; n];
        for &j in &qr.order {
            is_base[j] = true;
        }
        let dependents = (0..n).filter(|&j| !is_base[j]).collect();
        Self {
            m_cols,
            qr,
            dependents,
        }
    }

    /// Phase 4: `R_B` (b × b) and one triangular solve for
    /// `[χ_B | dependency coefficients | R_B⁻¹]` (scaled units).
    fn solve(&self, f: &Factored) -> Result<BaseSolution> {
        let b = self.qr.order.len();
        let r_b = Mat::<f64>::from_fn(b, b, |i, j| if i <= j { self.qr.r[j][i] } else { 0.0 });
        if (0..b).any(|k| r_b[(k, k)] == 0.0) {
            return Err(Error::Identifiability(
                "lstsq: the triangular factor of the base columns is singular; \
                 increase rank_tol"
                    .to_string(),
            ));
        }
        let nd = self.dependents.len();
        let mut rhs = Mat::<f64>::zeros(b, 1 + nd + b);
        let mut c = f.qty.clone();
        self.qr.apply(&mut c);
        for k in 0..b {
            rhs[(k, 0)] = c[k];
            rhs[(k, 1 + nd + k)] = 1.0;
        }
        for (t, &j) in self.dependents.iter().enumerate() {
            let mut v = self.m_cols[j].clone();
            self.qr.apply(&mut v);
            for k in 0..b {
                rhs[(k, 1 + t)] = v[k];
            }
        }
        solve_upper_triangular_in_place(r_b.as_ref(), rhs.as_mut(), Par::Seq);
        Ok(BaseSolution { r_b, rhs, nd })
    }

    /// Phase 7: each dependent column as a combination of base columns (terms
    /// below `thr` in the column's geometry left out).
    fn dependencies(&self, sol: &BaseSolution, thr: f64) -> Vec<Dependency> {
        let col_norms: Vec<f64> = self.m_cols.iter().map(|c| norm2(c)).collect();
        self.dependents
            .iter()
            .enumerate()
            .map(|(t, &j)| {
                let mut combination: Vec<(usize, f64)> = self
                    .qr
                    .order
                    .iter()
                    .enumerate()
                    .map(|(k, &bk)| (bk, sol.rhs[(k, 1 + t)]))
                    .filter(|&(bk, coef)| coef.abs() * col_norms[bk] > thr)
                    .collect();
                combination.sort_by_key(|&(bk, _)| bk);
                Dependency {
                    column: j,
                    combination,
                }
            })
            .collect()
    }
}

/// `R_B` and the solved columns `[χ_B | dependency coefficients | R_B⁻¹]`.
struct BaseSolution {
    r_b: Mat<f64>,
    rhs: Mat<f64>,
    /// Number of dependent columns.
    nd: usize,
}

/// Phase 5: the residual, its norm, the relative error and `σ̂ρ` (eq. (13) or the
/// sample standard deviation), in the caller's units.
struct Fit {
    residual: Vec<f64>,
    residual_norm: f64,
    relative_error: f64,
    sigma_rho: f64,
}

impl Fit {
    fn new(
        w: &[f64],
        y: &[f64],
        rows: usize,
        params: &[f64],
        b: usize,
        sigma: SigmaConvention,
    ) -> Result<Self> {
        let mut residual = y.to_vec();
        for (j, &p) in params.iter().enumerate() {
            if p != 0.0 {
                let col = &w[j * rows..(j + 1) * rows];
                for (e, &wij) in residual.iter_mut().zip(col) {
                    *e -= p * wij;
                }
            }
        }
        let residual_norm = norm2(&residual);
        let y_norm = norm2(y);
        let relative_error = if y_norm > 0.0 {
            residual_norm / y_norm
        } else {
            f64::NAN
        };
        let sigma_rho = match sigma {
            SigmaConvention::Paper => residual_norm / ((rows - b) as f64).sqrt(),
            SigmaConvention::SampleStd => {
                let mean = residual.iter().sum::<f64>() / rows as f64;
                let centered: Vec<f64> = residual.iter().map(|e| e - mean).collect();
                norm2(&centered) / ((rows - 1) as f64).sqrt()
            }
        };
        if !residual_norm.is_finite() || !sigma_rho.is_finite() {
            return Err(overflow_error());
        }
        Ok(Self {
            residual,
            residual_norm,
            relative_error,
            sigma_rho,
        })
    }
}

/// Phase 6: `C = σ̂ρ² R_B⁻¹ R_B⁻ᵀ` (eq. (14)), `σ_i` and `%σ_i` (eq. (15)). In the
/// caller's units, with `W' = 2^kw W` and `σ' = 2^ky σ̂ρ`:
/// `σ̂ρ R_B⁻¹ = 2^(kw−ky) σ' R_B'⁻¹` (the product formed in the scaled units).
fn uncertainty(
    base: &Base,
    sol: &BaseSolution,
    params: &[f64],
    sigma_rho: f64,
    kw: i32,
    ky: i32,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let n = params.len();
    let b = base.qr.order.len();
    let sigma_scaled = ldexp(sigma_rho, ky);
    let s_rinv = |k: usize, m: usize| ldexp(sigma_scaled * sol.rhs[(k, 1 + sol.nd + m)], kw - ky);
    let mut covariance = vec![0.0; n * n];
    for (k, &jk) in base.qr.order.iter().enumerate() {
        for (l, &jl) in base.qr.order.iter().enumerate().skip(k) {
            // R_B⁻¹ is upper triangular: row k is nonzero from column k on.
            let v: f64 = (l..b).map(|m| s_rinv(k, m) * s_rinv(l, m)).sum();
            covariance[jk * n + jl] = v;
            covariance[jl * n + jk] = v;
        }
    }
    let mut std = vec![f64::NAN; n];
    let mut rel_std_pct = vec![f64::NAN; n];
    for (k, &j) in base.qr.order.iter().enumerate() {
        // σ_i = ‖row i of σ̂ρ R_B⁻¹‖ (= sqrt(C_ii), without squaring).
        let row: Vec<f64> = (k..b).map(|m| s_rinv(k, m)).collect();
        let s = norm2(&row);
        std[j] = s;
        rel_std_pct[j] = if params[j] == 0.0 {
            f64::INFINITY
        } else {
            100.0 * s / params[j].abs()
        };
    }
    (covariance, std, rel_std_pct)
}

/// Checks shapes and values; see the `# Errors` section of [`lstsq`].
fn validate(w: &[f64], rows: usize, cols: usize, y: &[f64]) -> Result<()> {
    if cols == 0 {
        return Err(invalid!(
            "lstsq: W has no columns (cols = 0); the regressor needs at least one parameter \
             column"
        ));
    }
    match rows.checked_mul(cols) {
        Some(len) if len == w.len() => {}
        _ => {
            return Err(invalid!(
                "lstsq: W has {} entries but rows x cols = {} x {}; pass W column-major with \
                 exactly rows*cols entries",
                w.len(),
                rows,
                cols
            ))
        }
    }
    if y.len() != rows {
        return Err(invalid!(
            "lstsq: Y has {} entries but W has {} rows; Y needs one entry per row of W",
            y.len(),
            rows
        ));
    }
    if rows <= cols {
        return Err(invalid!(
            "lstsq: W has {} rows for {} columns; at least cols + 1 = {} rows are needed \
             (sigma_rho^2 = |Y - W chi|^2 / (r - b), eq. (13), needs r > b); use more samples \
             (less decimation) or fewer parameters",
            rows,
            cols,
            cols + 1
        ));
    }
    for (idx, &v) in w.iter().enumerate() {
        if !v.is_finite() {
            let (i, j) = (idx % rows, idx / rows);
            return Err(invalid!(
                "lstsq: W[{i}, {j}] (row {i}, column {j}) is {v}; W must be finite: remove or \
                 repair the corrupted samples"
            ));
        }
    }
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(invalid!(
            "lstsq: Y[{i}] (row {i}) is {}; Y must be finite: remove or repair the corrupted \
             samples",
            y[i]
        ));
    }
    if w.iter().all(|&v| v == 0.0) {
        return Err(invalid!(
            "lstsq: W is identically zero, so no parameter is identifiable; check the regressor \
             construction and the excitation of the trajectory"
        ));
    }
    Ok(())
}

/// The relative rank tolerance `τ` (see [`LstsqOptions::rank_tol`]).
fn rank_tolerance(rank_tol: Option<f64>, rows: usize, cols: usize) -> Result<f64> {
    match rank_tol {
        None => Ok(rows.max(cols) as f64 * f64::EPSILON),
        Some(t) if t.is_finite() && (0.0..1.0).contains(&t) => Ok(t),
        Some(t) => Err(invalid!(
            "lstsq: rank_tol = {t} is invalid; it must be finite and in [0, 1) (relative to \
             |R_00|); use None for the default max(r, n) * f64::EPSILON"
        )),
    }
}

fn overflow_error() -> Error {
    invalid!(
        "lstsq: the least-squares estimate or its residual overflowed f64 (W and Y have \
         wildly different magnitudes); rescale W and Y (e.g. change units) and retry"
    )
}

/// `k` such that `max |x| · 2^k` lies in `[0.5, 1)` (0 for an all-zero `x`).
fn pow2_exponent(x: &[f64]) -> i32 {
    let m = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if m == 0.0 || !m.is_finite() {
        return 0;
    }
    let mut k = -(m.log2().floor() as i32) - 1;
    // log2 may round across a power of two: correct to the exact interval.
    while ldexp(m, k) >= 1.0 {
        k -= 1;
    }
    while ldexp(m, k) < 0.5 {
        k += 1;
    }
    k
}

/// `x · 2^k`, exact unless the result under/overflows.
fn ldexp(x: f64, k: i32) -> f64 {
    let pow2 = |e: i32| f64::from_bits(((e + 1023) as u64) << 52);
    let (mut x, mut k) = (x, k);
    while k > 1000 {
        x *= pow2(1000);
        k -= 1000;
    }
    while k < -1000 {
        x *= pow2(-1000);
        k += 1000;
    }
    x * pow2(k)
}

/// 2-norm without intermediate overflow/underflow.
fn norm2(x: &[f64]) -> f64 {
    let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return scale;
    }
    scale * x.iter().map(|v| (v / scale) * (v / scale)).sum::<f64>().sqrt()
}

/// `σ_max/σ_min` of the small triangular factor (faer SVD); NaN on failure.
fn condition_number(r: MatRef<'_, f64>) -> f64 {
    let k = r.nrows();
    let mut s = Diag::<f64>::zeros(k);
    let mut mem = MemBuffer::new(svd_scratch::<f64>(
        k,
        k,
        ComputeSvdVectors::No,
        ComputeSvdVectors::No,
        Par::Seq,
        Default::default(),
    ));
    let ok = svd(
        r,
        s.as_mut(),
        None,
        None,
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    );
    if ok.is_err() {
        return f64::NAN;
    }
    let sv = s.column_vector();
    let (mut smax, mut smin) = (0.0f64, f64::INFINITY);
    for i in 0..k {
        smax = smax.max(sv[i]);
        smin = smin.min(sv[i]);
    }
    if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    }
}

/// Householder QR of a subset of the small `n`-vectors `m_cols`, processed in
/// the order of `candidates`, skipping those whose residual is not above `thr`.
struct SmallQr {
    /// Accepted columns, in processing order.
    order: Vec<usize>,
    /// Column `k` of the triangular factor (length `k + 1`).
    r: Vec<Vec<f64>>,
    /// Unit Householder vectors (`H_k = I − 2 v vᵀ`, zeros above entry `k`).
    reflectors: Vec<Vec<f64>>,
}

impl SmallQr {
    /// Accepts the candidates in order: with `thr = Some(t)` only those at
    /// distance `> t` from the span of the accepted ones; with `None`, all.
    fn factor(m_cols: &[Vec<f64>], candidates: &[usize], thr: Option<f64>) -> Self {
        let n = m_cols.first().map_or(0, Vec::len);
        let mut qr = SmallQr {
            order: Vec::new(),
            r: Vec::new(),
            reflectors: Vec::new(),
        };
        for &j in candidates {
            let k = qr.order.len();
            if k == n {
                break;
            }
            let mut x = m_cols[j].clone();
            qr.apply(&mut x);
            let nrm = norm2(&x[k..]);
            if let Some(t) = thr {
                if nrm.is_nan() || nrm <= t {
                    continue;
                }
            }
            let beta = if x[k] >= 0.0 { -nrm } else { nrm };
            let mut v = vec![0.0; n];
            v[k] = x[k] - beta;
            v[k + 1..].copy_from_slice(&x[k + 1..]);
            let vn = norm2(&v[k..]);
            if vn > 0.0 {
                v[k..].iter_mut().for_each(|e| *e /= vn);
            }
            let mut rk = x[..k].to_vec();
            rk.push(beta);
            qr.order.push(j);
            qr.r.push(rk);
            qr.reflectors.push(v);
        }
        qr
    }

    /// `x ← Q₂ᵀ x` with the accepted reflectors.
    fn apply(&self, x: &mut [f64]) {
        for (k, v) in self.reflectors.iter().enumerate() {
            let d: f64 = v[k..].iter().zip(&x[k..]).map(|(a, b)| a * b).sum();
            let f = 2.0 * d;
            for (e, &vi) in x[k..].iter_mut().zip(&v[k..]) {
                *e -= f * vi;
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index loops mirror the maths in the checks
mod tests {
    use super::*;

    /// splitmix64; `u()` is uniform in [-1, 1) and bit-identical to the Python
    /// generator used for the reference values below.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn u(&mut self) -> f64 {
            (self.next() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0) * 2.0 - 1.0
        }
    }

    /// Column-major r × n matrix of uniforms, filled column by column.
    fn random_w(rng: &mut Rng, r: usize, n: usize) -> Vec<f64> {
        (0..r * n).map(|_| rng.u()).collect()
    }

    fn matvec(w: &[f64], r: usize, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; r];
        for (j, &xj) in x.iter().enumerate() {
            for i in 0..r {
                y[i] += w[j * r + i] * xj;
            }
        }
        y
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    fn assert_rel(a: f64, b: f64, tol: f64, what: &str) {
        assert!(
            rel(a, b) <= tol,
            "{what}: got {a:e}, expected {b:e}, rel {:e}",
            rel(a, b)
        );
    }

    /// Explicit inverse by Gauss-Jordan with partial pivoting (k × k, row-major).
    fn inverse(a: &[f64], k: usize) -> Vec<f64> {
        let mut m = a.to_vec();
        let mut inv: Vec<f64> = (0..k * k)
            .map(|i| if i % (k + 1) == 0 { 1.0 } else { 0.0 })
            .collect();
        for c in 0..k {
            let p = (c..k)
                .max_by(|&i, &j| m[i * k + c].abs().total_cmp(&m[j * k + c].abs()))
                .unwrap();
            for t in 0..k {
                m.swap(c * k + t, p * k + t);
                inv.swap(c * k + t, p * k + t);
            }
            let d = m[c * k + c];
            for t in 0..k {
                m[c * k + t] /= d;
                inv[c * k + t] /= d;
            }
            for i in 0..k {
                if i != c {
                    let f = m[i * k + c];
                    for t in 0..k {
                        m[i * k + t] -= f * m[c * k + t];
                        inv[i * k + t] -= f * inv[c * k + t];
                    }
                }
            }
        }
        inv
    }

    /// Textbook normal equations on the columns `cols` of W:
    /// returns ((WᵀW)⁻¹ row-major, χ = (WᵀW)⁻¹ WᵀY).
    fn normal_equations(w: &[f64], r: usize, cols: &[usize], y: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let k = cols.len();
        let col = |j: usize| &w[j * r..(j + 1) * r];
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut g = vec![0.0; k * k];
        for a in 0..k {
            for b in 0..k {
                g[a * k + b] = dot(col(cols[a]), col(cols[b]));
            }
        }
        let gi = inverse(&g, k);
        let wty: Vec<f64> = cols.iter().map(|&j| dot(col(j), y)).collect();
        let chi = (0..k)
            .map(|a| (0..k).map(|b| gi[a * k + b] * wty[b]).sum())
            .collect();
        (gi, chi)
    }

    /// The 500 × 4 noisy problem of the numpy reference (seed 42).
    fn noisy_problem() -> (Vec<f64>, Vec<f64>) {
        let (r, n) = (500, 4);
        let mut rng = Rng(42);
        let mut w = random_w(&mut rng, r, n);
        for i in 0..r {
            w[3 * r + i] = 3.0 * w[3 * r + i] + 1.0;
        }
        let chi = [1.5, -2.0, 0.75, 3.0];
        let mut y = matvec(&w, r, &chi);
        for yi in y.iter_mut() {
            *yi += 0.1 * rng.u();
        }
        (w, y)
    }

    // Reference values for `noisy_problem`, produced offline with numpy 2.4 from the
    // same data, generated in Python with the same splitmix64:
    //   M = 2**64 - 1; s = 42
    //   def u():
    //       global s; s = (s + 0x9E3779B97F4A7C15) & M; z = s
    //       z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M
    //       z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M
    //       return ((z ^ (z >> 31)) >> 11) * 2.0**-53 * 2.0 - 1.0
    //   W = np.array([[u() for i in range(500)] for j in range(4)]).T; W[:, 3] = 3*W[:, 3] + 1
    //   Y = W @ [1.5, -2.0, 0.75, 3.0] + np.array([0.1 * u() for i in range(500)])
    //   x = np.linalg.lstsq(W, Y, rcond=None)[0]; e = Y - W @ x
    //   sp = np.sqrt(e @ e / (500 - 4)); ss = np.std(e, ddof=1)
    //   Ci = np.linalg.inv(W.T @ W); sp * np.sqrt(np.diag(Ci)); ss * np.sqrt(np.diag(Ci))
    //   np.linalg.norm(e) / np.linalg.norm(Y); np.linalg.cond(W); np.linalg.norm(e)
    const REF_CHI: [f64; 4] = [
        1.4994493574654095,
        -2.005310889323256,
        0.742476285766335,
        3.001931307145095,
    ];
    const REF_SIGMA_PAPER: f64 = 0.055482697609957415;
    const REF_SIGMA_STD: f64 = 0.05528729584346151;
    const REF_STD_PAPER: [f64; 4] = [
        0.004287700702790367,
        0.004167977100215431,
        0.00446947042863107,
        0.0012068335385014793,
    ];
    const REF_STD_SAMPLE: [f64; 4] = [
        0.004272600061912721,
        0.004153298107967758,
        0.004453729621953007,
        0.0012025832511966426,
    ];
    const REF_REL_ERR: f64 = 0.008633832558656792;
    const REF_COND: f64 = 3.786187884338226;
    const REF_RES_NORM: f64 = 1.2356583460255812;
    // Ill-conditioned 200 × 3 problem (same generator with s = 7, W built as above
    // with 3 columns, then W[:, 2] = W[:, 0] + 1e-8 * W[:, 2]): np.linalg.cond(W)
    const REF_ILL_COND: f64 = 203667498.58918974;

    #[test]
    fn exact_solution_is_recovered() {
        let (r, n) = (60, 5);
        let mut rng = Rng(1);
        let w = random_w(&mut rng, r, n);
        let chi = [0.5, -1.25, 2.0, 10.0, -0.001];
        let y = matvec(&w, r, &chi);
        let s = lstsq(&w, r, n, &y, &LstsqOptions::default()).unwrap();
        assert_eq!(s.rank, n);
        assert_eq!(s.base_columns, vec![0, 1, 2, 3, 4]);
        assert!(s.dependencies.is_empty());
        for j in 0..n {
            assert_rel(s.params[j], chi[j], 1e-12, "chi");
        }
        assert!(s.residual_norm < 1e-13, "residual {}", s.residual_norm);
        assert!(s.relative_error < 1e-14);
        assert_eq!(s.residual.len(), r);
        assert_eq!(s.rows, r);
    }

    #[test]
    fn matches_numpy_reference_paper_sigma() {
        let (w, y) = noisy_problem();
        let s = lstsq(&w, 500, 4, &y, &LstsqOptions::default()).unwrap();
        assert_eq!(s.rank, 4);
        for j in 0..4 {
            assert_rel(s.params[j], REF_CHI[j], 1e-10, "chi");
            assert_rel(s.std[j], REF_STD_PAPER[j], 1e-10, "std");
            assert_rel(
                s.rel_std_pct[j],
                100.0 * REF_STD_PAPER[j] / REF_CHI[j].abs(),
                1e-10,
                "%std",
            );
        }
        assert_rel(s.sigma_rho, REF_SIGMA_PAPER, 1e-10, "sigma");
        assert_rel(s.relative_error, REF_REL_ERR, 1e-10, "relative error");
        assert_rel(s.residual_norm, REF_RES_NORM, 1e-10, "residual norm");
        assert_rel(s.condition_number, REF_COND, 1e-10, "cond");
        // The residual vector is Y - W χ̂.
        let fit = matvec(&w, 500, &s.params);
        for i in 0..500 {
            assert!((s.residual[i] - (y[i] - fit[i])).abs() < 1e-14);
        }
    }

    #[test]
    fn matches_numpy_reference_sample_std() {
        let (w, y) = noisy_problem();
        let opts = LstsqOptions {
            sigma: SigmaConvention::SampleStd,
            ..Default::default()
        };
        let s = lstsq(&w, 500, 4, &y, &opts).unwrap();
        assert_rel(s.sigma_rho, REF_SIGMA_STD, 1e-10, "sigma");
        for j in 0..4 {
            assert_rel(s.params[j], REF_CHI[j], 1e-10, "chi");
            assert_rel(s.std[j], REF_STD_SAMPLE[j], 1e-10, "std");
        }
    }

    #[test]
    fn covariance_matches_textbook_inverse() {
        let (w, y) = noisy_problem();
        for sigma in [SigmaConvention::Paper, SigmaConvention::SampleStd] {
            let s = lstsq(
                &w,
                500,
                4,
                &y,
                &LstsqOptions {
                    sigma,
                    ..Default::default()
                },
            )
            .unwrap();
            let (gi, chi) = normal_equations(&w, 500, &[0, 1, 2, 3], &y);
            let s2 = s.sigma_rho * s.sigma_rho;
            for a in 0..4 {
                assert_rel(s.params[a], chi[a], 1e-10, "chi vs normal equations");
                for b in 0..4 {
                    let c = s.covariance[a * 4 + b];
                    assert_eq!(c, s.covariance[b * 4 + a], "symmetry");
                    let expect = s2 * gi[a * 4 + b];
                    assert!(
                        (c - expect).abs() <= 1e-10 * s2 * (gi[a * 4 + a] * gi[b * 4 + b]).sqrt(),
                        "C[{a},{b}] = {c:e}, expected {expect:e}"
                    );
                }
            }
        }
    }

    /// 200 × 4 with W[:,3] = 2 W[:,0] − W[:,2]; column 3 has the largest norm, so a
    /// plain pivoted QR would pick it first: the index-order rule keeps 0, 1, 2.
    fn deficient_problem() -> (Vec<f64>, Vec<f64>) {
        let r = 200;
        let mut rng = Rng(3);
        let mut w = random_w(&mut rng, r, 4);
        for i in 0..r {
            w[3 * r + i] = 2.0 * w[i] - w[2 * r + i];
        }
        let y: Vec<f64> = matvec(&w, r, &[1.0, 2.0, -3.0, 0.5])
            .iter()
            .map(|v| v + 0.01 * rng.u())
            .collect();
        (w, y)
    }

    #[test]
    fn rank_deficient_reports_dependency_and_base_solution() {
        let (w, y) = deficient_problem();
        let r = 200;
        let s = lstsq(&w, r, 4, &y, &LstsqOptions::default()).unwrap();
        assert_eq!(s.rank, 3);
        assert_eq!(s.base_columns, vec![0, 1, 2]);
        assert_eq!(s.dependencies.len(), 1);
        let d = &s.dependencies[0];
        assert_eq!(d.column, 3);
        assert_eq!(d.combination.len(), 2, "{:?}", d.combination);
        assert_eq!(d.combination[0].0, 0);
        assert_eq!(d.combination[1].0, 2);
        assert!((d.combination[0].1 - 2.0).abs() < 1e-10);
        assert!((d.combination[1].1 + 1.0).abs() < 1e-10);
        // Dependent parameter: zero estimate, NaN σ, zero covariance row/column.
        assert_eq!(s.params[3], 0.0);
        assert!(s.std[3].is_nan() && s.rel_std_pct[3].is_nan());
        for k in 0..4 {
            assert_eq!(s.covariance[3 * 4 + k], 0.0);
            assert_eq!(s.covariance[k * 4 + 3], 0.0);
        }
        // Base parameters = LS on the 3 base columns (normal equations and lstsq).
        let (gi, chi) = normal_equations(&w, r, &[0, 1, 2], &y);
        let sub = lstsq(&w[..3 * r], r, 3, &y, &LstsqOptions::default()).unwrap();
        for a in 0..3 {
            assert_rel(s.params[a], chi[a], 1e-10, "base chi");
            assert_rel(s.params[a], sub.params[a], 1e-10, "base chi vs 3-column lstsq");
            assert_rel(s.std[a], sub.std[a], 1e-10, "base std vs 3-column lstsq");
            assert_rel(
                s.covariance[a * 4 + a],
                s.sigma_rho.powi(2) * gi[a * 3 + a],
                1e-10,
                "C_aa",
            );
        }
        // σ uses r − b with b = 3.
        assert_rel(
            s.sigma_rho,
            s.residual_norm / ((r - 3) as f64).sqrt(),
            1e-14,
            "sigma",
        );
        assert_rel(s.sigma_rho, sub.sigma_rho, 1e-10, "sigma vs 3-column lstsq");
        assert_rel(
            s.condition_number,
            sub.condition_number,
            1e-10,
            "cond of base columns",
        );
    }

    #[test]
    fn zero_column_and_earlier_dependent_column() {
        // col 1 = 0.5 * col 0 (dependent on an earlier column, though smaller),
        // col 2 identically zero.
        let r = 30;
        let mut rng = Rng(11);
        let mut w = random_w(&mut rng, r, 4);
        for i in 0..r {
            w[r + i] = 0.5 * w[i];
            w[2 * r + i] = 0.0;
        }
        let y = matvec(&w, r, &[1.0, 0.0, 0.0, -1.0]);
        let s = lstsq(&w, r, 4, &y, &LstsqOptions::default()).unwrap();
        assert_eq!(s.rank, 2);
        assert_eq!(s.base_columns, vec![0, 3]);
        assert_eq!(s.dependencies[0].column, 1);
        assert_eq!(s.dependencies[0].combination.len(), 1);
        assert_eq!(s.dependencies[0].combination[0].0, 0);
        assert!((s.dependencies[0].combination[0].1 - 0.5).abs() < 1e-12);
        assert_eq!(
            s.dependencies[1],
            Dependency {
                column: 2,
                combination: vec![]
            }
        );
        assert_rel(s.params[0], 1.0, 1e-12, "chi0");
        assert_rel(s.params[3], -1.0, 1e-12, "chi3");
    }

    #[test]
    fn ill_conditioned_full_rank_is_solved() {
        let r = 200;
        let mut rng = Rng(7);
        let mut w = random_w(&mut rng, r, 3);
        for i in 0..r {
            w[2 * r + i] = w[i] + 1e-8 * w[2 * r + i];
        }
        let chi = [1.0, -2.0, 3.0];
        let y = matvec(&w, r, &chi);
        let s = lstsq(&w, r, 3, &y, &LstsqOptions::default()).unwrap();
        assert_eq!(s.rank, 3);
        assert_rel(s.condition_number, REF_ILL_COND, 1e-6, "cond vs numpy");
        for j in 0..3 {
            assert_rel(s.params[j], chi[j], 1e-6, "chi");
        }
        assert!(s.relative_error < 1e-14);
        // A coarser rank tolerance declares it rank deficient instead.
        let opts = LstsqOptions {
            rank_tol: Some(1e-6),
            ..Default::default()
        };
        let s = lstsq(&w, r, 3, &y, &opts).unwrap();
        assert_eq!(s.rank, 2);
        assert_eq!(s.base_columns, vec![0, 1]);
        assert_eq!(s.dependencies[0].column, 2);
    }

    #[test]
    fn borderline_tolerance_falls_back_to_pivot_columns() {
        // c0 = e1, c1 = e1 + δ e3, c2 = e1 − δ e3: pivoted QR sees rank 2 (second
        // pivot ≈ 2δ) but the index-order scan finds c1 at distance δ < τ from c0.
        let (r, delta) = (5, 1e-6);
        let mut w = vec![0.0; r * 3];
        w[0] = 1.0;
        w[r] = 1.0;
        w[r + 2] = delta;
        w[2 * r] = 1.0;
        w[2 * r + 2] = -delta;
        let y = vec![1.0, 0.5, 0.2, -0.1, 0.3];
        let opts = LstsqOptions {
            rank_tol: Some(1.5 * delta),
            ..Default::default()
        };
        let s = lstsq(&w, r, 3, &y, &opts).unwrap();
        assert_eq!(s.rank, 2);
        assert_eq!(s.base_columns, vec![1, 2]);
        let d = &s.dependencies[0];
        assert_eq!(d.column, 0);
        assert_eq!(d.combination.len(), 2);
        assert!((d.combination[0].1 - 0.5).abs() < 1e-10 && (d.combination[1].1 - 0.5).abs() < 1e-10);
        // LS on columns 1, 2: y0 = a + b, y2 = δ (a − b).
        assert_rel(s.params[1], 0.5 * (1.0 + 0.2 / delta), 1e-9, "chi1");
        assert_rel(s.params[2], 0.5 * (1.0 - 0.2 / delta), 1e-9, "chi2");
    }

    #[test]
    fn large_problem_uses_parallel_path() {
        let (r, n) = (20_000, 6);
        let mut rng = Rng(5);
        let w = random_w(&mut rng, r, n);
        let chi = [1.0, -1.0, 2.0, -2.0, 0.5, 4.0];
        let y: Vec<f64> = matvec(&w, r, &chi).iter().map(|v| v + 0.1 * rng.u()).collect();
        let s = lstsq(&w, r, n, &y, &LstsqOptions::default()).unwrap();
        let cols: Vec<usize> = (0..n).collect();
        let (gi, x) = normal_equations(&w, r, &cols, &y);
        for j in 0..n {
            assert_rel(s.params[j], x[j], 1e-10, "chi");
            assert_rel(s.std[j], s.sigma_rho * gi[j * n + j].sqrt(), 1e-10, "std");
        }
    }

    #[test]
    fn zero_y_gives_nan_relative_error() {
        let (r, n) = (10, 2);
        let mut rng = Rng(9);
        let w = random_w(&mut rng, r, n);
        let s = lstsq(&w, r, n, &vec![0.0; r], &LstsqOptions::default()).unwrap();
        assert_eq!(s.params, vec![0.0, 0.0]);
        assert_eq!(s.residual_norm, 0.0);
        assert!(s.relative_error.is_nan());
        assert_eq!(s.sigma_rho, 0.0);
        assert!(s.rel_std_pct.iter().all(|v| *v == f64::INFINITY));
    }

    fn expect_invalid(res: Result<LstsqSolution>, needles: &[&str]) {
        match res {
            Err(Error::InvalidInput(m)) => {
                for n in needles {
                    assert!(m.contains(n), "message {m:?} lacks {n:?}");
                }
            }
            other => panic!("expected InvalidInput, got {other:?}"),
        }
    }

    #[test]
    fn invalid_inputs_are_reported() {
        let o = LstsqOptions::default();
        let w: Vec<f64> = (0..12).map(|v| v as f64 * 0.37 + (v * v) as f64 * 0.1).collect();
        let y = vec![1.0, 2.0, 3.0, 4.0];
        assert!(lstsq(&w, 4, 3, &y, &o).is_ok());
        expect_invalid(lstsq(&[], 4, 0, &y, &o), &["no columns"]);
        expect_invalid(lstsq(&w[..11], 4, 3, &y, &o), &["W has 11 entries", "4 x 3"]);
        expect_invalid(lstsq(&w, usize::MAX, 3, &y, &o), &["W has 12 entries"]);
        expect_invalid(lstsq(&w, 4, 3, &y[..3], &o), &["Y has 3 entries", "4 rows"]);
        expect_invalid(
            lstsq(&w, 3, 4, &y[..3], &o),
            &["3 rows for 4 columns", "cols + 1 = 5"],
        );
        expect_invalid(lstsq(&w[..9], 3, 3, &y[..3], &o), &["3 rows for 3 columns"]);
        let mut bad = w.clone();
        bad[4 + 2] = f64::NAN;
        expect_invalid(lstsq(&bad, 4, 3, &y, &o), &["W[2, 1]", "row 2, column 1", "NaN"]);
        bad[6] = f64::NEG_INFINITY;
        expect_invalid(lstsq(&bad, 4, 3, &y, &o), &["row 2, column 1", "-inf"]);
        let mut bady = y.clone();
        bady[3] = f64::INFINITY;
        expect_invalid(lstsq(&w, 4, 3, &bady, &o), &["Y[3]", "row 3", "inf"]);
        expect_invalid(lstsq(&[0.0; 12], 4, 3, &y, &o), &["identically zero"]);
        for t in [-1e-3, 1.0, f64::NAN, f64::INFINITY] {
            let opts = LstsqOptions {
                rank_tol: Some(t),
                ..Default::default()
            };
            expect_invalid(lstsq(&w, 4, 3, &y, &opts), &["rank_tol", "[0, 1)"]);
        }
        // An estimate beyond f64 range (tiny W, huge Y) is reported, not returned as inf.
        let tiny: Vec<f64> = w.iter().map(|v| v * 1e-300).collect();
        let huge_y: Vec<f64> = y.iter().map(|v| v * 1e300).collect();
        expect_invalid(lstsq(&tiny, 4, 3, &huge_y, &o), &["overflowed", "rescale"]);
    }

    #[test]
    fn extreme_magnitudes_are_rescaled_exactly() {
        let o = LstsqOptions::default();
        let (w, y) = noisy_problem();
        let s0 = lstsq(&w, 500, 4, &y, &o).unwrap();
        // W near f64::MAX (column norms would overflow), subnormal W, huge Y.
        for (fw, fy) in [(1e307, 1.0), (f64::MIN_POSITIVE * 1e-5, 1e-300), (1.0, 1e305)] {
            let ws: Vec<f64> = w.iter().map(|v| v * fw).collect();
            let ys: Vec<f64> = y.iter().map(|v| v * fy).collect();
            let s = lstsq(&ws, 500, 4, &ys, &o).unwrap();
            assert_eq!(s.rank, 4);
            for j in 0..4 {
                assert_rel(s.params[j] * fw / fy, s0.params[j], 1e-9, "scaled chi");
            }
            assert_rel(s.relative_error, s0.relative_error, 1e-9, "relative error");
            assert_rel(s.condition_number, s0.condition_number, 1e-9, "cond");
            for j in 0..4 {
                assert_rel(s.std[j] * fw / fy, s0.std[j], 1e-9, "scaled std");
            }
        }
    }
}
