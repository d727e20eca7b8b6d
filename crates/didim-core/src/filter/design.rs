//! Filter design: analog prototypes, bilinear transform, ba and sos forms, as scipy.signal.

use super::*;

/// Butterworth digital low-pass filter of order `order` (1..=20) with cutoff
/// `wn` (−3 dB point) normalised to the Nyquist frequency, `0 < wn < 1`
/// (`wn = cutoff_hz / (fs_hz / 2)`), in transfer-function form.
///
/// Same as `scipy.signal.butter(order, wn)` (coefficients to the last bit on
/// glibc platforms). Used by the zero-phase filters of paper section III; see
/// the module documentation on when to prefer [`butter_sos`].
pub fn butter(order: usize, wn: f64) -> Result<Tf> {
    let zpk = design_zpk(order, wn, Proto::Butter)?;
    check_tf(zpk.to_tf(), order, wn)
}

/// Chebyshev type I digital low-pass filter of order `order` (1..=20), with
/// `rp_db` dB of peak-to-peak passband ripple (`rp_db > 0`) and passband edge
/// `wn` normalised to the Nyquist frequency, `0 < wn < 1` (the gain first
/// drops below `-rp_db` dB there), in transfer-function form.
///
/// Same as `scipy.signal.cheby1(order, rp_db, wn)`. MATLAB's `decimate` uses
/// `cheby1(8, 0.05, 0.8/r)` (see [`Decimation::matlab`], paper section III).
pub fn cheby1(order: usize, rp_db: f64, wn: f64) -> Result<Tf> {
    let zpk = design_zpk(order, wn, Proto::Cheby1 { rp_db })?;
    check_tf(zpk.to_tf(), order, wn)
}

/// [`butter`] as second-order sections: the same filter as
/// `scipy.signal.butter(order, wn, output='sos')` (same sections, paired and
/// ordered like scipy's `zpk2sos`, gain in the first section).
pub fn butter_sos(order: usize, wn: f64) -> Result<Sos> {
    let zpk = design_zpk(order, wn, Proto::Butter)?;
    check_sos(zpk.to_sos()?, order, wn)
}

/// [`cheby1`] as second-order sections: the same filter as
/// `scipy.signal.cheby1(order, rp_db, wn, output='sos')`.
pub fn cheby1_sos(order: usize, rp_db: f64, wn: f64) -> Result<Sos> {
    let zpk = design_zpk(order, wn, Proto::Cheby1 { rp_db })?;
    check_sos(zpk.to_sos()?, order, wn)
}

#[derive(Clone, Copy)]
pub(super) enum Proto {
    Butter,
    Cheby1 { rp_db: f64 },
}

/// Digital zeros, poles and gain.
pub(super) struct Zpk {
    z: Vec<C64>,
    p: Vec<C64>,
    k: f64,
}

pub(super) fn validate_order_wn(order: usize, wn: f64) -> Result<()> {
    if order == 0 || order > MAX_ORDER {
        return Err(invalid!(
            "filter order must be between 1 and {MAX_ORDER}, got {order}; choose an order in that range (4 is typical)"
        ));
    }
    if !(wn.is_finite() && wn > 0.0 && wn < 1.0) {
        return Err(invalid!(
            "normalised cutoff wn must satisfy 0 < wn < 1 (cutoff / Nyquist frequency), got {wn}; pass wn = cutoff_hz / (fs_hz / 2) with 0 < cutoff_hz < fs_hz / 2"
        ));
    }
    Ok(())
}

