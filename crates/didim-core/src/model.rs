//! Linear-in-parameters models of a position-controlled axis.
//!
//! One definition feeds everything: a [`Model`] is a list of named terms, each a
//! parameter times a basis function of the state ([`Basis`]). The same basis
//! functions give
//! - the inverse dynamic model (IDM), `τ_idm = Σ_j χ_j φ_j(q, q̇, q̈)`, one row per
//!   degree of freedom (paper eqs. (2), (4), (6), (7)),
//! - the regressor `W` used by IDIM-LS and DIDIM (the matrix of the `φ_j`),
//! - the direct dynamic model integrated by the simulator (eqs. (5), (9)):
//!   `M q̈ = u − Σ_{non-inertial j} χ_j φ_j(q, q̇)`, where `u = (τ, 0, …)`.
//!
//! A new physical effect is added as one [`Basis`] variant; the simulator, the
//! regressor and the sensitivities pick it up unchanged.
//!
//! Units are SI on the load side: positions in m, velocities in m/s, forces in N,
//! masses in kg, viscous friction in N/(m/s), Coulomb friction in N, stiffness in N/m.
//!
//! Coordinates of the flexible model follow the paper: dof 0 is the motor
//! position `q1`, dof 1 is the load position `q12 = q1 + q2`; the spring
//! elongation is `q2 = q12 − q1`.

use crate::error::{invalid, Result};
use nalgebra::{SMatrix, SVector};

/// Index of the motor (actuated, measured) degree of freedom.
pub const MOTOR: usize = 0;
/// Index of the load degree of freedom of the flexible model (`q12`).
pub const LOAD: usize = 1;

/// A named hyper-parameter of a term kind: a number fixed while the term's parameter is
/// identified (a Stribeck speed, a period, a knot), with its SI unit on the load side and
/// its default (None: it must be given).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hyper {
    pub name: &'static str,
    pub unit: &'static str,
    pub default: Option<f64>,
}

const fn hyper(name: &'static str, unit: &'static str) -> Hyper {
    Hyper {
        name,
        unit,
        default: None,
    }
}

const fn hyper_or(name: &'static str, unit: &'static str, default: f64) -> Hyper {
    Hyper {
        name,
        unit,
        default: Some(default),
    }
}

/// One kind of extra model term: its name, its named hyper-parameters and how its basis
/// function is built from them (in the order of `hypers`) on a degree of freedom.
pub struct TermKind {
    pub name: &'static str,
    pub hypers: &'static [Hyper],
    /// What it is, in a few words (the Python layer's docs and errors).
    pub doc: &'static str,
    build: fn(usize, &[f64]) -> Basis,
}

/// The kinds of extra model terms, the one table every layer reads (the Python layer's
/// `TERM_KINDS`, the saved models, the doctor). A new term kind is one row here, one
/// [`Basis`] variant with its arm in [`Basis::local`], [`Basis::unit`] and [`Basis::role`],
/// and its test.
pub const TERM_TABLE: &[TermKind] = &[
    TermKind {
        name: "offset",
        hypers: &[],
        doc: "a constant force: 1",
        build: |dof, _| Basis::Offset { dof },
    },
    TermKind {
        name: "viscous",
        hypers: &[],
        doc: "viscous friction: q̇",
        build: |dof, _| Basis::Viscous { dof },
    },
    TermKind {
        name: "coulomb",
        hypers: &[],
        doc: "Coulomb friction: sign(q̇)",
        build: |dof, _| Basis::Coulomb { dof },
    },
    TermKind {
        name: "abs_viscous",
        hypers: &[],
        doc: "direction-dependent viscous friction: |q̇|",
        build: |dof, _| Basis::AbsViscous { dof },
    },
    TermKind {
        name: "abs_coulomb",
        hypers: &[],
        doc: "direction-dependent Coulomb friction: |sign(q̇)|",
        build: |dof, _| Basis::AbsCoulomb { dof },
    },
    TermKind {
        name: "stribeck",
        hypers: &[hyper("vs", "m/s")],
        doc: "Stribeck friction: sign(q̇)·exp(−(q̇/vs)²)",
        build: |dof, h| Basis::Stribeck { dof, vs: h[0] },
    },
    TermKind {
        name: "ripple",
        hypers: &[hyper("period", "m"), hyper_or("phase", "rad", 0.0)],
        doc: "a position-periodic force: sin(2π q/period + phase)",
        build: |dof, h| Basis::Ripple {
            dof,
            period: h[0],
            phase: h[1],
        },
    },
    TermKind {
        name: "coulomb_ripple",
        hypers: &[hyper("period", "m"), hyper_or("phase", "rad", 0.0)],
        doc: "Coulomb friction varying along the stroke: sign(q̇)·sin(2π q/period + phase)",
        build: |dof, h| Basis::CoulombRipple {
            dof,
            period: h[0],
            phase: h[1],
        },
    },
    TermKind {
        name: "coulomb_spline",
        hypers: &[
            hyper("center", "m"),
            hyper("width", "m"),
            hyper_or("side", "1", 0.0),
            hyper_or("lo", "m", 0.0),
            hyper_or("hi", "m", 0.0),
        ],
        doc: "a friction profile's knot: B((q − center)/width)·σ(q̇), side 1 forward, −1 backward, 0 both; \
              q held within [lo, hi] when lo < hi (the profile flat beyond its stroke)",
        build: |dof, h| Basis::CoulombSpline {
            dof,
            center: h[0],
            width: h[1],
            side: h[2] as i8,
            lo: h[3],
            hi: h[4],
        },
    },
    TermKind {
        name: "spline",
        hypers: &[
            hyper("center", "m"),
            hyper("width", "m"),
            hyper_or("lo", "m", 0.0),
            hyper_or("hi", "m", 0.0),
        ],
        doc: "a force profile's knot along the stroke: B((q − center)/width) (a counterbalance, a cable, a spring); \
              q held within [lo, hi] when lo < hi (the profile flat beyond its stroke)",
        build: |dof, h| Basis::Spline {
            dof,
            center: h[0],
            width: h[1],
            lo: h[2],
            hi: h[3],
        },
    },
    TermKind {
        name: "damper",
        hypers: &[],
        doc: "coupling damping in parallel with K12: q̇1 − q̇12 (flexible model)",
        build: |_, _| Basis::Damper { a: MOTOR, b: LOAD },
    },
    TermKind {
        name: "gravity",
        hypers: &[
            hyper_or("angle_offset", "rad", 0.0),
            hyper_or("phase", "rad", 0.0),
        ],
        doc: "the gravity torque of a rotary joint: sin(q + angle_offset + phase) (phase π/2 for the cosine)",
        build: |dof, h| Basis::Gravity {
            dof,
            angle_offset: h[0],
            phase: h[1],
        },
    },
];

/// An older kind name, the kind it stands for and the hyper-parameters its name fixed.
pub type TermAlias = (&'static str, &'static str, &'static [(&'static str, f64)]);

/// Older kind names, read from saved models: each is a kind of [`TERM_TABLE`] with some
/// hyper-parameters fixed (the phase or the side that was part of the name).
pub const TERM_ALIASES: &[TermAlias] = &[
    ("ripple_sin", "ripple", &[("phase", 0.0)]),
    ("ripple_cos", "ripple", &[("phase", std::f64::consts::FRAC_PI_2)]),
    ("coulomb_ripple_sin", "coulomb_ripple", &[("phase", 0.0)]),
    (
        "coulomb_ripple_cos",
        "coulomb_ripple",
        &[("phase", std::f64::consts::FRAC_PI_2)],
    ),
    ("coulomb_spline_fwd", "coulomb_spline", &[("side", 1.0)]),
    ("coulomb_spline_bwd", "coulomb_spline", &[("side", -1.0)]),
];

/// The row of [`TERM_TABLE`] named `kind`.
pub fn term_kind(kind: &str) -> Result<&'static TermKind> {
    TERM_TABLE.iter().find(|k| k.name == kind).ok_or_else(|| {
        invalid!(
            "unknown term kind {kind:?}: use one of {} (damper: flexible model)",
            TERM_TABLE.iter().map(|k| k.name).collect::<Vec<_>>().join(", ")
        )
    })
}

/// A kind and its named hyper-parameters in canonical form: an alias of [`TERM_ALIASES`]
/// becomes its kind with the hyper-parameters its name fixed; every hyper-parameter of
/// the kind is given a value (the given one, else its default) in the table's order. An
/// unknown or repeated name, a missing hyper-parameter without default, or an alias's
/// fixed one given otherwise is an error naming it.
pub fn canonical_term(kind: &str, given: &[(&str, f64)]) -> Result<(&'static TermKind, Vec<f64>)> {
    let (name, fixed): (&str, &[(&str, f64)]) = match TERM_ALIASES.iter().find(|a| a.0 == kind) {
        Some((_, k, f)) => (k, f),
        None => (kind, &[]),
    };
    let tk = term_kind(name)?;
    let names = || tk.hypers.iter().map(|h| h.name).collect::<Vec<_>>().join(", ");
    for (i, (n, _)) in given.iter().enumerate() {
        if !tk.hypers.iter().any(|h| h.name == *n) {
            return Err(if tk.hypers.is_empty() {
                invalid!("a {kind} term has no hyper-parameter, got {n:?}")
            } else {
                invalid!("a {kind} term's hyper-parameters are {}, got {n:?}", names())
            });
        }
        if given[..i].iter().any(|(m, _)| m == n) {
            return Err(invalid!("hyper-parameter {n:?} of a {kind} term given twice"));
        }
        if let Some((_, v)) = fixed.iter().find(|(m, _)| m == n) {
            if given[i].1 != *v {
                return Err(invalid!(
                    "a {kind} term has {n} = {v}; give a {name} term for another {n}"
                ));
            }
        }
    }
    let values = tk
        .hypers
        .iter()
        .map(|h| {
            given
                .iter()
                .chain(fixed.iter())
                .find(|(n, _)| *n == h.name)
                .map(|(_, v)| *v)
                .or(h.default)
                .ok_or_else(|| {
                    invalid!(
                        "a {name} term needs its hyper-parameter {} ({}); its hyper-parameters are {}",
                        h.name,
                        h.unit,
                        names()
                    )
                })
        })
        .collect::<Result<Vec<f64>>>()?;
    Ok((tk, values))
}

/// What a parameter is, physically: how the doctor and the reports group parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Mass,
    Friction,
    Stiffness,
    Damping,
    Force,
}

impl Role {
    pub fn name(&self) -> &'static str {
        match self {
            Role::Mass => "mass",
            Role::Friction => "friction",
            Role::Stiffness => "stiffness",
            Role::Damping => "damping",
            Role::Force => "force",
        }
    }
}

/// Default velocity scale of the smoothed Coulomb sign, in m/s.
///
/// Small against the EMPS speeds (plateaus at 0.042 to 0.125 m/s, sign > 0.9999
/// there), about two encoder counts per millisecond, and large enough that the
/// equivalent viscous slope `Fc/ε` at rest stays well inside the stability region
/// of RK4 with the default 10 substeps of 1 kHz sampling.
pub const DEFAULT_COULOMB_EPS: f64 = 1e-4;

