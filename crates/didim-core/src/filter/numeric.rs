//! Numerical helpers: complex arithmetic as numpy's, polynomial roots, the small linear solves (with OpenBLAS's operation order).

/// Complex number with numpy's arithmetic (no fused operations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct C64 {
    pub(super) re: f64,
    pub(super) im: f64,
}

impl C64 {
    pub(super) const ZERO: C64 = C64 { re: 0.0, im: 0.0 };
    pub(super) const ONE: C64 = C64 { re: 1.0, im: 0.0 };

    pub(super) fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }

    pub(super) fn mul(self, o: Self) -> Self {
        Self::new(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
    }

    /// numpy's complex division (Smith's method with a reciprocal).
    pub(super) fn div(self, o: Self) -> Self {
        let (ar, ai, br, bi) = (self.re, self.im, o.re, o.im);
        if br.abs() >= bi.abs() {
            if br == 0.0 && bi == 0.0 {
                return Self::new(ar / br.abs(), ai / br.abs());
            }
            let rat = bi / br;
            let scl = 1.0 / (br + bi * rat);
            Self::new((ar + ai * rat) * scl, (ai - ar * rat) * scl)
        } else {
            let rat = br / bi;
            let scl = 1.0 / (bi + br * rat);
            Self::new((ar * rat + ai) * scl, (ai * rat - ar) * scl)
        }
    }

    pub(super) fn abs(self) -> f64 {
        self.re.hypot(self.im)
    }

    pub(super) fn conj(self) -> Self {
        Self::new(self.re, -self.im)
    }

    pub(super) fn is_real(self) -> bool {
        self.im == 0.0
    }
}

/// Double-double number `hi + lo` (about 106 significant bits).
#[derive(Debug, Clone, Copy)]
pub(super) struct Dd {
    hi: f64,
    lo: f64,
}

impl Dd {
    pub(super) const ZERO: Dd = Dd { hi: 0.0, lo: 0.0 };

    pub(super) fn from(v: f64) -> Self {
        Self { hi: v, lo: 0.0 }
    }

    pub(super) fn value(self) -> f64 {
        self.hi + self.lo
    }

    pub(super) fn renorm(s: f64, e: f64) -> Self {
        let hi = s + e;
        Self { hi, lo: e - (hi - s) }
    }

    pub(super) fn add(self, o: Self) -> Self {
        let s = self.hi + o.hi;
        let bb = s - self.hi;
        let e = (self.hi - (s - bb)) + (o.hi - bb);
        Self::renorm(s, e + self.lo + o.lo)
    }

    pub(super) fn sub(self, o: Self) -> Self {
        self.add(Self { hi: -o.hi, lo: -o.lo })
    }

    pub(super) fn mul(self, c: f64) -> Self {
        let p = self.hi * c;
        let e = self.hi.mul_add(c, -p);
        Self::renorm(p, e + self.lo * c)
    }
}

/// `asinh` as computed by fdlibm/glibc (what Python's `math.asinh` returns on
/// glibc); Rust's `f64::asinh` rounds differently in the last bit.
pub(super) fn asinh_fdlibm(x: f64) -> f64 {
    pub(super) const LN2: f64 = std::f64::consts::LN_2;
    let ix = ((x.to_bits() >> 32) as u32) & 0x7fff_ffff;
    if ix >= 0x7ff0_0000 {
        return x + x;
    }
    if ix < 0x3e30_0000 {
        return x;
    }
    let ax = x.abs();
    let w = if ix > 0x41b0_0000 {
        ax.ln() + LN2
    } else if ix > 0x4000_0000 {
        (2.0 * ax + 1.0 / ((ax * ax + 1.0).sqrt() + ax)).ln()
    } else {
        let t = ax * ax;
        (ax + t / (1.0 + (1.0 + t).sqrt())).ln_1p()
    };
    w.copysign(x)
}

/// Solves `M x = rhs` (`M` column-major `m × m`) by LU with partial pivoting;
/// `None` if `M` is singular or the solution is not finite. numpy's `solve`
/// (LAPACK `dgesv`) does the same in another operation order: on the
/// ill-conditioned steady states of high-order ba filters the two agree to the
/// conditioning of the system, not to the last bit (see the tests).
pub(super) fn solve(mat: Vec<f64>, m: usize, rhs: &[f64]) -> Option<Vec<f64>> {
    let a = nalgebra::DMatrix::from_vec(m, m, mat);
    let x = a.lu().solve(&nalgebra::DVector::from_column_slice(rhs))?;
    x.iter().all(|v| v.is_finite()).then(|| x.as_slice().to_vec())
}