/// scipy's `iirfilter(order, wn, btype='low', analog=False)` up to the zpk.
pub(super) fn design_zpk(order: usize, wn: f64, proto: Proto) -> Result<Zpk> {
    validate_order_wn(order, wn)?;
    let (p, k) = match proto {
        Proto::Butter => buttap(order),
        Proto::Cheby1 { rp_db } => {
            if !(rp_db.is_finite() && rp_db > 0.0) {
                return Err(invalid!(
                    "Chebyshev passband ripple rp_db must be a finite positive number of dB, got {rp_db}; MATLAB's decimate uses 0.05"
                ));
            }
            cheb1ap(order, rp_db)?
        }
    };
    // Prewarp (fs = 2): warped = 2*fs*tan(pi*wn/fs).
    let warped = 4.0 * (PI * wn / 2.0).tan();
    // lp2lp_zpk: scale the poles radially; the relative degree is the order.
    let p: Vec<C64> = p.iter().map(|q| C64::new(warped * q.re, warped * q.im)).collect();
    let k = k * warped.powf(order as f64);
    // bilinear_zpk with fs2 = 2*fs = 4.
    let fs2 = 4.0;
    let pz: Vec<C64> = p
        .iter()
        .map(|q| C64::new(fs2 + q.re, 0.0 + q.im).div(C64::new(fs2 - q.re, 0.0 - q.im)))
        .collect();
    let den = p
        .iter()
        .fold(C64::ONE, |acc, q| acc.mul(C64::new(fs2 - q.re, 0.0 - q.im)));
    let kz = k * C64::ONE.div(den).re;
    // The zeros at infinity move to Nyquist.
    let z = vec![C64::new(-1.0, 0.0); order];
    Ok(Zpk { z, p: pz, k: kz })
}

/// scipy's `buttap`: poles `-exp(i*pi*m/(2N))`, `m = -N+1, -N+3, …, N-1`.
pub(super) fn buttap(order: usize) -> (Vec<C64>, f64) {
    // numpy evaluates 1j*pi*m/(2N) as a complex division, i.e. times 1/(2N).
    let inv = 1.0 / (2 * order) as f64;
    let p = pole_index(order)
        .map(|m| {
            let th = (PI * m) * inv;
            C64::new(-th.cos(), -th.sin())
        })
        .collect();
    (p, 1.0)
}

/// scipy's `cheb1ap`.
pub(super) fn cheb1ap(order: usize, rp_db: f64) -> Result<(Vec<C64>, f64)> {
    let eps = (10f64.powf(0.1 * rp_db) - 1.0).sqrt();
    let mu = 1.0 / order as f64 * asinh_fdlibm(1.0 / eps);
    if !(eps.is_finite() && eps > 0.0 && mu.is_finite()) {
        return Err(invalid!(
            "Chebyshev passband ripple rp_db = {rp_db} dB gives a degenerate prototype (10^(rp_db/10) - 1 is 0 or overflows); use a ripple such as 0.01 to 3 dB (MATLAB's decimate uses 0.05)"
        ));
    }
    let (sh, ch) = (mu.sinh(), mu.cosh());
    let p: Vec<C64> = pole_index(order)
        .map(|m| {
            let th = PI * m / (2 * order) as f64;
            C64::new(-(sh * th.cos()), -(ch * th.sin()))
        })
        .collect();
    let mut k = p
        .iter()
        .fold(C64::ONE, |acc, q| acc.mul(C64::new(-q.re, -q.im)))
        .re;
    if order % 2 == 0 {
        k /= (1.0 + eps * eps).sqrt();
    }
    Ok((p, k))
}

/// `-N+1, -N+3, …, N-1` as floats.
pub(super) fn pole_index(order: usize) -> impl Iterator<Item = f64> {
    (0..order).map(move |i| (2 * i) as f64 - (order - 1) as f64)
}

impl Zpk {
    /// scipy's `zpk2tf`.
    pub(super) fn to_tf(&self) -> Tf {
        let b = poly(&self.z).iter().map(|c| self.k * c.re).collect();
        let a = poly(&self.p).iter().map(|c| c.re).collect();
        Tf { b, a }
    }