/// The sign of a velocity in every Coulomb-type friction term.
///
/// `eps > 0`: the smooth sign `v / sqrt(v² + eps²)` (odd, monotone, slope `1/eps`
/// at rest, within 0.5 % of ±1 beyond `|v| = 10 eps`).
/// `eps == 0`: the hard sign, with `sign(0) = 0` (MATLAB's `sign`, used by the
/// EMPS benchmark's IDIM-LS recipe on filtered measured velocities).
///
/// The simulator and the regressors call this one function with the model's
/// `coulomb_eps`, so the dynamics that produce the states and the regressor that
/// explains the force use the same friction law: a hard sign in the regressor
/// against a smoothed sign in the dynamics would bias the friction estimates.
///
/// Robust for any input: where `v² + eps²` underflows or overflows (velocities or
/// `eps` beyond about 1e±150) it divides by `hypot(v, eps)` instead, so the result
/// stays within [-1, 1] (±1 for infinite `v`, NaN only for NaN `v`).
#[inline]
pub fn coulomb_sign(v: f64, eps: f64) -> f64 {
    if eps > 0.0 {
        let d = v * v + eps * eps;
        // `d.is_normal()` for d ≥ 0 (as d is, or NaN), tested in the floating-point unit: the bit test moved d to
        // an integer register on the simulator's critical path
        if (f64::MIN_POSITIVE..f64::INFINITY).contains(&d) {
            v / d.sqrt()
        } else if v.is_infinite() {
            v.signum()
        } else {
            v / v.hypot(eps)
        }
    } else if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Derivative of [`coulomb_sign`] with respect to the velocity (0 for the hard sign
/// away from 0; the hard sign has no derivative at 0 and 0 is returned).
#[inline]
pub fn coulomb_sign_derivative(v: f64, eps: f64) -> f64 {
    if eps > 0.0 {
        let s = v * v + eps * eps;
        if s.is_normal() {
            eps * eps / (s * s.sqrt())
        } else {
            let h = v.hypot(eps);
            let r = eps / h;
            r * r / h
        }
    } else {
        0.0
    }
}

/// The uniform cubic B-spline `B(u)` (support `|u| < 2`, `B(0) = 2/3`, the splines at the
/// integers summing to 1) and its derivative `B'(u)`.
#[inline]
pub fn cubic_bspline(u: f64) -> (f64, f64) {
    let a = u.abs();
    if a < 1.0 {
        (2.0 / 3.0 - a * a + 0.5 * a * a * a, u * (1.5 * a - 2.0))
    } else if a < 2.0 {
        let r = 2.0 - a;
        (r * r * r / 6.0, -0.5 * r * r * u.signum())
    } else {
        (0.0, 0.0)
    }
}

/// A spline knot's value and slope in `x` (`B((x − center)/width)`, `B'/width`), with `x` held
/// within `[lo, hi]` when `lo < hi`: beyond the ends the value of the end and slope 0.
#[inline]
pub fn held_bspline(x: f64, center: f64, width: f64, lo: f64, hi: f64) -> (f64, f64) {
    if lo < hi && !(lo..=hi).contains(&x) {
        let (b, _) = cubic_bspline((x.clamp(lo, hi) - center) / width);
        return (b, 0.0);
    }
    let (b, db) = cubic_bspline((x - center) / width);
    (b, db / width)
}

/// [`coulomb_sign`] and [`coulomb_sign_derivative`] at once (one square root).
#[inline(always)]
pub fn coulomb_sign_and_derivative(v: f64, eps: f64) -> (f64, f64) {
    if eps > 0.0 {
        let d = v * v + eps * eps;
        // `d.is_normal()` for d ≥ 0 (as d is, or NaN), tested in the floating-point unit: the bit test moved d to
        // an integer register on the simulator's critical path
        if (f64::MIN_POSITIVE..f64::INFINITY).contains(&d) {
            let inv = 1.0 / d.sqrt();
            let s = v * inv;
            (s, (eps * inv) * (eps * inv) * inv)
        } else {
            (coulomb_sign(v, eps), coulomb_sign_derivative(v, eps))
        }
    } else {
        (coulomb_sign(v, eps), 0.0)
    }
}

/// The shapes of the smoothed Coulomb sign through zero speed. Each is odd, monotone,
/// saturates at ±1 and has the slope `1/eps` at rest, so that `eps` means the same
/// transition speed for every shape; real friction's shape is not known in advance,
/// and the shape is a hyper-parameter of the model (the doctor chooses it by
/// closed-loop fit).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LawShape {
    /// `v / sqrt(v² + eps²)`: saturates slowly (`1 − 1/(2x²)`, `x = v/eps`).
    #[default]
    Algebraic,
    /// `tanh(v / eps)`: saturates exponentially fast.
    Tanh,
    /// `(2/π)·atan(π v / (2 eps))`: the slowest (`1 − 4/(π² x)`).
    Atan,
    /// `sign(v)·(1 − exp(−|v| / eps))`: a first-order rise.
    Exp,
}

/// The names of [`LawShape`]s (`coulomb_law` in the Python layer).
pub const LAW_SHAPES: &[&str] = &["algebraic", "tanh", "atan", "exp"];

impl LawShape {
    /// The shape named `name` (one of [`LAW_SHAPES`]).
    pub fn from_name(name: &str) -> Result<LawShape> {
        Ok(match name {
            "algebraic" => LawShape::Algebraic,
            "tanh" => LawShape::Tanh,
            "atan" => LawShape::Atan,
            "exp" => LawShape::Exp,
            other => {
                return Err(invalid!(
                    "unknown Coulomb law {other:?}: use one of {}",
                    LAW_SHAPES.join(", ")
                ))
            }
        })
    }

    /// This shape's name, as [`LawShape::from_name`] reads it.
    pub fn name(&self) -> &'static str {
        match self {
            LawShape::Algebraic => "algebraic",
            LawShape::Tanh => "tanh",
            LawShape::Atan => "atan",
            LawShape::Exp => "exp",
        }
    }
}

/// The friction law through zero speed of every Coulomb-type term: its shape and its
/// transition speed `eps` (m/s or rad/s; 0 for the hard sign, whatever the shape).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FrictionLaw {
    pub shape: LawShape,
    pub eps: f64,
}

impl FrictionLaw {
    /// The algebraic law `v / sqrt(v² + eps²)` (didim's default shape).
    pub fn algebraic(eps: f64) -> FrictionLaw {
        FrictionLaw {
            shape: LawShape::Algebraic,
            eps,
        }
    }

    /// The smoothed sign of `v` and its derivative with respect to `v`.
    #[inline(always)]
    pub fn sign_and_derivative(&self, v: f64) -> (f64, f64) {
        let eps = self.eps;
        if eps.is_nan() || eps <= 0.0 {
            return (coulomb_sign(v, 0.0), 0.0);
        }
        match self.shape {
            LawShape::Algebraic => Algebraic::shape(v, eps),
            LawShape::Tanh => Tanh::shape(v, eps),
            LawShape::Atan => Atan::shape(v, eps),
            LawShape::Exp => ExpRise::shape(v, eps),
        }
    }

    /// Runs `f` with this law as a [`Law`] whose shape is a type: the shape is dispatched
    /// here, once, and `f`'s loop is compiled for it (no branch on the shape per evaluation).
    #[inline(always)]
    pub(crate) fn dispatch<F: WithLaw>(self, f: F) -> F::Out {
        let eps = self.eps;
        match self.shape {
            LawShape::Algebraic => f.call(Shaped::<Algebraic>::new(eps)),
            LawShape::Tanh => f.call(Shaped::<Tanh>::new(eps)),
            LawShape::Atan => f.call(Shaped::<Atan>::new(eps)),
            LawShape::Exp => f.call(Shaped::<ExpRise>::new(eps)),
        }
    }

    /// The smoothed sign of `v`.
    #[inline]
    pub fn sign(&self, v: f64) -> f64 {
        self.sign_and_derivative(v).0
    }

    /// The derivative of the smoothed sign of `v` with respect to the smoothing speed `eps`: every
    /// shape is a function of `v / eps`, so `∂s/∂eps = −(v/eps) ∂s/∂v`; 0 for the hard sign.
    #[inline]
    pub fn eps_derivative(&self, v: f64) -> f64 {
        let eps = self.eps;
        if eps.is_nan() || eps <= 0.0 {
            return 0.0;
        }
        -(v / eps) * self.sign_and_derivative(v).1
    }
}

/// A friction law as the hot loops read it: the smoothed sign of a velocity and its
/// derivative. [`FrictionLaw`] chooses its shape at run time, per evaluation; a [`Shaped`] law
/// has its shape in its type ([`FrictionLaw::dispatch`]), so a loop generic over the law is
/// compiled once per shape without a branch on it. Both compute the same values, bit for bit
/// (the same shape functions).
pub(crate) trait Law: Copy {
    /// The smoothed sign of `v` and its derivative with respect to `v`.
    fn sign_and_derivative(&self, v: f64) -> (f64, f64);
    /// The law as a value.
    fn law(&self) -> FrictionLaw;
}

impl Law for FrictionLaw {
    #[inline(always)]
    fn sign_and_derivative(&self, v: f64) -> (f64, f64) {
        FrictionLaw::sign_and_derivative(self, v)
    }
    #[inline(always)]
    fn law(&self) -> FrictionLaw {
        *self
    }
}

/// One shape of the smoothed sign, for `eps > 0` (`eps` ≤ 0 or NaN is the hard sign for
/// every shape, decided by the caller).
pub(crate) trait Shape: Copy + Default {
    const SHAPE: LawShape;
    fn shape(v: f64, eps: f64) -> (f64, f64);
}

/// [`LawShape::Algebraic`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Algebraic;
/// [`LawShape::Tanh`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Tanh;
/// [`LawShape::Atan`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Atan;
/// [`LawShape::Exp`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ExpRise;

impl Shape for Algebraic {
    const SHAPE: LawShape = LawShape::Algebraic;
    #[inline(always)]
    fn shape(v: f64, eps: f64) -> (f64, f64) {
        coulomb_sign_and_derivative(v, eps)
    }
}

impl Shape for Tanh {
    const SHAPE: LawShape = LawShape::Tanh;
    #[inline(always)]
    fn shape(v: f64, eps: f64) -> (f64, f64) {
        // through one exponential (the C library's tanh goes through expm1: twice the time
        // in a robot's closed loop), odd by construction, within 4 ulp of 1 of it
        let x = v / eps;
        let t = (1.0 - 2.0 / ((2.0 * x.abs()).exp() + 1.0)).copysign(x);
        (t, (1.0 - t * t) / eps)
    }
}

impl Shape for Atan {
    const SHAPE: LawShape = LawShape::Atan;
    #[inline(always)]
    fn shape(v: f64, eps: f64) -> (f64, f64) {
        let k = std::f64::consts::FRAC_PI_2 / eps;
        let x = k * v;
        (
            std::f64::consts::FRAC_2_PI * x.atan(),
            1.0 / (eps * (1.0 + x * x)),
        )
    }
}

impl Shape for ExpRise {
    const SHAPE: LawShape = LawShape::Exp;
    #[inline(always)]
    fn shape(v: f64, eps: f64) -> (f64, f64) {
        let e = (-(v.abs() / eps)).exp();
        if v.is_infinite() {
            (v.signum(), 0.0)
        } else {
            (coulomb_sign(v, 0.0) * (1.0 - e), e / eps)
        }
    }
}

/// A [`FrictionLaw`] of shape `S`: the same values, the shape known at compile time.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Shaped<S: Shape> {
    eps: f64,
    /// `eps > 0` (else the hard sign): decided once.
    smooth: bool,
    shape: S,
}