    /// scipy's `zpk2sos(z, p, k, pairing='nearest')` (discrete time).
    pub(super) fn to_sos(&self) -> Result<Sos> {
        let mut z = self.z.clone();
        let mut p = self.p.clone();
        if z.is_empty() && p.is_empty() {
            return Ok(Sos(vec![[self.k, 0.0, 0.0, 1.0, 0.0, 0.0]]));
        }
        while p.len() < z.len() {
            p.push(C64::ZERO);
        }
        while z.len() < p.len() {
            z.push(C64::ZERO);
        }
        let n_sections = p.len().div_ceil(2);
        if p.len() % 2 == 1 {
            p.push(C64::ZERO);
            z.push(C64::ZERO);
        }
        let mut z = cplxreal(&z)?;
        let mut p = cplxreal(&p)?;
        let mut sos = vec![[0.0; 6]; n_sections];
        for si in (0..n_sections).rev() {
            let Some(p1_idx) = idx_worst(&p, |_| true) else {
                break;
            };
            let p1 = p.remove(p1_idx);
            let real_p = p.iter().filter(|q| q.is_real()).count();
            let real_z = z.iter().filter(|q| q.is_real()).count();
            let row = if p1.is_real() && real_p == 0 {
                // Last remaining real pole: pair it with the nearest real zero
                // and the pole and zero at the origin.
                let z1 = take_nearest(&mut z, p1, Which::Real).unwrap_or(C64::ZERO);
                single_zpksos(&[z1, C64::ZERO], &[p1, C64::ZERO])
            } else if p.len() + 1 == z.len() && !p1.is_real() && real_p == 1 && real_z == 1 {
                // One real pole and zero left: the complex pole takes a complex zero.
                match take_nearest(&mut z, p1, Which::Complex) {
                    Some(z1) => single_zpksos(&[z1, z1.conj()], &[p1, p1.conj()]),
                    None => single_zpksos(&[], &[p1, p1.conj()]),
                }
            } else {
                let p2 = if p1.is_real() {
                    match idx_worst(&p, |q| q.is_real()) {
                        Some(i) => p.remove(i),
                        None => C64::ZERO,
                    }
                } else {
                    p1.conj()
                };
                match take_nearest(&mut z, p1, Which::Any) {
                    Some(z1) if !z1.is_real() => single_zpksos(&[z1, z1.conj()], &[p1, p2]),
                    Some(z1) => match take_nearest(&mut z, p1, Which::Real) {
                        Some(z2) => single_zpksos(&[z1, z2], &[p1, p2]),
                        None => single_zpksos(&[z1], &[p1, p2]),
                    },
                    None => single_zpksos(&[], &[p1, p2]),
                }
            };
            sos[si] = row;
        }
        if let Some(first) = sos.first_mut() {
            for v in &mut first[..3] {
                *v *= self.k;
            }
        }
        Ok(Sos(sos))
    }
}

pub(super) fn check_tf(tf: Tf, order: usize, wn: f64) -> Result<Tf> {
    let finite = tf.b.iter().chain(&tf.a).all(|v| v.is_finite());
    if !finite || tf.b.iter().all(|&v| v == 0.0) {
        return Err(degenerate(order, wn));
    }
    Ok(tf)
}

pub(super) fn check_sos(sos: Sos, order: usize, wn: f64) -> Result<Sos> {
    let finite = sos.0.iter().flatten().all(|v| v.is_finite());
    let zero_gain = sos.0.first().is_none_or(|s| s[..3].iter().all(|&v| v == 0.0));
    if !finite || zero_gain {
        return Err(degenerate(order, wn));
    }
    Ok(sos)
}

pub(super) fn degenerate(order: usize, wn: f64) -> Error {
    invalid!(
        "the order-{order} design at wn = {wn} is numerically degenerate (coefficients underflow or overflow); use a larger cutoff wn or a lower order"
    )
}

/// numpy's `poly` (scipy `_polyutils.poly`): expand `Π (x - r_i)` by repeated
/// convolution with `[1, -r_i]`, with the rounding of numpy's `convolve`
/// (OpenBLAS `zdotu` for the two-term sums). Only the real part is used.
pub(super) fn poly(roots: &[C64]) -> Vec<C64> {
    let mut c = vec![C64::ONE];
    for r in roots {
        let m = C64::new(-r.re, -r.im);
        let len = c.len();
        let mut next = Vec::with_capacity(len + 1);
        next.push(c[0]);
        for i in 1..len {
            let (cur, prev) = (c[i], c[i - 1]);
            let re = (cur.re + prev.re * m.re) - prev.im * m.im;
            let im = prev.re * m.im + (cur.im + prev.im * m.re);
            next.push(C64::new(re, im));
        }
        next.push(c[len - 1].mul(m));
        c = next;
    }
    c
}