impl<S: Shape> Shaped<S> {
    #[inline(always)]
    pub(crate) fn new(eps: f64) -> Self {
        Self {
            eps,
            smooth: !(eps.is_nan() || eps <= 0.0),
            shape: S::default(),
        }
    }
}

impl<S: Shape> Law for Shaped<S> {
    #[inline(always)]
    fn sign_and_derivative(&self, v: f64) -> (f64, f64) {
        let _ = self.shape;
        if !self.smooth {
            return (coulomb_sign(v, 0.0), 0.0);
        }
        S::shape(v, self.eps)
    }
    #[inline(always)]
    fn law(&self) -> FrictionLaw {
        FrictionLaw {
            shape: S::SHAPE,
            eps: self.eps,
        }
    }
}

/// What runs with a [`Law`] of a static shape ([`FrictionLaw::dispatch`]): a generic
/// function with its arguments.
pub(crate) trait WithLaw {
    type Out;
    fn call<L: Law>(self, law: L) -> Self::Out;
}

/// The basis function multiplying one parameter, per degree of freedom.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Basis {
    /// Mass of dof `dof`: `φ = q̈_dof` on row `dof` (kg).
    Inertia { dof: usize },
    /// Viscous friction of dof `dof`: `φ = q̇_dof` (N/(m/s)).
    Viscous { dof: usize },
    /// Coulomb friction of dof `dof`: `φ = coulomb_sign(q̇_dof)` (N).
    Coulomb { dof: usize },
    /// Constant force on dof `dof`: `φ = 1` (N), e.g. an amplifier offset.
    Offset { dof: usize },
    /// Spring between the motor dof `a` and the load dof `b` (N/m):
    /// `φ_a = q_a − q_b = −q2`, `φ_b = q_b − q_a = q2` (eq. (4), last column).
    Spring { a: usize, b: usize },
    /// Direction-dependent viscous friction (N/(m/s)): `φ = |q̇|` (smoothed as
    /// `q̇·coulomb_sign(q̇)`). With a `Viscous` term `Fv`, the slope is `Fv + dFv`
    /// moving forward and `Fv − dFv` moving backward.
    AbsViscous { dof: usize },
    /// Direction-dependent Coulomb friction (N): `φ = |coulomb_sign(q̇)|`. With a
    /// `Coulomb` term `Fc`, the level is `Fc + dFc` forward and `Fc − dFc` backward;
    /// it acts only while moving (unlike an offset).
    AbsCoulomb { dof: usize },
    /// Stribeck friction (N): `φ = coulomb_sign(q̇)·exp(−(q̇/vs)²)`, extra friction
    /// at low speed decaying over the Stribeck speed `vs` (m/s).
    Stribeck { dof: usize, vs: f64 },
    /// Position-periodic force (N): `φ = sin(2π q/period + phase)`, with the
    /// period in m (cogging, ball-screw lead error, position-dependent friction).
    Ripple { dof: usize, period: f64, phase: f64 },
    /// Position-dependent Coulomb friction (N): `φ = coulomb_sign(q̇)·sin(2π q/period + phase)`,
    /// with the period in m. With a `Coulomb` term `Fc`, the friction level varies along the
    /// stroke, `Fc + A sin(2π q/P + φ)`, always against the motion (a preload or lubrication
    /// that changes along a screw, a worn zone of a guide).
    CoulombRipple { dof: usize, period: f64, phase: f64 },
    /// Coulomb friction that varies along the stroke in one direction of motion (N): `φ =
    /// B((q − center)/width)·σ(q̇)`, `B` the uniform cubic B-spline (support `±2 width`, `B(0) =
    /// 2/3`; B-splines `width` apart sum to 1), `σ = s(1 + s)/2` for the forward direction and
    /// `s(1 − s)/2` for the backward one, `s = coulomb_sign(q̇)`: 1 and 0 moving forward, 0 and
    /// −1 moving backward, summing to `s`, smooth through rest. A set of them is a smooth friction
    /// profile along the stroke for each direction, each parameter the friction added near
    /// its knot (a tight or worn zone of a guide, a preload that changes along a screw, seen
    /// differently going forward and backward). `side`: 1 forward, −1 backward, 0 both
    /// directions alike (`σ = s`: one profile against the motion whichever way it goes).
    ///
    /// `lo < hi`: the profile's stroke; beyond it `q` is held at the end it passed (`B` at `lo` or
    /// `hi`, its slope 0), so that a profile fitted on one stretch of the stroke carries its end
    /// values beyond it instead of falling back to the plain Coulomb friction. `lo = hi` (0 and 0,
    /// the default): no limit.
    CoulombSpline {
        dof: usize,
        center: f64,
        width: f64,
        side: i8,
        lo: f64,
        hi: f64,
    },
    /// A force that varies along the stroke whatever the motion (N): `φ = B((q − center)/width)`,
    /// the uniform cubic B-spline of [`Basis::CoulombSpline`]. A set of them `width` apart is a
    /// smooth profile of force along the stroke, each parameter the force near its knot (a
    /// counterbalance cylinder's or a cable's torque, a spring's force, an unmodelled weight).
    /// `lo`, `hi` as for [`Basis::CoulombSpline`].
    Spline {
        dof: usize,
        center: f64,
        width: f64,
        lo: f64,
        hi: f64,
    },
    /// Gravity torque of a rotary joint (N·m, the core's "N" on the load side): `φ =
    /// sin(q + angle_offset + phase)`, q the joint angle (rad); the torque `A sin(q + θ0) + B cos(q + θ0)`
    /// is two terms, phases 0 and π/2, with `angle_offset` θ0 where the joint's zero is.
    Gravity {
        dof: usize,
        angle_offset: f64,
        phase: f64,
    },
    /// Damper in parallel with the spring between dofs `a` and `b` (N/(m/s)):
    /// `φ_a = q̇_a − q̇_b`, `φ_b = q̇_b − q̇_a` (coupling damping of a flexible joint).
    Damper { a: usize, b: usize },
    /// Spring with a dead zone (backlash) of total width `gap` (m) between dofs
    /// `a` and `b` (N/m): `φ_a = dz(q_a − q_b)`, `φ_b = −φ_a`, with
    /// `dz(x) = sign(x)·max(|x| − gap/2, 0)`.
    Backlash { a: usize, b: usize, gap: f64 },
}

impl Basis {
    /// True for the terms that multiply an acceleration (they build the mass matrix).
    pub fn is_inertia(&self) -> bool {
        matches!(self, Basis::Inertia { .. })
    }

    /// True for the non-inertial terms whose basis function is affine in the state
    /// `(q, q̇)` (viscous, offset, spring): the exponential integrator
    /// (`sim::Integrator::Exponential`) propagates them exactly. Every other term —
    /// Coulomb, and any term not listed here — is integrated numerically from
    /// [`Basis::accumulate`], so a new nonlinear term is handled correctly without
    /// changes to the integrator.
    pub fn is_affine(&self) -> bool {
        matches!(
            self,
            Basis::Viscous { .. } | Basis::Offset { .. } | Basis::Spring { .. } | Basis::Damper { .. }
        )
    }

    /// True for a term between two dofs (a spring, damper or backlash).
    pub fn couples(&self) -> bool {
        self.dofs().1.is_some()
    }

    /// The degrees of freedom this basis function touches.
    pub(crate) fn dofs(&self) -> (usize, Option<usize>) {
        match *self {
            Basis::Inertia { dof }
            | Basis::Viscous { dof }
            | Basis::Coulomb { dof }
            | Basis::Offset { dof }
            | Basis::AbsViscous { dof }
            | Basis::AbsCoulomb { dof }
            | Basis::Stribeck { dof, .. }
            | Basis::Ripple { dof, .. }
            | Basis::CoulombRipple { dof, .. }
            | Basis::CoulombSpline { dof, .. }
            | Basis::Spline { dof, .. }
            | Basis::Gravity { dof, .. } => (dof, None),
            Basis::Spring { a, b } | Basis::Damper { a, b } | Basis::Backlash { a, b, .. } => (a, Some(b)),
        }
    }

    /// Checks the hyper-parameters (Stribeck speed, ripple period, gap).
    fn check(&self) -> Result<()> {
        match *self {
            Basis::Stribeck { vs, .. } if !(vs.is_finite() && vs > 0.0) => {
                Err(invalid!("the Stribeck speed vs must be finite and > 0 m/s, got {vs}"))
            }
            Basis::Ripple { period, phase, .. } | Basis::CoulombRipple { period, phase, .. }
                if !(period.is_finite() && period > 0.0 && phase.is_finite()) =>
            {
                Err(invalid!(
                    "a position ripple needs a finite period > 0 m and a finite phase, got {period} and {phase}"
                ))
            }
            Basis::CoulombSpline { center, width, .. } | Basis::Spline { center, width, .. }
                if !(center.is_finite() && width.is_finite() && width > 0.0) =>
            {
                Err(invalid!(
                    "a friction spline needs a finite knot position (hyper, m) and a finite knot spacing width > 0 m, \
                     got {center} and {width}"
                ))
            }
            Basis::CoulombSpline { lo, hi, .. } | Basis::Spline { lo, hi, .. }
                if !(lo.is_finite() && hi.is_finite() && lo <= hi) =>
            {
                Err(invalid!(
                    "a spline's stroke [lo, hi] needs finite ends with lo <= hi (lo = hi: no limit), got {lo} and {hi}"
                ))
            }
            Basis::CoulombSpline { side, .. } if !(-1..=1).contains(&side) => {
                Err(invalid!("a friction spline's side is 1 (forward), -1 (backward) or 0 (both), got {side}"))
            }
            Basis::Gravity { angle_offset, phase, .. } if !(angle_offset.is_finite() && phase.is_finite()) => {
                Err(invalid!("a gravity term needs a finite angle offset and phase (rad), got {angle_offset} and {phase}"))
            }
            Basis::Backlash { gap, .. } if !(gap.is_finite() && gap >= 0.0) => {
                Err(invalid!("the backlash gap must be finite and >= 0 m, got {gap}"))
            }
            _ => Ok(()),
        }
    }

    /// The basis function of an extra model term: its kind (a name of [`TERM_TABLE`] or of
    /// [`TERM_ALIASES`]), its named hyper-parameters (in the units of the table; those with a
    /// default may be left out) and the dof it acts on (a `damper` always couples the motor
    /// and the load). The hyper-parameters' values are checked.
    pub fn from_kind(kind: &str, hypers: &[(&str, f64)], dof: usize) -> Result<Basis> {
        let (tk, values) = canonical_term(kind, hypers)?;
        if tk.name == "coulomb_spline" && values[2].fract() != 0.0 {
            return Err(invalid!(
                "a friction spline's side is 1 (forward), -1 (backward) or 0 (both), got {}",
                values[2]
            ));
        }
        let b = (tk.build)(dof, &values);
        b.check()?;
        Ok(b)
    }

    /// What the parameter multiplying this basis function is, physically.
    pub fn role(&self) -> Role {
        match self {
            Basis::Inertia { .. } => Role::Mass,
            Basis::Spring { .. } | Basis::Backlash { .. } => Role::Stiffness,
            Basis::Damper { .. } => Role::Damping,
            Basis::Viscous { .. }
            | Basis::Coulomb { .. }
            | Basis::AbsViscous { .. }
            | Basis::AbsCoulomb { .. }
            | Basis::Stribeck { .. }
            | Basis::CoulombRipple { .. }
            | Basis::CoulombSpline { .. } => Role::Friction,
            Basis::Offset { .. } | Basis::Ripple { .. } | Basis::Gravity { .. } | Basis::Spline { .. } => {
                Role::Force
            }
        }
    }