/// scipy's `_single_zpksos(z, p, 1)`.
pub(super) fn single_zpksos(z: &[C64], p: &[C64]) -> [f64; 6] {
    let mut row = [0.0; 6];
    let b = poly(z);
    let a = poly(p);
    for (dst, src) in row[..3].iter_mut().rev().zip(b.iter().rev()) {
        *dst = src.re;
    }
    for (dst, src) in row[3..].iter_mut().rev().zip(a.iter().rev()) {
        *dst = src.re;
    }
    row
}

/// Index of the element closest to the unit circle among those selected
/// (scipy's `idx_worst`, first one on ties).
pub(super) fn idx_worst(p: &[C64], select: impl Fn(&C64) -> bool) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, q) in p.iter().enumerate() {
        if !select(q) {
            continue;
        }
        let d = (1.0 - q.abs()).abs();
        if best.is_none_or(|(_, bd)| d < bd) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

#[derive(Clone, Copy)]
pub(super) enum Which {
    Real,
    Complex,
    Any,
}

/// scipy's `_nearest_real_complex_idx` followed by the removal of that element.
pub(super) fn take_nearest(fro: &mut Vec<C64>, to: C64, which: Which) -> Option<C64> {
    let mut best: Option<(usize, f64)> = None;
    for (i, q) in fro.iter().enumerate() {
        let ok = match which {
            Which::Real => q.is_real(),
            Which::Complex => !q.is_real(),
            Which::Any => true,
        };
        if !ok {
            continue;
        }
        let d = C64::new(q.re - to.re, q.im - to.im).abs();
        if best.is_none_or(|(_, bd)| d < bd) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| fro.remove(i))
}

/// scipy's `_cplxreal`: the complex elements, one per conjugate pair (positive
/// imaginary part, averaged), followed by the real ones (sorted).
pub(super) fn cplxreal(z: &[C64]) -> Result<Vec<C64>> {
    let tol = 100.0 * f64::EPSILON;
    let key = |v: f64| if v == 0.0 { 0.0 } else { v };
    let mut s = z.to_vec();
    s.sort_by(|a, b| {
        key(a.re)
            .total_cmp(&key(b.re))
            .then(key(a.im.abs()).total_cmp(&key(b.im.abs())))
    });
    let is_real = |q: &C64| q.im.abs() <= tol * q.abs();
    let mut out: Vec<C64> = Vec::with_capacity(s.len());
    let reals: Vec<C64> = s
        .iter()
        .filter(|q| is_real(q))
        .map(|q| C64::new(q.re, 0.0))
        .collect();
    let cplx: Vec<C64> = s.iter().filter(|q| !is_real(q)).copied().collect();
    let mut zp: Vec<C64> = cplx.iter().filter(|q| q.im > 0.0).copied().collect();
    let mut zn: Vec<C64> = cplx.iter().filter(|q| q.im < 0.0).copied().collect();
    if zp.len() != zn.len() {
        return Err(invalid!(
            "internal filter design error: a complex pole or zero has no conjugate"
        ));
    }
    // Runs of (nearly) equal real part are sorted by imaginary part.
    let mut start = 0;
    while start < zp.len() {
        let mut stop = start;
        while stop + 1 < zp.len() && zp[stop + 1].re - zp[stop].re <= tol * zp[stop].abs() {
            stop += 1;
        }
        if stop > start {
            zp[start..=stop].sort_by(|a, b| key(a.im.abs()).total_cmp(&key(b.im.abs())));
            zn[start..=stop].sort_by(|a, b| key(a.im.abs()).total_cmp(&key(b.im.abs())));
        }
        start = stop + 1;
    }
    for (a, b) in zp.iter().zip(&zn) {
        if C64::new(a.re - b.re, a.im + b.im).abs() > tol * b.abs() {
            return Err(invalid!(
                "internal filter design error: a complex pole or zero has no conjugate"
            ));
        }
        out.push(C64::new((a.re + b.re) * 0.5, (a.im - b.im) * 0.5));
    }
    out.extend(reals);
    Ok(out)
}