    /// The SI unit of the parameter that multiplies this basis function (load side).
    pub fn unit(&self) -> &'static str {
        match self {
            Basis::Inertia { .. } => "kg",
            Basis::Viscous { .. } | Basis::AbsViscous { .. } | Basis::Damper { .. } => "N/(m/s)",
            Basis::Spring { .. } | Basis::Backlash { .. } => "N/m",
            Basis::Offset { .. }
            | Basis::Coulomb { .. }
            | Basis::AbsCoulomb { .. }
            | Basis::Stribeck { .. }
            | Basis::Spline { .. }
            | Basis::Ripple { .. }
            | Basis::CoulombRipple { .. }
            | Basis::CoulombSpline { .. }
            | Basis::Gravity { .. } => "N",
        }
    }

    /// The dofs the term acts on, as the vector `d` of its force `value · φ · d`:
    /// `e_dof` for a one-dof term, `e_a − e_b` for a coupling. The basis function reads
    /// the state through `x = dᵀq` and `ẋ = dᵀq̇` only.
    #[inline(always)]
    pub(crate) fn direction<const N: usize>(&self) -> SVector<f64, N> {
        let mut d = SVector::<f64, N>::zeros();
        match self.dofs() {
            (a, None) => d[a] = 1.0,
            (a, Some(b)) => {
                d[a] = 1.0;
                d[b] = -1.0;
            }
        }
        d
    }

    /// The scalar basis function `φ(x, ẋ)` of a non-inertial term and its derivatives
    /// `(φ, ∂φ/∂x, ∂φ/∂ẋ)`, with `x = dᵀq`, `ẋ = dᵀq̇` (see [`Basis::direction`]). The
    /// physics of every term is here and nowhere else: the direct model, the regressor,
    /// both integrators and the sensitivities all read it.
    #[inline(always)]
    pub(crate) fn local<L: Law>(&self, x: f64, xd: f64, law: L) -> (f64, f64, f64) {
        match *self {
            Basis::Inertia { .. } => (0.0, 0.0, 0.0),
            Basis::Viscous { .. } | Basis::Damper { .. } => (xd, 0.0, 1.0),
            Basis::Offset { .. } => (1.0, 0.0, 0.0),
            Basis::Spring { .. } => (x, 1.0, 0.0),
            Basis::Coulomb { .. } => {
                let (s, ds) = law.sign_and_derivative(xd);
                (s, 0.0, ds)
            }
            Basis::AbsViscous { .. } => {
                let (s, ds) = law.sign_and_derivative(xd);
                (xd * s, 0.0, s + xd * ds)
            }
            Basis::AbsCoulomb { .. } => {
                let (s, ds) = law.sign_and_derivative(xd);
                (s.abs(), 0.0, s.signum() * ds)
            }
            Basis::Stribeck { vs, .. } => {
                let (s, ds) = law.sign_and_derivative(xd);
                let e = (-(xd / vs) * (xd / vs)).exp();
                (s * e, 0.0, ds * e - s * e * 2.0 * xd / (vs * vs))
            }
            Basis::Ripple { period, phase, .. } => {
                let w = std::f64::consts::TAU / period;
                let (sn, cs) = crate::trig::sin_cos(w * x + phase);
                (sn, w * cs, 0.0)
            }
            Basis::CoulombRipple { period, phase, .. } => {
                let w = std::f64::consts::TAU / period;
                let (sn, cs) = crate::trig::sin_cos(w * x + phase);
                let (s, ds) = law.sign_and_derivative(xd);
                (s * sn, s * w * cs, ds * sn)
            }
            Basis::Gravity {
                angle_offset, phase, ..
            } => {
                let (sn, cs) = crate::trig::sin_cos(x + angle_offset + phase);
                (sn, cs, 0.0)
            }
            Basis::Spline {
                center,
                width,
                lo,
                hi,
                ..
            } => {
                let (b, db) = held_bspline(x, center, width, lo, hi);
                (b, db, 0.0)
            }
            Basis::CoulombSpline {
                center,
                width,
                side,
                lo,
                hi,
                ..
            } => {
                let (b, db) = held_bspline(x, center, width, lo, hi);
                if b == 0.0 && db == 0.0 {
                    // outside the knot's support (most of the stroke for each of a profile's splines): no
                    // friction law to evaluate, the products below would all be zero
                    return (0.0, 0.0, 0.0);
                }
                let (s, ds) = law.sign_and_derivative(xd);
                // the forward or backward part of the sign, s(1 ± s)/2: 1 or 0 (−1 or 0) away from rest, the two
                // summing to s, and as smooth as s (max(s, 0) would kink the dynamics at every reversal); both: s
                let (sigma, dsigma) = if side == 0 {
                    (s, ds)
                } else {
                    let side = f64::from(side);
                    (0.5 * s * (1.0 + side * s), 0.5 * ds * (1.0 + 2.0 * side * s))
                };
                (b * sigma, db * sigma, b * dsigma)
            }
            Basis::Backlash { gap, .. } => {
                // slope 1 outside the gap, 0 inside
                (
                    dead_zone(x, gap),
                    if x.abs() > 0.5 * gap { 1.0 } else { 0.0 },
                    0.0,
                )
            }
        }
    }

    /// `∂φ/∂eps`: the derivative of [`Basis::local`]'s `φ(x, ẋ)` with respect to the friction law's
    /// smoothing speed, through the smoothed sign `s` each Coulomb-type term is made of
    /// (`∂φ/∂s · ∂s/∂eps`, [`FrictionLaw::eps_derivative`]); 0 for a term without it. The closed
    /// loop's sensitivities read it beside [`Basis::local`], case for case.
    pub(crate) fn local_eps(&self, x: f64, xd: f64, law: FrictionLaw) -> f64 {
        let ds_deps = || law.eps_derivative(xd);
        match *self {
            Basis::Coulomb { .. } => ds_deps(),
            Basis::AbsViscous { .. } => xd * ds_deps(),
            Basis::AbsCoulomb { .. } => law.sign(xd).signum() * ds_deps(),
            Basis::Stribeck { vs, .. } => (-(xd / vs) * (xd / vs)).exp() * ds_deps(),
            Basis::CoulombRipple { period, phase, .. } => {
                crate::trig::sin(std::f64::consts::TAU / period * x + phase) * ds_deps()
            }
            Basis::CoulombSpline {
                center,
                width,
                side,
                lo,
                hi,
                ..
            } => {
                let (b, _) = held_bspline(x, center, width, lo, hi);
                if b == 0.0 {
                    return 0.0;
                }
                if side == 0 {
                    b * ds_deps()
                } else {
                    b * 0.5 * ds_deps() * (1.0 + 2.0 * f64::from(side) * law.sign(xd))
                }
            }
            Basis::Inertia { .. }
            | Basis::Viscous { .. }
            | Basis::Damper { .. }
            | Basis::Offset { .. }
            | Basis::Spring { .. }
            | Basis::Ripple { .. }
            | Basis::Gravity { .. }
            | Basis::Spline { .. }
            | Basis::Backlash { .. } => 0.0,
        }
    }

    /// `(x, ẋ) = (dᵀq, dᵀq̇)`, the arguments of [`Basis::local`].
    #[inline(always)]
    pub(crate) fn coordinates<const N: usize>(
        &self,
        q: &SVector<f64, N>,
        qd: &SVector<f64, N>,
    ) -> (f64, f64) {
        match self.dofs() {
            (a, None) => (q[a], qd[a]),
            (a, Some(b)) => (q[a] - q[b], qd[a] - qd[b]),
        }
    }

    /// Adds `value · φ(q, q̇, q̈)` to `out`, one entry per dof.
    #[inline(always)]
    pub(crate) fn accumulate<const N: usize, L: Law>(
        &self,
        value: f64,
        q: &SVector<f64, N>,
        qd: &SVector<f64, N>,
        qdd: &SVector<f64, N>,
        law: L,
        out: &mut SVector<f64, N>,
    ) {
        let phi = match *self {
            Basis::Inertia { dof } => qdd[dof],
            _ => {
                let (x, xd) = self.coordinates(q, qd);
                self.local(x, xd, law).0
            }
        };
        match self.dofs() {
            (a, None) => out[a] += value * phi,
            (a, Some(b)) => {
                let f = value * phi;
                out[a] += f;
                out[b] -= f;
            }
        }
    }
}

/// `sign(x)·max(|x| − gap/2, 0)`: the elongation of a coupling with backlash.
#[inline]
pub fn dead_zone(x: f64, gap: f64) -> f64 {
    let h = 0.5 * gap;
    if x > h {
        x - h
    } else if x < -h {
        x + h
    } else {
        0.0
    }
}

impl Basis {
    /// Adds `value · ∂φ/∂q` to `dq` and `value · ∂φ/∂q̇` to `dv` (`[row dof, column dof]`),
    /// for the non-inertial terms; used by the sensitivity equations.
    #[inline(always)]
    pub(crate) fn accumulate_partials<const N: usize>(
        &self,
        value: f64,
        q: &SVector<f64, N>,
        qd: &SVector<f64, N>,
        law: FrictionLaw,
        dq: &mut SMatrix<f64, N, N>,
        dv: &mut SMatrix<f64, N, N>,
    ) {
        if self.is_inertia() {
            return;
        }
        let (x, xd) = self.coordinates(q, qd);
        let (_, px, pv) = self.local(x, xd, law);
        let d = self.direction::<N>();
        let dd = d * d.transpose();
        *dq += dd * (value * px);
        *dv += dd * (value * pv);
    }
}

/// A model: named parameters, each with its basis function, on `N` degrees of freedom.
///
/// The structure is separate from the parameter values `χ` (a slice in the
/// order of [`Model::names`]), so one model serves every iteration of an
/// identification and every member of a batch.
#[derive(Clone, Debug, PartialEq)]
pub struct Model<const N: usize> {
    names: Vec<String>,
    basis: Vec<Basis>,
    law: FrictionLaw,
}

impl<const N: usize> Model<N> {
    /// Builds a model from `(name, basis)` terms.
    ///
    /// Errors when a term refers to a dof `>= N`, a name repeats, a dof has no
    /// inertia term (its acceleration would be undefined), or `coulomb_eps` is
    /// negative or not finite.
    pub fn new(terms: Vec<(String, Basis)>, coulomb_eps: f64) -> Result<Self> {
        if !(coulomb_eps.is_finite() && coulomb_eps >= 0.0) {
            return Err(invalid!(
                "coulomb_eps must be a finite velocity >= 0 m/s (0 = hard sign), got {coulomb_eps}"
            ));
        }
        let mut names: Vec<String> = Vec::with_capacity(terms.len());
        let mut basis = Vec::with_capacity(terms.len());
        for (name, b) in terms {
            let (d0, d1) = b.dofs();
            if d0 >= N || d1.is_some_and(|d| d >= N) {
                return Err(invalid!(
                    "term {name} refers to a degree of freedom outside this {N}-dof model"
                ));
            }
            b.check().map_err(|e| invalid!("term {name}: {e}"))?;
            if matches!(b, Basis::Spring { a, b } | Basis::Damper { a, b } | Basis::Backlash { a, b, .. } if a == b)
            {
                return Err(invalid!(
                    "term {name}: a spring or damper needs two different dofs"
                ));
            }
            if names.contains(&name) {
                return Err(invalid!("parameter name {name} appears twice in the model"));
            }
            names.push(name);
            basis.push(b);
        }
        for dof in 0..N {
            if !basis.contains(&Basis::Inertia { dof }) {
                return Err(invalid!(
                    "degree of freedom {dof} has no inertia term: add a mass parameter for it"
                ));
            }
        }
        Ok(Self {
            names,
            basis,
            law: FrictionLaw::algebraic(coulomb_eps),
        })
    }

    /// Parameter names, in the order of `χ`.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The SI unit of each parameter, in the order of `χ`.
    pub fn units(&self) -> Vec<&'static str> {
        self.basis.iter().map(Basis::unit).collect()
    }

    /// Basis functions, in the order of `χ`.
    pub fn basis(&self) -> &[Basis] {
        &self.basis
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        self.basis.len()
    }

    /// Velocity scale of the Coulomb sign (m/s), see [`coulomb_sign`].
    pub fn coulomb_eps(&self) -> f64 {
        self.law.eps
    }

    /// The friction law through zero speed of every Coulomb-type term.
    pub fn law(&self) -> FrictionLaw {
        self.law
    }

    /// Returns a copy whose Coulomb-type terms follow `shape` (same transition speed).
    pub fn with_law_shape(&self, shape: LawShape) -> Self {
        let mut m = self.clone();
        m.law.shape = shape;
        m
    }

    /// Returns a copy with `extra` terms appended (e.g. a candidate effect of the doctor).
    pub fn with_terms(&self, extra: Vec<(String, Basis)>) -> Result<Self> {
        let mut terms: Vec<(String, Basis)> = self
            .names
            .iter()
            .cloned()
            .zip(self.basis.iter().copied())
            .collect();
        terms.extend(extra);
        Ok(Self::new(terms, self.law.eps)?.with_law_shape(self.law.shape))
    }

    /// Returns a copy where the parameter `name` gets another basis function
    /// (e.g. the spring K12 replaced by a spring with backlash).
    pub fn with_basis(&self, name: &str, basis: Basis) -> Result<Self> {
        let Some(i) = self.names.iter().position(|n| n == name) else {
            return Err(invalid!(
                "the model has no parameter {name} ({})",
                self.names.join(", ")
            ));
        };
        let mut terms: Vec<(String, Basis)> = self
            .names
            .iter()
            .cloned()
            .zip(self.basis.iter().copied())
            .collect();
        terms[i].1 = basis;
        Ok(Self::new(terms, self.law.eps)?.with_law_shape(self.law.shape))
    }

    /// Returns a copy with another Coulomb velocity scale.
    pub fn with_coulomb_eps(&self, coulomb_eps: f64) -> Result<Self> {
        let terms = self
            .names
            .iter()
            .cloned()
            .zip(self.basis.iter().copied())
            .collect();
        Ok(Self::new(terms, coulomb_eps)?.with_law_shape(self.law.shape))
    }

    /// Checks a parameter vector for simulation: right length, finite values,
    /// positive masses (each dof's total inertia) and positive stiffness.
    pub fn check_params(&self, chi: &[f64]) -> Result<()> {
        if chi.len() != self.n_params() {
            return Err(invalid!(
                "expected {} parameters ({}), got {}",
                self.n_params(),
                self.names.join(", "),
                chi.len()
            ));
        }
        for (name, &v) in self.names.iter().zip(chi) {
            if !v.is_finite() {
                return Err(invalid!("parameter {name} is not finite ({v})"));
            }
        }
        for ((name, b), &v) in self.names.iter().zip(&self.basis).zip(chi) {
            match b {
                Basis::Inertia { .. } if v <= 0.0 => {
                    return Err(invalid!("mass {name} must be > 0 kg, got {v}"))
                }
                Basis::Spring { .. } | Basis::Backlash { .. } if v <= 0.0 => {
                    return Err(invalid!("stiffness {name} must be > 0 N/m, got {v}"))
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Diagonal of the mass matrix for `χ` (sum of the inertia terms of each dof).
    pub fn masses(&self, chi: &[f64]) -> SVector<f64, N> {
        let mut m = SVector::<f64, N>::zeros();
        for (b, &v) in self.basis.iter().zip(chi) {
            if let Basis::Inertia { dof } = *b {
                m[dof] += v;
            }
        }
        m
    }

    /// Inverse dynamic model, eq. (3): the generalized forces `τ_idm(q, q̇, q̈)` of every dof.
    pub fn idm(
        &self,
        chi: &[f64],
        q: &SVector<f64, N>,
        qd: &SVector<f64, N>,
        qdd: &SVector<f64, N>,
    ) -> SVector<f64, N> {
        let mut out = SVector::<f64, N>::zeros();
        for (b, &v) in self.basis.iter().zip(chi) {
            b.accumulate(v, q, qd, qdd, self.law, &mut out);
        }
        out
    }

    /// Direct dynamic model, eqs. (5) and (9): accelerations for the generalized
    /// input `u` (the motor force on dof 0, zero on the others), with
    /// `inv_mass` the inverse of [`Model::masses`].
    #[inline]
    pub fn accel(
        &self,
        chi: &[f64],
        inv_mass: &SVector<f64, N>,
        q: &SVector<f64, N>,
        qd: &SVector<f64, N>,
        u: &SVector<f64, N>,
    ) -> SVector<f64, N> {
        let zero = SVector::<f64, N>::zeros();
        let mut f = SVector::<f64, N>::zeros();
        for (b, &v) in self.basis.iter().zip(chi) {
            if !b.is_inertia() {
                b.accumulate(v, q, qd, &zero, self.law, &mut f);
            }
        }
        (u - f).component_mul(inv_mass)
    }

    /// Jacobians of the accelerations of the direct model with respect to the
    /// positions and the velocities, `(∂q̈/∂q, ∂q̈/∂q̇)`, at `(q, q̇)`.
    #[inline]
    pub fn accel_partials(
        &self,
        chi: &[f64],
        inv_mass: &SVector<f64, N>,
        q: &SVector<f64, N>,
        qd: &SVector<f64, N>,
    ) -> (SMatrix<f64, N, N>, SMatrix<f64, N, N>) {
        let mut dq = SMatrix::<f64, N, N>::zeros();
        let mut dv = SMatrix::<f64, N, N>::zeros();
        for (b, &v) in self.basis.iter().zip(chi) {
            b.accumulate_partials(v, q, qd, self.law, &mut dq, &mut dv);
        }
        for d in 0..N {
            for e in 0..N {
                dq[(d, e)] *= -inv_mass[d];
                dv[(d, e)] *= -inv_mass[d];
            }
        }
        (dq, dv)
    }

    /// The regressor row block of one sample: `out[d * p + j] = φ_j` of dof `d`
    /// (`p` = number of parameters), so that `idm = Σ_j χ_j φ_j` (eqs. (4), (7)).
    pub fn regressor_into(
        &self,
        q: &SVector<f64, N>,
        qd: &SVector<f64, N>,
        qdd: &SVector<f64, N>,
        out: &mut [f64],
    ) {
        let p = self.n_params();
        out.iter_mut().for_each(|x| *x = 0.0);
        for (j, b) in self.basis.iter().enumerate() {
            let mut col = SVector::<f64, N>::zeros();
            b.accumulate(1.0, q, qd, qdd, self.law, &mut col);
            for d in 0..N {
                out[d * p + j] = col[d];
            }
        }
    }

    /// The regressor's columns `cols` (indices among the parameters) on the rows of dof `dof` over a
    /// whole trajectory, as [`Model::regressor`] gives them there (its other values not computed):
    /// layout `[column][sample]`.
    pub fn regressor_columns<R: AsRef<[f64]> + Sync>(
        &self,
        q: &[R],
        qd: &[R],
        qdd: &[R],
        cols: &[usize],
        dof: usize,
    ) -> Result<Vec<f64>> {
        let (n, columns) = self.columns(q, qd, qdd, cols, dof)?;
        let mut w = vec![0.0; cols.len() * n];
        if n > 0 {
            for (&j, col) in cols.iter().zip(w.chunks_mut(n)) {
                columns.fill(j, dof, col);
            }
        }
        Ok(w)
    }

    /// [`Model::regressor_columns`] decimated by `dec`, one column a vector of `dec.output_len(n)`
    /// values: bit for bit [`Decimation::apply_columns`] of the full-rate columns, which never
    /// exist all at once ([`Decimation::apply_filled`]: a group of four at a time). The doctor's
    /// grids are 160 columns of the record (32 MB at 1 kHz over 25 s); only their decimated form
    /// is tested.
    ///
    /// [`Decimation::apply_columns`]: crate::filter::Decimation::apply_columns
    /// [`Decimation::apply_filled`]: crate::filter::Decimation::apply_filled
    pub fn decimated_columns<R: AsRef<[f64]> + Sync>(
        &self,
        q: &[R],
        qd: &[R],
        qdd: &[R],
        cols: &[usize],
        dof: usize,
        dec: &crate::filter::Decimation,
    ) -> Result<Vec<Vec<f64>>> {
        let (n, columns) = self.columns(q, qd, qdd, cols, dof)?;
        dec.apply_filled(
            cols.len(),
            n,
            |i, col| columns.fill(cols[i], dof, col),
            |i| format!("regressor column {}", cols[i]),
        )
    }

    /// Checks the series, the dof and the columns `cols` (parameters) that will be filled, and
    /// gives the series' length and their [`Columns`].
    fn columns<'a, R: AsRef<[f64]>>(
        &'a self,
        q: &'a [R],
        qd: &'a [R],
        qdd: &'a [R],
        cols: &[usize],
        dof: usize,
    ) -> Result<(usize, Columns<'a, N, R>)> {
        let n = check_series::<N, R>(q, qd, qdd)?;
        let p = self.n_params();
        if dof >= N {
            return Err(invalid!("dof {dof} of a model of {N} dof(s)"));
        }
        if let Some(&j) = cols.iter().find(|&&j| j >= p) {
            return Err(invalid!("column {j} of a model of {p} parameters"));
        }
        // the friction law's sign of a dof's speed, shared by its position-periodic Coulomb columns
        // (a grid of periods on one joint: computed once, not once a column)
        let law = self.law;
        let signs = (0..N)
            .map(|d| {
                let periodic = cols.iter().any(|&j| {
                    matches!(self.basis[j], Basis::CoulombRipple { .. }) && self.basis[j].dofs() == (d, None)
                });
                periodic.then(|| {
                    qd[d]
                        .as_ref()
                        .iter()
                        .map(|&v| law.sign_and_derivative(v).0)
                        .collect()
                })
            })
            .collect();
        Ok((
            n,
            Columns {
                model: self,
                q,
                qd,
                qdd,
                signs,
            },
        ))
    }

    /// The regressor of a whole trajectory, from per-dof sample series
    /// (`q[d][k]`, likewise `qd`, `qdd`).
    ///
    /// Layout: `[dof][parameter][sample]`, i.e. for each dof a column-major
    /// `(n × p)` block whose columns are the `φ_j` over time, ready for
    /// parallel decimation column by column.
    pub fn regressor<R: AsRef<[f64]>>(&self, q: &[R], qd: &[R], qdd: &[R]) -> Result<Vec<f64>> {
        let p = self.n_params();
        let (n, columns) = self.columns(q, qd, qdd, &(0..p).collect::<Vec<_>>(), 0)?;
        let mut w = vec![0.0; N * p * n];
        if n == 0 {
            return Ok(w);
        }
        // column by column, each basis function over the whole series (a sample's row, as
        // `regressor_into` builds it, visited every column's block n apart): the same values,
        // 0 + φ on the term's dof and 0 − φ on its second dof, 0 on the other dofs' rows (as
        // allocated)
        for (j, b) in self.basis.iter().enumerate() {
            let (a, other) = b.dofs();
            for d in std::iter::once(a).chain(other) {
                columns.fill(j, d, &mut w[(d * p + j) * n..(d * p + j + 1) * n]);
            }
        }
        Ok(w)
    }
}

/// A model's regressor columns over one trajectory (per-dof series `q`, `qd`, `qdd`, checked by
/// [`Model::regressor_columns`] and its kin), column by column: [`Columns::fill`] writes one, each
/// loop compiled for the processor (AVX2 and FMA where it has both, as [`crate::sim::driver::simd`]
/// does, the same IEEE operations in either build) and for the model's friction-law shape
/// ([`FrictionLaw::dispatch`]: no branch on it per sample).
struct Columns<'a, const N: usize, R> {
    model: &'a Model<N>,
    q: &'a [R],
    qd: &'a [R],
    qdd: &'a [R],
    /// The law's sign of each dof's speed where a position-periodic Coulomb column needs it.
    signs: Vec<Option<Vec<f64>>>,
}

impl<'a, const N: usize, R: AsRef<[f64]>> Columns<'a, N, R> {
    /// Writes the column of parameter `j` on the rows of dof `dof` into `col` (0 where the
    /// parameter does not act on that dof).
    fn fill(&self, j: usize, dof: usize, col: &mut [f64]) {
        struct Fill<'b, 'a, const N: usize, R> {
            columns: &'b Columns<'a, N, R>,
            j: usize,
            dof: usize,
            col: &'b mut [f64],
        }
        impl<const N: usize, R: AsRef<[f64]>> WithLaw for Fill<'_, '_, N, R> {
            type Out = ();
            #[inline(always)]
            fn call<L: Law>(self, law: L) {
                self.columns.fill_with(law, self.j, self.dof, self.col)
            }
        }
        /// # Safety
        /// The processor must support AVX2 and FMA.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn wide<F: WithLaw<Out = ()>>(law: FrictionLaw, f: F) {
            law.dispatch(f)
        }
        let f = Fill {
            columns: self,
            j,
            dof,
            col,
        };
        let law = self.model.law;
        #[cfg(target_arch = "x86_64")]
        {
            let _flush = crate::filter::FlushSubnormals::on();
            if crate::cpu::wide_simd() {
                // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
                return unsafe { wide(law, f) };
            }
            law.dispatch(f)
        }
        #[cfg(not(target_arch = "x86_64"))]
        law.dispatch(f)
    }

    /// [`Columns::fill`] under the law `law` (the model's, its shape static).
    #[inline(always)]
    fn fill_with<L: Law>(&self, law: L, j: usize, dof: usize, col: &mut [f64]) {
        let (q, qd, qdd) = (self.q, self.qd, self.qdd);
        let b = self.model.basis[j];
        let (a, other) = b.dofs();
        let sign = if a == dof {
            1.0
        } else if other == Some(dof) {
            -1.0
        } else {
            col.iter_mut().for_each(|c| *c = 0.0);
            return; // zero on this dof's rows
        };
        match (b, other) {
            (Basis::Inertia { dof }, _) => col.copy_from_slice(qdd[dof].as_ref()),
            // the periodic columns by the vector sine, each sample the bits of `local`'s
            (Basis::Ripple { period, phase, .. }, None) => {
                crate::trig::sin_into(col, q[a].as_ref(), std::f64::consts::TAU / period, phase)
            }
            (Basis::CoulombRipple { period, phase, .. }, None) => {
                crate::trig::sin_into(col, q[a].as_ref(), std::f64::consts::TAU / period, phase);
                let s = self.signs[a]
                    .as_ref()
                    .expect("the signs of every dof with a periodic Coulomb column");
                col.iter_mut().zip(s).for_each(|(c, &s)| *c *= s);
            }
            (_, None) => {
                let (x, v) = (q[a].as_ref(), qd[a].as_ref());
                for ((c, &x), &v) in col.iter_mut().zip(x).zip(v) {
                    *c = b.local(x, v, law).0;
                }
            }
            (_, Some(o)) => {
                let (xa, va, xo, vo) = (q[a].as_ref(), qd[a].as_ref(), q[o].as_ref(), qd[o].as_ref());
                for (k, c) in col.iter_mut().enumerate() {
                    *c = b.local(xa[k] - xo[k], va[k] - vo[k], law).0;
                }
            }
        }
        if sign < 0.0 {
            col.iter_mut().for_each(|c| *c = 0.0 - *c);
        } else {
            col.iter_mut().for_each(|c| *c += 0.0);
        }
    }
}

fn check_series<const N: usize, R: AsRef<[f64]>>(q: &[R], qd: &[R], qdd: &[R]) -> Result<usize> {
    if q.len() != N || qd.len() != N || qdd.len() != N {
        return Err(invalid!(
            "expected position, velocity and acceleration series for {N} dof(s), got {}, {} and {}",
            q.len(),
            qd.len(),
            qdd.len()
        ));
    }
    let n = q[0].as_ref().len();
    for (what, s) in [("position", q), ("velocity", qd), ("acceleration", qdd)] {
        for (d, x) in s.iter().enumerate() {
            let x = x.as_ref();
            if x.len() != n {
                return Err(invalid!(
                    "{what} series of dof {d} has {} samples, expected {n}",
                    x.len()
                ));
            }
            if let Some(k) = x.iter().position(|v| !v.is_finite()) {
                return Err(invalid!("{what} series of dof {d} is not finite at sample {k}"));
            }
        }
    }
    Ok(n)
}

/// The rigid model, eqs. (6)-(7): parameters `M` (kg), `Fv` (N/(m/s)), `Fc` (N)
/// and, with `offset`, a constant force `OF` (N).
pub fn rigid(offset: bool, coulomb_eps: f64) -> Result<Model<1>> {
    let mut terms = vec![
        ("M".to_string(), Basis::Inertia { dof: MOTOR }),
        ("Fv".to_string(), Basis::Viscous { dof: MOTOR }),
        ("Fc".to_string(), Basis::Coulomb { dof: MOTOR }),
    ];
    if offset {
        terms.push(("OF".to_string(), Basis::Offset { dof: MOTOR }));
    }
    Model::new(terms, coulomb_eps)
}

/// The flexible two-mass model, eqs. (2)-(4): `M1, Fv1, Fc1` on the motor side,
/// `M2, Fv2, Fc2` on the load side, `K12` the coupling stiffness.
pub fn flexible(coulomb_eps: f64) -> Result<Model<2>> {
    flexible_with(false, coulomb_eps)
}

/// The flexible model with, when `offset`, a constant motor-side force `OF` (N).
pub fn flexible_with(offset: bool, coulomb_eps: f64) -> Result<Model<2>> {
    let mut terms = vec![
        ("M1".to_string(), Basis::Inertia { dof: MOTOR }),
        ("Fv1".to_string(), Basis::Viscous { dof: MOTOR }),
        ("Fc1".to_string(), Basis::Coulomb { dof: MOTOR }),
        ("M2".to_string(), Basis::Inertia { dof: LOAD }),
        ("Fv2".to_string(), Basis::Viscous { dof: LOAD }),
        ("Fc2".to_string(), Basis::Coulomb { dof: LOAD }),
        ("K12".to_string(), Basis::Spring { a: MOTOR, b: LOAD }),
    ];
    if offset {
        terms.push(("OF".to_string(), Basis::Offset { dof: MOTOR }));
    }
    Model::new(terms, coulomb_eps)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// The tanh law through one exponential: within 4 ulp of 1 of the C library's tanh (its values
    /// are at most 1), odd, ±1 at infinite speeds.
    #[test]
    fn tanh_law_agrees_with_the_c_library() {
        let law = FrictionLaw {
            shape: LawShape::Tanh,
            eps: 0.01,
        };
        for k in -40_000..=40_000 {
            let v = k as f64 * 1e-5 + 3e-9;
            let (t, d) = law.sign_and_derivative(v);
            let t0 = (v / 0.01).tanh();
            assert!(
                (t - t0).abs() <= 4.0 * f64::EPSILON,
                "tanh({v}/0.01): {t} against {t0}"
            );
            assert!((d - (1.0 - t0 * t0) / 0.01).abs() <= 1e-13 * (1.0 / 0.01));
            assert_eq!(law.sign(-v), -t);
        }
        assert_eq!(law.sign(f64::INFINITY), 1.0);
        assert_eq!(law.sign(f64::NEG_INFINITY), -1.0);
        assert!(law.sign(f64::NAN).is_nan());
    }

    /// A model's chosen columns on one dof are the whole regressor's there, value for value: every
    /// basis of the flexible model with a Stribeck term on each dof and a backlash spring.
    #[test]
    fn regressor_columns_are_the_regressors() {
        let m = flexible_with(true, 1e-3)
            .unwrap()
            .with_terms(vec![
                ("S1".into(), Basis::Stribeck { dof: 0, vs: 0.02 }),
                ("S2".into(), Basis::Stribeck { dof: 1, vs: 0.05 }),
                (
                    "R1".into(),
                    Basis::Ripple {
                        dof: 0,
                        period: 2.5e-3,
                        phase: 0.0,
                    },
                ),
                (
                    "R2".into(),
                    Basis::Ripple {
                        dof: 0,
                        period: 7e-3,
                        phase: std::f64::consts::FRAC_PI_2,
                    },
                ),
                (
                    "C1".into(),
                    Basis::CoulombRipple {
                        dof: 0,
                        period: 3e-3,
                        phase: 0.0,
                    },
                ),
                (
                    "C2".into(),
                    Basis::CoulombRipple {
                        dof: 1,
                        period: 5e-3,
                        phase: 0.3,
                    },
                ),
                (
                    "C3".into(),
                    Basis::CoulombRipple {
                        dof: 0,
                        period: 9e-3,
                        phase: std::f64::consts::FRAC_PI_2,
                    },
                ),
            ])
            .unwrap()
            .with_basis(
                "K12",
                Basis::Backlash {
                    a: 0,
                    b: 1,
                    gap: 1e-3,
                },
            )
            .unwrap();
        let n = 500;
        let series = |f: &dyn Fn(f64) -> f64| -> Vec<Vec<f64>> {
            (0..2)
                .map(|d| (0..n).map(|k| f(k as f64 * 0.01 + d as f64)).collect())
                .collect()
        };
        let (q, qd, qdd) = (
            series(&|t| 0.01 * t.sin()),
            series(&|t| 0.03 * (1.7 * t).cos()),
            series(&|t| (0.3 * t).sin()),
        );
        let p = m.n_params();
        let w = m.regressor(&q, &qd, &qdd).unwrap();
        for dof in 0..2 {
            let cols: Vec<usize> = (0..p).rev().collect();
            let c = m.regressor_columns(&q, &qd, &qdd, &cols, dof).unwrap();
            for (i, &j) in cols.iter().enumerate() {
                for k in 0..n {
                    assert_eq!(
                        c[i * n + k].to_bits(),
                        w[(dof * p + j) * n + k].to_bits(),
                        "dof {dof}, column {j}, sample {k}"
                    );
                }
            }
        }
        assert!(m.regressor_columns(&q, &qd, &qdd, &[p], 0).is_err());
        assert!(m.regressor_columns(&q, &qd, &qdd, &[0], 2).is_err());

        // decimated without the full-rate columns: bit for bit the decimation of the full-rate ones
        let dec =
            crate::filter::Decimation::butterworth(4, 5.0, 100.0, 4, crate::filter::FilterForm::Sos).unwrap();
        for dof in 0..2 {
            let cols: Vec<usize> = (0..p).collect();
            let full = m.regressor_columns(&q, &qd, &qdd, &cols, dof).unwrap();
            let want = dec
                .apply_columns(&full.chunks(n).collect::<Vec<_>>(), |j| format!("{j}"))
                .unwrap();
            let got = m.decimated_columns(&q, &qd, &qdd, &cols, dof, &dec).unwrap();
            assert_eq!(got.len(), p);
            for (j, (g, w)) in got.iter().zip(&want).enumerate() {
                assert_eq!(g.len(), dec.output_len(n));
                assert!(
                    g.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "dof {dof}, column {j}"
                );
            }
        }
        let short: Vec<Vec<f64>> = q.iter().map(|c| c[..5].to_vec()).collect();
        let err = m
            .decimated_columns(&short, &short, &short, &[0, 1], 0, &dec)
            .unwrap_err()
            .to_string();
        assert!(err.contains("regressor column 0"), "{err}");
    }

    /// Values for every hyper-parameter of a kind: its default, or a value valid for its unit.
    fn sample_hypers(tk: &TermKind) -> Vec<(&'static str, f64)> {
        tk.hypers
            .iter()
            .map(|h| {
                (
                    h.name,
                    h.default.unwrap_or(if h.name == "width" { 0.02 } else { 0.01 }),
                )
            })
            .collect()
    }

    #[test]
    fn every_term_kind_builds_its_basis_and_knows_its_unit_and_role() {
        for tk in TERM_TABLE {
            let b = Basis::from_kind(tk.name, &sample_hypers(tk), LOAD).unwrap();
            let unit = b.unit();
            assert!(["N", "N/(m/s)"].contains(&unit), "{}: {unit}", tk.name);
            assert_ne!(b.role(), Role::Mass, "{}", tk.name);
            // a load term acts on the load row only; the damper couples both
            let (a, other) = b.dofs();
            if tk.name == "damper" {
                assert_eq!((a, other), (MOTOR, Some(LOAD)));
            } else {
                assert_eq!((a, other), (LOAD, None), "{}", tk.name);
            }
            // its partial derivatives are those of its basis function (central differences)
            let law = FrictionLaw::algebraic(1e-3);
            for (x, v) in [(0.3, 0.02), (-1.2, -0.004), (2.5, 0.3)] {
                let (_, px, pv) = b.local(x, v, law);
                let (hx, hv) = (1e-6, 1e-7);
                let fx = (b.local(x + hx, v, law).0 - b.local(x - hx, v, law).0) / (2.0 * hx);
                let fv = (b.local(x, v + hv, law).0 - b.local(x, v - hv, law).0) / (2.0 * hv);
                assert!(
                    (fx - px).abs() < 1e-5 * (1.0 + px.abs()),
                    "{}: {fx} vs {px}",
                    tk.name
                );
                assert!(
                    (fv - pv).abs() < 1e-4 * (1.0 + pv.abs()),
                    "{}: {fv} vs {pv}",
                    tk.name
                );
            }
        }
        let e = Basis::from_kind("stribek", &[("vs", 0.01)], MOTOR).unwrap_err();
        assert!(e.to_string().contains("unknown term kind \"stribek\""), "{e}");
        assert_eq!(Basis::Inertia { dof: 0 }.unit(), "kg");
        assert_eq!(Basis::Inertia { dof: 0 }.role(), Role::Mass);
        assert_eq!(Basis::Spring { a: 0, b: 1 }.unit(), "N/m");
        assert_eq!(Basis::Spring { a: 0, b: 1 }.role(), Role::Stiffness);
    }

    #[test]
    fn hyper_parameters_are_named_and_every_mistake_in_them_is_named() {
        // a Stribeck speed by name; a ripple's phase defaults to 0
        assert_eq!(
            Basis::from_kind("stribeck", &[("vs", 0.02)], MOTOR).unwrap(),
            Basis::Stribeck { dof: MOTOR, vs: 0.02 }
        );
        assert_eq!(
            Basis::from_kind("ripple", &[("period", 0.1)], MOTOR).unwrap(),
            Basis::Ripple {
                dof: MOTOR,
                period: 0.1,
                phase: 0.0
            }
        );
        // the older names are their kind with the phase or the side fixed
        assert_eq!(
            Basis::from_kind("ripple_cos", &[("period", 0.1)], MOTOR).unwrap(),
            Basis::from_kind(
                "ripple",
                &[("period", 0.1), ("phase", std::f64::consts::FRAC_PI_2)],
                MOTOR
            )
            .unwrap()
        );
        assert_eq!(
            Basis::from_kind("coulomb_spline_bwd", &[("center", 0.1), ("width", 0.05)], MOTOR).unwrap(),
            Basis::CoulombSpline {
                dof: MOTOR,
                center: 0.1,
                width: 0.05,
                side: -1,
                lo: 0.0,
                hi: 0.0,
            }
        );
        for (kind, hypers, says) in [
            ("stribeck", vec![], "needs its hyper-parameter vs (m/s)"),
            (
                "stribeck",
                vec![("speed", 0.1)],
                "hyper-parameters are vs, got \"speed\"",
            ),
            ("viscous", vec![("vs", 0.1)], "has no hyper-parameter"),
            ("ripple", vec![("period", 0.1), ("period", 0.2)], "given twice"),
            (
                "ripple_sin",
                vec![("period", 0.1), ("phase", 1.0)],
                "has phase = 0",
            ),
            (
                "coulomb_spline",
                vec![("center", 0.0), ("width", 0.1), ("side", 2.0)],
                "side is 1",
            ),
            (
                "coulomb_spline",
                vec![("center", 0.0), ("width", 0.0)],
                "knot spacing width > 0",
            ),
            (
                "stribeck",
                vec![("vs", -1.0)],
                "Stribeck speed vs must be finite and > 0",
            ),
            ("gravity", vec![("angle_offset", f64::NAN)], "finite angle offset"),
        ] {
            let e = Basis::from_kind(kind, &hypers, MOTOR).unwrap_err().to_string();
            assert!(e.contains(says), "{kind} {hypers:?}: {e}");
        }
    }

    #[test]
    fn a_gravity_pair_is_the_torque_of_a_pendulum_at_any_angle_offset() {
        // m g l sin(q + θ0) as A sin(q + θ0) + B cos(q + θ0): A = m g l, B = 0, for any θ0; and a pendulum whose zero
        // is off by δ is A' = m g l cos δ, B' = m g l sin δ at θ0 = 0
        let law = FrictionLaw::algebraic(1e-3);
        let (mgl, delta) = (3.7, 0.4);
        for theta0 in [0.0, 0.3, -2.0] {
            let s = Basis::from_kind("gravity", &[("angle_offset", theta0)], MOTOR).unwrap();
            let c = Basis::from_kind(
                "gravity",
                &[("angle_offset", theta0), ("phase", std::f64::consts::FRAC_PI_2)],
                MOTOR,
            )
            .unwrap();
            for q in [-3.0, -0.5, 0.0, 1.1, 2.9] {
                let truth = mgl * (q + theta0 + delta).sin();
                let fit =
                    mgl * delta.cos() * s.local(q, 0.0, law).0 + mgl * delta.sin() * c.local(q, 0.0, law).0;
                assert!(
                    (fit - truth).abs() < 1e-12 * mgl,
                    "{theta0} {q}: {fit} vs {truth}"
                );
            }
        }
        assert_eq!(
            Basis::Gravity {
                dof: 0,
                angle_offset: 0.0,
                phase: 0.0
            }
            .role(),
            Role::Force
        );
    }

    #[test]
    fn a_profile_held_within_its_stroke_keeps_its_end_values_beyond_it() {
        // knots 0.1 apart from -0.1 to 1.1 cover the stroke [0, 1]: inside, the held splines are the
        // plain ones; beyond, each keeps its value at the end it passed (slope 0), so a profile
        // (here weights 1, 2, ... per knot) carries its end value on, where the plain splines fall
        // to 0 within two knots
        let (lo, hi, w) = (0.0, 1.0, 0.1);
        let knots: Vec<f64> = (-1..=11).map(|j| lo + f64::from(j) * w).collect();
        let profile = |x: f64, held: bool| -> (f64, f64) {
            knots.iter().enumerate().fold((0.0, 0.0), |(p, dp), (j, &c)| {
                let (b, db) = if held {
                    held_bspline(x, c, w, lo, hi)
                } else {
                    held_bspline(x, c, w, 0.0, 0.0)
                };
                (p + (j as f64 + 1.0) * b, dp + (j as f64 + 1.0) * db)
            })
        };
        for x in [0.0, 0.013, 0.5, 0.77, 1.0] {
            assert_eq!(profile(x, true), profile(x, false));
        }
        let (at_hi, _) = profile(hi, true);
        let (at_lo, _) = profile(lo, true);
        for x in [1.01, 1.3, 5.0] {
            assert_eq!(profile(x, true), (at_hi, 0.0));
        }
        for x in [-0.01, -0.4, -7.0] {
            assert_eq!(profile(x, true), (at_lo, 0.0));
        }
        assert!(profile(5.0, false).0 == 0.0 && at_hi > 10.0);
        // the basis functions of both kinds hold alike, and a stroke with lo > hi is refused
        let b = Basis::from_kind(
            "coulomb_spline",
            &[("center", 1.0), ("width", w), ("lo", lo), ("hi", hi)],
            MOTOR,
        )
        .unwrap();
        let law = FrictionLaw::algebraic(1e-3);
        assert_eq!(b.local(3.0, 0.2, law).0, b.local(hi, 0.2, law).0);
        assert_eq!(b.local(3.0, 0.2, law).1, 0.0);
        let s = Basis::from_kind(
            "spline",
            &[("center", 1.0), ("width", w), ("lo", lo), ("hi", hi)],
            MOTOR,
        )
        .unwrap();
        assert_eq!(s.local(3.0, 0.0, law), s.local(hi, 0.0, law));
        assert!(Basis::from_kind(
            "spline",
            &[("center", 1.0), ("width", w), ("lo", 1.0), ("hi", 0.0)],
            MOTOR
        )
        .is_err());
    }

    #[test]
    fn cubic_bsplines_sum_to_one_and_friction_splines_split_the_sign_by_direction() {
        for i in 0..200 {
            let u = -3.0 + 0.0317 * i as f64;
            // the B-splines at the integers are a partition of unity, and B' is the slope of B
            let total: f64 = (-5..=5).map(|k| cubic_bspline(u - k as f64).0).sum();
            assert!((total - 1.0).abs() < 1e-14, "{u}: {total}");
            let h = 1e-6;
            let fd = (cubic_bspline(u + h).0 - cubic_bspline(u - h).0) / (2.0 * h);
            assert!((fd - cubic_bspline(u).1).abs() < 1e-8, "{u}: {fd}");
        }
        assert!((cubic_bspline(0.0).0 - 2.0 / 3.0).abs() < 1e-15);
        let eps = 1e-4;
        let law = FrictionLaw::algebraic(eps);
        let (fwd, bwd, both) = (
            Basis::from_kind(
                "coulomb_spline",
                &[("center", 0.05), ("width", 0.03), ("side", 1.0)],
                MOTOR,
            )
            .unwrap(),
            Basis::from_kind(
                "coulomb_spline",
                &[("center", 0.05), ("width", 0.03), ("side", -1.0)],
                MOTOR,
            )
            .unwrap(),
            Basis::from_kind("coulomb_spline", &[("center", 0.05), ("width", 0.03)], MOTOR).unwrap(),
        );
        for (x, v) in [
            (0.05, 0.02),
            (0.071, -0.013),
            (0.02, 3e-5),
            (0.11, -2e-4),
            (0.2, 0.1),
        ] {
            let (pf, xf, vf) = fwd.local(x, v, law);
            let (pb, xb, vb) = bwd.local(x, v, law);
            // the profile of both directions is their sum, derivatives included
            let (p2, x2, v2) = both.local(x, v, law);
            assert!(
                (p2 - pf - pb).abs() < 1e-15 && (x2 - xf - xb).abs() < 1e-12 && (v2 - vf - vb).abs() < 1e-9
            );
            // forward and backward together are the whole Coulomb sign times the spline
            let whole = cubic_bspline((x - 0.05) / 0.03).0 * coulomb_sign(v, eps);
            assert!((pf + pb - whole).abs() < 1e-15);
            // each acts in its own direction; the other one only within the smoothing of the sign
            let (s, bx) = (coulomb_sign(v, eps), cubic_bspline((x - 0.05) / 0.03).0);
            let (own, other) = if v > 0.0 { (pf, pb) } else { (-pb, pf) };
            assert!((own - bx * s.abs()).abs() <= bx * (1.0 - s.abs()) + 1e-15);
            assert!(other.abs() <= 0.5 * bx * (1.0 - s.abs()) + 1e-15);
            // partial derivatives against central differences
            let (hx, hv) = (1e-7, 1e-9);
            for (b, px, pv) in [(fwd, xf, vf), (bwd, xb, vb)] {
                let fx = (b.local(x + hx, v, law).0 - b.local(x - hx, v, law).0) / (2.0 * hx);
                let fv = (b.local(x, v + hv, law).0 - b.local(x, v - hv, law).0) / (2.0 * hv);
                assert!((fx - px).abs() < 1e-6 * (1.0 + px.abs()), "{x} {v}: {fx} vs {px}");
                assert!((fv - pv).abs() < 1e-4 * (1.0 + pv.abs()), "{x} {v}: {fv} vs {pv}");
            }
        }
        let e =
            Basis::from_kind("coulomb_spline_fwd", &[("center", 0.05), ("width", 0.0)], MOTOR).unwrap_err();
        assert!(e.to_string().contains("knot spacing width > 0"), "{e}");
    }

    #[test]
    fn every_friction_law_is_odd_saturating_with_slope_one_over_eps_and_its_derivative() {
        let eps = 2e-3;
        for name in LAW_SHAPES {
            let shape = LawShape::from_name(name).unwrap();
            assert_eq!(shape.name(), *name);
            let law = FrictionLaw { shape, eps };
            // slope 1/eps at rest
            let h = 1e-9;
            let slope = (law.sign(h) - law.sign(-h)) / (2.0 * h);
            assert!((slope * eps - 1.0).abs() < 1e-6, "{name}: {slope}");
            for v in [
                -5.0,
                -0.3,
                -4e-3,
                -1e-4,
                0.0,
                2e-5,
                1e-3,
                0.02,
                7.0,
                f64::INFINITY,
            ] {
                let (s, ds) = law.sign_and_derivative(v);
                assert!((law.sign(-v) + s).abs() < 1e-15, "{name} odd at {v}");
                assert!(s.abs() <= 1.0 && ds >= 0.0, "{name} at {v}: {s} {ds}");
                if v.is_finite() && v != 0.0 {
                    let hv = 1e-7 * v.abs().max(eps);
                    let fd = (law.sign(v + hv) - law.sign(v - hv)) / (2.0 * hv);
                    assert!(
                        (fd - ds).abs() <= 1e-5 * (1.0 / eps),
                        "{name} at {v}: {fd} vs {ds}"
                    );
                }
            }
            assert!(law.sign(1e3 * eps) > 0.99, "{name} saturates");
            assert_eq!(FrictionLaw { shape, eps: 0.0 }.sign(-3.0), -1.0);
        }
        assert!(LawShape::from_name("linear").is_err());
    }

    #[test]
    fn coulomb_sign_is_odd_saturating_and_hard_at_zero_eps() {
        assert_eq!(coulomb_sign(0.0, 0.0), 0.0);
        assert_eq!(coulomb_sign(-3.0, 0.0), -1.0);
        assert_eq!(coulomb_sign(1e-300, 0.0), 1.0);
        let eps = 1e-4;
        assert!((coulomb_sign(10.0 * eps, eps) - 0.995037190).abs() < 1e-9);
        assert_eq!(coulomb_sign(-2e-3, eps), -coulomb_sign(2e-3, eps));
        // derivative against a central difference
        for v in [-3e-4, 0.0, 5e-5, 2e-3] {
            let h = 1e-9;
            let fd = (coulomb_sign(v + h, eps) - coulomb_sign(v - h, eps)) / (2.0 * h);
            assert!((fd - coulomb_sign_derivative(v, eps)).abs() < 1e-5 * (1.0 / eps));
        }
    }

    #[test]
    fn flexible_idm_matches_equation_2() {
        let m = flexible(0.0).unwrap();
        let chi = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5];
        let q = Vector2::new(0.10, 0.1001); // q2 = 1e-4 m
        let qd = Vector2::new(0.05, -0.02);
        let qdd = Vector2::new(1.5, -2.0);
        let tau = m.idm(&chi, &q, &qd, &qdd);
        let q2 = q[1] - q[0];
        let t1 = 68.0 * 1.5 + 104.0 * 0.05 + 10.0 - 8.8e5 * q2;
        let t2 = 38.0 * -2.0 + 96.5 * -0.02 - 9.5 + 8.8e5 * q2;
        assert!((tau[0] - t1).abs() < 1e-9 && (tau[1] - t2).abs() < 1e-9);
        // The direct model inverts the inverse model.
        let inv_m = m.masses(&chi).map(|x| 1.0 / x);
        let u = Vector2::new(t1, t2);
        let acc = m.accel(&chi, &inv_m, &q, &qd, &u);
        assert!((acc - qdd).norm() < 1e-9);
        // The regressor reproduces the idm.
        let mut row = vec![0.0; 14];
        m.regressor_into(&q, &qd, &qdd, &mut row);
        let r0: f64 = (0..7).map(|j| row[j] * chi[j]).sum();
        let r1: f64 = (0..7).map(|j| row[7 + j] * chi[j]).sum();
        assert!((r0 - t1).abs() < 1e-9 && (r1 - t2).abs() < 1e-9);
        assert_eq!(row[6], -q2);
        assert_eq!(row[13], q2);
    }

    #[test]
    fn the_trajectory_regressor_is_each_sample_s_row_bit_for_bit() {
        // every kind of basis function, on two dofs, through every friction-law shape
        let terms: Vec<(String, Basis)> = vec![
            ("M1".into(), Basis::Inertia { dof: 0 }),
            ("M2".into(), Basis::Inertia { dof: 1 }),
            ("Fv".into(), Basis::Viscous { dof: 0 }),
            ("Fc".into(), Basis::Coulomb { dof: 1 }),
            ("OF".into(), Basis::Offset { dof: 0 }),
            ("K".into(), Basis::Spring { a: 1, b: 0 }),
            ("D".into(), Basis::Damper { a: 0, b: 1 }),
            ("AV".into(), Basis::AbsViscous { dof: 0 }),
            ("AC".into(), Basis::AbsCoulomb { dof: 1 }),
            ("S".into(), Basis::Stribeck { dof: 0, vs: 0.02 }),
            (
                "R".into(),
                Basis::Ripple {
                    dof: 1,
                    period: 0.03,
                    phase: 0.4,
                },
            ),
            (
                "CR".into(),
                Basis::CoulombRipple {
                    dof: 0,
                    period: 0.05,
                    phase: -1.0,
                },
            ),
            (
                "CS".into(),
                Basis::CoulombSpline {
                    dof: 0,
                    center: 0.01,
                    width: 0.02,
                    side: -1,
                    lo: 0.0,
                    hi: 0.0,
                },
            ),
            (
                "SP".into(),
                Basis::Spline {
                    dof: 1,
                    center: -0.01,
                    width: 0.03,
                    lo: 0.0,
                    hi: 0.0,
                },
            ),
            (
                "G".into(),
                Basis::Gravity {
                    dof: 0,
                    angle_offset: 0.3,
                    phase: 0.1,
                },
            ),
            (
                "B".into(),
                Basis::Backlash {
                    a: 1,
                    b: 0,
                    gap: 1e-3,
                },
            ),
        ];
        let base = Model::<2>::new(terms, 1e-3).unwrap();
        let n = 500;
        let series = |f: &dyn Fn(f64) -> f64| -> Vec<Vec<f64>> {
            (0..2)
                .map(|d| (0..n).map(|k| f(k as f64 * 0.01 + d as f64)).collect())
                .collect()
        };
        let q = series(&|t| 0.05 * (1.3 * t).sin() + 1e-3 * (7.0 * t).cos());
        let qd = series(&|t| 0.06 * (1.3 * t).cos() - 2e-3 * (9.0 * t).sin());
        let qdd = series(&|t| -0.08 * (1.3 * t).sin());
        for shape in [LawShape::Algebraic, LawShape::Tanh, LawShape::Atan, LawShape::Exp] {
            let m = base.with_law_shape(shape);
            let p = m.n_params();
            let w = m.regressor(&q, &qd, &qdd).unwrap();
            let mut row = vec![0.0; 2 * p];
            for k in 0..n {
                let at = |s: &Vec<Vec<f64>>| Vector2::new(s[0][k], s[1][k]);
                m.regressor_into(&at(&q), &at(&qd), &at(&qdd), &mut row);
                for d in 0..2 {
                    for j in 0..p {
                        assert_eq!(
                            w[(d * p + j) * n + k].to_bits(),
                            row[d * p + j].to_bits(),
                            "{shape:?} {d} {j} {k}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn invalid_models_and_parameters_are_named() {
        let e = Model::<1>::new(vec![("Fv".into(), Basis::Viscous { dof: 0 })], 0.0).unwrap_err();
        assert!(e.to_string().contains("no inertia"));
        let e = Model::<1>::new(vec![("M".into(), Basis::Inertia { dof: 1 })], 0.0).unwrap_err();
        assert!(e.to_string().contains("outside"));
        let r = rigid(true, 1e-4).unwrap();
        assert!(r
            .check_params(&[1.0, 2.0])
            .unwrap_err()
            .to_string()
            .contains("expected 4"));
        assert!(r
            .check_params(&[-1.0, 2.0, 1.0, 0.0])
            .unwrap_err()
            .to_string()
            .contains("mass M"));
        assert!(r
            .check_params(&[1.0, f64::NAN, 1.0, 0.0])
            .unwrap_err()
            .to_string()
            .contains("Fv"));
        let f = flexible(1e-4).unwrap();
        let e = f.check_params(&[1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(e.to_string().contains("stiffness K12"));
        assert!(rigid(false, -1.0).is_err());
    }
}
