//! Forward dynamics by Featherstone's articulated-body algorithm, in frames chosen as
//! Denavit–Hartenberg's: every joint moves about or along its z axis (its rotation mixes two
//! coordinates, its motion subspace picks one); the placement between two joints turns about x
//! only, by a quarter or half turn in most arms (entries moved, not multiplied), and its
//! translation lies along one axis in most (a cross product with it takes two products). Turning
//! a joint's frame about z to get there is an offset of its angle. The robot's own frames
//! (Pinocchio's) are kept everywhere else; torques and accelerations are the same in both (to
//! 2·10⁻¹² where a URDF writes a quarter turn with 12 digits, taken here for exact).

use nalgebra::{Matrix3, Vector3};

use super::spatial::{inertia_matrix, Force, Motion};
use super::{JointKind, Robot, BODY_PARAMS};
use crate::error::{invalid, Result};

/// `a·b + c` in one rounding: one instruction in the AVX2 and FMA build (5 % faster than two);
/// the baseline build computes the same, in software (processors without FMA predate 2013).
#[inline(always)]
fn muladd(a: f64, b: f64, c: f64) -> f64 {
    a.mul_add(b, c)
}

/// `a·b − c·d`.
#[inline(always)]
fn det2(a: f64, b: f64, c: f64, d: f64) -> f64 {
    muladd(a, b, -c * d)
}

/// `a × b`.
#[inline(always)]
fn cross(a: &Vector3<f64>, b: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        det2(a.y, b.z, a.z, b.y),
        det2(a.z, b.x, a.x, b.z),
        det2(a.x, b.y, a.y, b.x),
    )
}

/// `x·a + y·b` for vectors `a`, `b`.
#[inline(always)]
fn comb2(x: f64, a: &Vector3<f64>, y: f64, b: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        muladd(x, a.x, y * b.x),
        muladd(x, a.y, y * b.y),
        muladd(x, a.z, y * b.z),
    )
}

/// `a + k·b` for vectors `a`, `b`.
#[inline(always)]
fn axpy(a: &Vector3<f64>, k: f64, b: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(muladd(k, b.x, a.x), muladd(k, b.y, a.y), muladd(k, b.z, a.z))
}

/// Flat index of entry (i, j) of a symmetric 3 × 3 matrix stored as `[xx, xy, xz, yy, yz, zz]`.
const SYM: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];

/// A symmetric 3 × 3 matrix by its six entries `[xx, xy, xz, yy, yz, zz]`.
#[derive(Clone, Copy, Debug)]
struct Sym3([f64; 6]);

impl Sym3 {
    fn of(m: &Matrix3<f64>) -> Sym3 {
        Sym3([m[(0, 0)], m[(0, 1)], m[(0, 2)], m[(1, 1)], m[(1, 2)], m[(2, 2)]])
    }

    #[inline(always)]
    fn col(&self, k: usize) -> Vector3<f64> {
        Vector3::new(self.0[SYM[0][k]], self.0[SYM[1][k]], self.0[SYM[2][k]])
    }

    /// `self − k·u·uᵀ`.
    #[inline(always)]
    fn sub_outer(&mut self, u: &Vector3<f64>, k: f64) {
        let m = &mut self.0;
        let ku = -u * k;
        m[0] = muladd(ku.x, u.x, m[0]);
        m[1] = muladd(ku.x, u.y, m[1]);
        m[2] = muladd(ku.x, u.z, m[2]);
        m[3] = muladd(ku.y, u.y, m[3]);
        m[4] = muladd(ku.y, u.z, m[4]);
        m[5] = muladd(ku.z, u.z, m[5]);
    }

    #[inline(always)]
    fn add(&mut self, o: &Sym3) {
        for k in 0..6 {
            self.0[k] += o.0[k];
        }
    }

    /// `Rz·M·Rzᵀ` for the rotation about z of `(cos, sin)` (with `cs2 = (c², s², c·s)`).
    #[inline(always)]
    fn rz(&self, c: f64, s: f64, cs2: (f64, f64, f64)) -> Sym3 {
        let m = &self.0;
        let (cc, ss, cs) = cs2;
        let t = 2.0 * cs * m[1];
        Sym3([
            muladd(cc, m[0], muladd(ss, m[3], -t)),
            muladd(cs, m[0] - m[3], (cc - ss) * m[1]),
            det2(c, m[2], s, m[4]),
            muladd(ss, m[0], muladd(cc, m[3], t)),
            muladd(s, m[2], c * m[4]),
            m[5],
        ])
    }
}

/// How far a turn's cosine or sine may be from 0 or ±1 and be taken for a quarter or half turn:
/// URDFs write them with 11 or 12 digits of π/2, whose cosine is 5·10⁻¹² (dimensionless; the
/// dynamics move by that relative amount).
const AXES_SNAP: f64 = 1e-10;

/// The constant rotation `R` between two joints' frames. The frames are chosen (as
/// Denavit–Hartenberg's) so that it turns about x only, by a quarter turn or none in most arms:
/// those are applied by moving entries.
#[derive(Clone, Copy, Debug)]
enum Turn {
    /// No turn (parallel joints).
    Same,
    /// `Rx(+90°)`.
    Up,
    /// `Rx(180°)`.
    Flip,
    /// `Rx(α)` by `(cos α, sin α)`.
    X(f64, f64),
    /// Any rotation (after a prismatic joint whose next joint is turned about it).
    Any(Matrix3<f64>),
}

impl Turn {
    /// `Rx(α)` of `(cos α, sin α)`, quarter and half turns recognised.
    fn x(c: f64, s: f64) -> Turn {
        let near = |x: f64, y: f64| (x - y).abs() <= AXES_SNAP;
        if near(c, 1.0) && near(s, 0.0) {
            Turn::Same
        } else if near(c, 0.0) && near(s, 1.0) {
            Turn::Up
        } else if near(c, -1.0) && near(s, 0.0) {
            Turn::Flip
        } else {
            Turn::X(c, s)
        }
    }

    fn matrix(&self) -> Matrix3<f64> {
        let rx = |c: f64, s: f64| Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c);
        match *self {
            Turn::Same => Matrix3::identity(),
            Turn::Up => rx(0.0, 1.0),
            Turn::Flip => rx(-1.0, 0.0),
            Turn::X(c, s) => rx(c, s),
            Turn::Any(r) => r,
        }
    }

    /// `R·x`.
    #[inline(always)]
    fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Turn::Same => *x,
            Turn::Up => Vector3::new(x.x, -x.z, x.y),
            Turn::Flip => Vector3::new(x.x, -x.y, -x.z),
            Turn::X(c, s) => Vector3::new(x.x, det2(*c, x.y, *s, x.z), muladd(*s, x.y, c * x.z)),
            Turn::Any(r) => r * x,
        }
    }

    /// `Rᵀ·x`.
    #[inline(always)]
    fn apply_tr(&self, x: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Turn::Same => *x,
            Turn::Up => Vector3::new(x.x, x.z, -x.y),
            Turn::Flip => Vector3::new(x.x, -x.y, -x.z),
            Turn::X(c, s) => Vector3::new(x.x, muladd(*c, x.y, s * x.z), det2(*c, x.z, *s, x.y)),
            Turn::Any(r) => r.tr_mul(x),
        }
    }

    /// `R·M·Rᵀ`.
    #[inline(always)]
    fn congruence(&self, m: &Matrix3<f64>) -> Matrix3<f64> {
        let b = |i: usize, j: usize| m[(i, j)];
        match self {
            Turn::Same => *m,
            Turn::Up => Matrix3::new(
                b(0, 0),
                -b(0, 2),
                b(0, 1),
                -b(2, 0),
                b(2, 2),
                -b(2, 1),
                b(1, 0),
                -b(1, 2),
                b(1, 1),
            ),
            Turn::Flip => Matrix3::new(
                b(0, 0),
                -b(0, 1),
                -b(0, 2),
                -b(1, 0),
                b(1, 1),
                b(1, 2),
                -b(2, 0),
                b(2, 1),
                b(2, 2),
            ),
            Turn::X(c, s) => {
                // rows 1 and 2 mixed, then columns 1 and 2
                let (c, s) = (*c, *s);
                let mut n = *m;
                for j in 0..3 {
                    let (y, z) = (m[(1, j)], m[(2, j)]);
                    n[(1, j)] = det2(c, y, s, z);
                    n[(2, j)] = muladd(s, y, c * z);
                }
                let mut o = n;
                for i in 0..3 {
                    let (y, z) = (n[(i, 1)], n[(i, 2)]);
                    o[(i, 1)] = det2(c, y, s, z);
                    o[(i, 2)] = muladd(s, y, c * z);
                }
                o
            }
            Turn::Any(r) => r * m * r.transpose(),
        }
    }

    /// `R·M·Rᵀ` for a symmetric `M`.
    #[inline(always)]
    fn congruence_sym(&self, m: &Sym3) -> Sym3 {
        let d = &m.0;
        match self {
            Turn::Same => *m,
            Turn::Up => Sym3([d[0], -d[2], d[1], d[5], -d[4], d[3]]),
            Turn::Flip => Sym3([d[0], -d[1], -d[2], d[3], d[4], d[5]]),
            Turn::X(c, s) => {
                let (c, s) = (*c, *s);
                let (cc, ss, cs) = (c * c, s * s, c * s);
                let t = 2.0 * cs * d[4];
                Sym3([
                    d[0],
                    det2(c, d[1], s, d[2]),
                    muladd(s, d[1], c * d[2]),
                    muladd(cc, d[3], muladd(ss, d[5], -t)),
                    muladd(cs, d[3] - d[5], (cc - ss) * d[4]),
                    muladd(ss, d[3], muladd(cc, d[5], t)),
                ])
            }
            Turn::Any(r) => {
                let full = inertia_matrix(&[d[0], d[1], d[3], d[2], d[4], d[5]]);
                Sym3::of(&(r * full * r.transpose()))
            }
        }
    }
}

/// `Rz·x` for the rotation about z of `(cos, sin)`.
#[inline(always)]
fn rz(c: f64, s: f64, x: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(det2(c, x.x, s, x.y), muladd(s, x.x, c * x.y), x.z)
}

/// `Rzᵀ·x`.
#[inline(always)]
fn rz_tr(c: f64, s: f64, x: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(muladd(c, x.x, s * x.y), det2(c, x.y, s, x.x), x.z)
}

/// `Rz·M·Rzᵀ` for any `M`: its rows, then its columns 0 and 1 mixed.
#[inline(always)]
fn rz_congruence(c: f64, s: f64, m: &Matrix3<f64>) -> Matrix3<f64> {
    let mut n = *m;
    for j in 0..3 {
        let (x, y) = (m[(0, j)], m[(1, j)]);
        n[(0, j)] = det2(c, x, s, y);
        n[(1, j)] = muladd(s, x, c * y);
    }
    let mut o = n;
    for i in 0..3 {
        let (x, y) = (n[(i, 0)], n[(i, 1)]);
        o[(i, 0)] = det2(c, x, s, y);
        o[(i, 1)] = muladd(s, x, c * y);
    }
    o
}

/// A spatial (articulated) inertia as 3 × 3 blocks `[A, B; Bᵀ, C]` (A, C symmetric): the force of
/// a motion (ω, v) is (A ω + B v, Bᵀ ω + C v).
#[derive(Clone, Copy, Debug)]
struct Articulated {
    a: Sym3,
    b: Matrix3<f64>,
    c: Sym3,
}

impl Articulated {
    /// A rigid body's: `[I_O, [h]×; −[h]×, m·1]`.
    fn of_body(p: &[f64; BODY_PARAMS]) -> Self {
        Articulated {
            a: Sym3([p[4], p[5], p[7], p[6], p[8], p[9]]),
            b: Matrix3::new(0.0, -p[3], p[2], p[3], 0.0, -p[1], -p[2], p[1], 0.0),
            c: Sym3([p[0], 0.0, 0.0, p[0], 0.0, p[0]]),
        }
    }

    fn zero() -> Self {
        Articulated {
            a: Sym3([0.0; 6]),
            b: Matrix3::zeros(),
            c: Sym3([0.0; 6]),
        }
    }

    /// The force of a motion with no z components (the velocity-product accelerations).
    #[inline(always)]
    fn apply_xy(&self, m: &Motion) -> Force {
        let (a, c, b) = (&self.a, &self.c, &self.b);
        let (b0, b1) = (b.column(0).into_owned(), b.column(1).into_owned());
        let (r0, r1) = (b.row(0).transpose(), b.row(1).transpose());
        Force {
            n: comb2(m.w.x, &a.col(0), m.w.y, &a.col(1)) + comb2(m.v.x, &b0, m.v.y, &b1),
            f: comb2(m.w.x, &r0, m.w.y, &r1) + comb2(m.v.x, &c.col(0), m.v.y, &c.col(1)),
        }
    }

    /// `I·S` for `S` the z axis's rotation (`revolute`) or translation: the force that the
    /// joint's unit motion takes.
    #[inline(always)]
    fn times_z(&self, revolute: bool) -> Force {
        if revolute {
            Force {
                n: self.a.col(2),
                f: self.b.row(2).transpose(),
            }
        } else {
            Force {
                n: self.b.column(2).into_owned(),
                f: self.c.col(2),
            }
        }
    }

    /// `self − k·u·uᵀ` for a force `u` (the articulated inertia less what the joint takes up).
    #[inline(always)]
    fn subtract_outer(&mut self, u: &Force, k: f64) {
        self.a.sub_outer(&u.n, k);
        let kn = -u.n * k;
        for j in 0..3 {
            for i in 0..3 {
                self.b[(i, j)] = muladd(kn[i], u.f[j], self.b[(i, j)]);
            }
        }
        self.c.sub_outer(&u.f, k);
    }

    #[inline(always)]
    fn add(&mut self, o: &Articulated) {
        self.a.add(&o.a);
        self.b += o.b;
        self.c.add(&o.c);
    }

    /// Turned about z by `(cos, sin)`: each block `Rz·X·Rzᵀ`.
    #[inline(always)]
    fn rz(&self, c: f64, s: f64) -> Articulated {
        let cs2 = (c * c, s * s, c * s);
        Articulated {
            a: self.a.rz(c, s, cs2),
            b: rz_congruence(c, s, &self.b),
            c: self.c.rz(c, s, cs2),
        }
    }

    /// Turned by `turn`: each block `R·X·Rᵀ`.
    #[inline(always)]
    fn turned(&self, turn: &Turn) -> Articulated {
        Articulated {
            a: turn.congruence_sym(&self.a),
            b: turn.congruence(&self.b),
            c: turn.congruence_sym(&self.c),
        }
    }

    /// The inertia (in the parent's axes, about the child's origin) moved to the parent's origin,
    /// the child's origin being at `p`: `Xᵀ·I·X` for a translation,
    /// `A + S + Sᵀ − Q·P`, `B + Q`, `C` with `P = [p]×`, `S = P·Bᵀ`, `Q = P·C`, the skew
    /// products as cross products.
    #[inline(always)]
    fn shifted(&self, p: &Shift) -> Articulated {
        // one build per kind of translation: its cross products without branches
        match *p {
            Shift::X(a) => self.shifted_by(|x| Vector3::new(0.0, -a * x.z, a * x.y)),
            Shift::Y(b) => self.shifted_by(|x| Vector3::new(b * x.z, 0.0, -b * x.x)),
            Shift::Z(c) => self.shifted_by(|x| Vector3::new(-c * x.y, c * x.x, 0.0)),
            Shift::Any(p) => self.shifted_by(|x| cross(&p, x)),
        }
    }

    /// [`Articulated::shifted`] with `p × ·` as `cross`.
    #[inline(always)]
    fn shifted_by(&self, cross: impl Fn(&Vector3<f64>) -> Vector3<f64>) -> Articulated {
        // columns of S = P·Bᵀ and Q = P·C
        let b = &self.b;
        let s = [
            cross(&b.row(0).transpose()),
            cross(&b.row(1).transpose()),
            cross(&b.row(2).transpose()),
        ];
        let q = [
            cross(&self.c.col(0)),
            cross(&self.c.col(1)),
            cross(&self.c.col(2)),
        ];
        // Q·P = −(P·Qᵀ)ᵀ: (Q·P)[i][j] = −(p × Q's row i)[j]
        let qrow = |i: usize| Vector3::new(q[0][i], q[1][i], q[2][i]);
        let qp = [-cross(&qrow(0)), -cross(&qrow(1)), -cross(&qrow(2))];
        let a = &self.a.0;
        let entry = |i: usize, j: usize| a[SYM[i][j]] + s[j][i] + s[i][j] - qp[i][j];
        Articulated {
            a: Sym3([
                entry(0, 0),
                entry(0, 1),
                entry(0, 2),
                entry(1, 1),
                entry(1, 2),
                entry(2, 2),
            ]),
            b: self.b + Matrix3::from_columns(&q),
            c: self.c,
        }
    }
}

/// How far from 0, relative to the whole translation, a component of a joint's translation may be
/// and be taken for 0: the rounding that turning a URDF's frames leaves (10⁻¹² here).
const SHIFT_SNAP: f64 = 1e-9;

/// The translation between two joints' frames: along one axis, as most arms' are in these frames
/// (a cross product with it then takes two products), or any.
#[derive(Clone, Copy, Debug)]
enum Shift {
    X(f64),
    Y(f64),
    Z(f64),
    Any(Vector3<f64>),
}

impl Shift {
    fn of(p: &Vector3<f64>) -> Shift {
        let tol = SHIFT_SNAP * p.norm();
        match [p.x, p.y, p.z].map(|x| x.abs() > tol) {
            [_, false, false] => Shift::X(p.x),
            [false, true, false] => Shift::Y(p.y),
            [false, false, true] => Shift::Z(p.z),
            _ => Shift::Any(*p),
        }
    }

    fn vector(&self) -> Vector3<f64> {
        match *self {
            Shift::X(a) => Vector3::new(a, 0.0, 0.0),
            Shift::Y(b) => Vector3::new(0.0, b, 0.0),
            Shift::Z(c) => Vector3::new(0.0, 0.0, c),
            Shift::Any(p) => p,
        }
    }

    /// `p × x`.
    #[inline(always)]
    fn cross(&self, x: &Vector3<f64>) -> Vector3<f64> {
        match *self {
            Shift::X(a) => Vector3::new(0.0, -a * x.z, a * x.y),
            Shift::Y(b) => Vector3::new(b * x.z, 0.0, -b * x.x),
            Shift::Z(c) => Vector3::new(-c * x.y, c * x.x, 0.0),
            Shift::Any(p) => cross(&p, x),
        }
    }
}

/// One joint of the chain in joint-aligned frames: whether it turns, the rotation and translation
/// of its zero-position frame in the previous joint's, its body's parameters and spatial inertia.
#[derive(Clone, Debug)]
struct Link {
    revolute: bool,
    /// A revolute joint's angle at which its frame is the robot's (its frame turned about z so
    /// that the next joint's placement turns about x only).
    offset: f64,
    turn: Turn,
    shift: Shift,
    params: [f64; BODY_PARAMS],
    body: Articulated,
}

/// One joint's share of a call: its (cos, sin), its frame's origin (a prismatic joint's moves),
/// the velocity-product acceleration, the bias force, `1/D` and `u − U·c`.
#[derive(Clone, Copy, Debug)]
struct State {
    cs: (f64, f64),
    origin: Shift,
    c: Motion,
    pa: Force,
    /// `U = I·S` seen from the previous joint's frame (its force transform): the acceleration pass
    /// takes `U·a` from the parent's acceleration, beside that acceleration's transform.
    u_parent: Force,
    inv_d: f64,
    uu: f64,
}

/// The articulated-body algorithm's workspace for one robot: the chain in joint-aligned frames
/// (computed once) and the per-call state.
#[derive(Clone, Debug)]
pub struct AbaWork {
    links: Vec<Link>,
    /// Gravity's acceleration in the base's frame (turned about z as the first joint needs).
    gravity: Vector3<f64>,
    state: Vec<State>,
}

/// A body's parameters in a frame turned by `r` (`x_old = r·x_new`).
fn turned_params(p: &[f64; BODY_PARAMS], r: &Matrix3<f64>) -> [f64; BODY_PARAMS] {
    let h = r.tr_mul(&Vector3::new(p[1], p[2], p[3]));
    let i = r.transpose() * inertia_matrix(&p[4..10]) * r;
    [
        p[0],
        h.x,
        h.y,
        h.z,
        i[(0, 0)],
        i[(0, 1)],
        i[(1, 1)],
        i[(0, 2)],
        i[(1, 2)],
        i[(2, 2)],
    ]
}

impl AbaWork {
    /// The workspace of `robot` (its chain turned into joint-aligned frames once).
    pub fn new(robot: &Robot) -> Self {
        // Each frame is the robot's turned by `align`, so that its joint moves about or along z;
        // about z, it is chosen so that the next joint's placement turns about x only: the turn
        // about z that this needs goes to the joint before (an offset of its angle) or the base.
        let mut links: Vec<Link> = Vec::with_capacity(robot.ndof());
        let mut align = Matrix3::identity();
        let mut base = Matrix3::identity();
        for j in &robot.joints {
            let axis = j.axis.normalize();
            // the joint's axis in the previous frame: (sin β sin α, −cos β sin α, cos α)
            let u = align.tr_mul(&(j.placement_rotation * axis));
            let sin_a = u.x.hypot(u.y);
            if sin_a > AXES_SNAP {
                let beta = u.x.atan2(-u.y);
                let rzb = Matrix3::new(
                    beta.cos(),
                    -beta.sin(),
                    0.0,
                    beta.sin(),
                    beta.cos(),
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                );
                align *= rzb;
                match links.last_mut() {
                    None => base = align,
                    Some(prev) => {
                        prev.params = turned_params(&prev.params, &rzb);
                        prev.body = Articulated::of_body(&prev.params);
                        if prev.revolute {
                            prev.offset += beta;
                        } else {
                            prev.turn = Turn::Any(prev.turn.matrix() * rzb);
                        }
                    }
                }
            }
            let turn = Turn::x(u.z, sin_a);
            let shift = Shift::of(&align.tr_mul(&j.placement_translation));
            align = j.placement_rotation.tr_mul(&(align * turn.matrix()));
            let params = turned_params(&j.inertia, &align);
            links.push(Link {
                revolute: j.kind == JointKind::Revolute,
                offset: 0.0,
                turn,
                shift,
                params,
                body: Articulated::of_body(&params),
            });
        }
        let rest = State {
            cs: (1.0, 0.0),
            origin: Shift::X(0.0),
            c: Motion::zero(),
            pa: Force::zero(),
            u_parent: Force::zero(),
            inv_d: 0.0,
            uu: 0.0,
        };
        AbaWork {
            state: vec![rest; links.len()],
            links,
            gravity: base.tr_mul(&robot.gravity),
        }
    }
}

/// A motion of the previous joint's frame in this joint's.
#[inline(always)]
fn to_child(l: &Link, st: &State, m: &Motion) -> Motion {
    let w = l.turn.apply_tr(&m.w);
    let v = l.turn.apply_tr(&(m.v - st.origin.cross(&m.w)));
    if l.revolute {
        let (c, s) = st.cs;
        Motion::new(rz_tr(c, s, &w), rz_tr(c, s, &v))
    } else {
        Motion::new(w, v)
    }
}

/// A force in this joint's frame, in the previous joint's.
#[inline(always)]
fn to_parent(l: &Link, st: &State, f: &Force) -> Force {
    let (n, f) = if l.revolute {
        let (c, s) = st.cs;
        (rz(c, s, &f.n), rz(c, s, &f.f))
    } else {
        (f.n, f.f)
    };
    let fr = l.turn.apply(&f);
    Force {
        n: l.turn.apply(&n) + st.origin.cross(&fr),
        f: fr,
    }
}

/// A body's bias force `v ×* (I·v)` for parameters `p` (in the body's frame) moving with `v`.
#[inline(always)]
fn bias(p: &[f64; BODY_PARAMS], m: &Motion) -> Force {
    let (w, v) = (&m.w, &m.v);
    let h = Vector3::new(p[1], p[2], p[3]);
    let io = Vector3::new(
        muladd(p[4], w.x, muladd(p[5], w.y, p[7] * w.z)),
        muladd(p[5], w.x, muladd(p[6], w.y, p[8] * w.z)),
        muladd(p[7], w.x, muladd(p[8], w.y, p[9] * w.z)),
    );
    let n = io + cross(&h, v);
    let f = v * p[0] - cross(&h, w);
    Force {
        n: cross(w, &n) + cross(v, &f),
        f: cross(w, &f),
    }
}

/// The joint's motion `x` along its subspace (z): a rotation's about z, a translation's along z.
#[inline(always)]
fn along_z(revolute: bool, x: f64) -> Motion {
    let z = Vector3::new(0.0, 0.0, x);
    if revolute {
        Motion::new(z, Vector3::zeros())
    } else {
        Motion::new(Vector3::zeros(), z)
    }
}

impl Robot {
    /// Forward dynamics: the accelerations that torques `tau` give at positions `q` and speeds
    /// `v`, M(q)⁻¹ (τ − C(q, v) v − g(q)), with `armature` (rotor inertias reflected to each joint,
    /// kg·m² or kg, added to M's diagonal) when given. Featherstone's articulated-body algorithm:
    /// O(n), no mass matrix formed.
    pub fn aba(&self, q: &[f64], v: &[f64], tau: &[f64], armature: Option<&[f64]>) -> Result<Vec<f64>> {
        self.check("q", q)?;
        self.check("v", v)?;
        self.check("tau", tau)?;
        if let Some(ia) = armature {
            self.check("armature", ia)?;
        }
        let mut ws = AbaWork::new(self);
        let mut out = vec![0.0; self.ndof()];
        self.aba_into(q, v, tau, armature, &mut ws, &mut out)?;
        Ok(out)
    }

    /// [`Robot::aba`] without the checks, in a reusable workspace, in the processor's widest
    /// build (the simulator's inner loop calls this: one copy of the algorithm, out of line,
    /// runs a fifth faster than one inlined at each RK4 stage).
    pub fn aba_into(
        &self,
        q: &[f64],
        v: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
        ws: &mut AbaWork,
        out: &mut [f64],
    ) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::wide_simd() {
            // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
            return unsafe { self.aba_wide(q, v, tau, armature, ws, out) };
        }
        self.aba_kernel(q, v, tau, armature, ws, out)
    }

    /// [`Robot::aba_kernel`] compiled with AVX2 and FMA.
    ///
    /// # Safety
    /// The processor must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn aba_wide(
        &self,
        q: &[f64],
        v: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
        ws: &mut AbaWork,
        out: &mut [f64],
    ) -> Result<()> {
        self.aba_kernel(q, v, tau, armature, ws, out)
    }

    /// The articulated-body algorithm itself, inlined into each build. Spatial inertias are kept
    /// as 3 × 3 blocks.
    #[inline(always)]
    fn aba_kernel(
        &self,
        q: &[f64],
        v: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
        ws: &mut AbaWork,
        out: &mut [f64],
    ) -> Result<()> {
        let n = self.ndof();
        debug_assert_eq!(ws.links.len(), n, "the workspace of another robot");
        let (links, state) = (&ws.links[..n], &mut ws.state[..n]);
        let (q, v, tau, out) = (&q[..n], &v[..n], &tau[..n], &mut out[..n]);
        // forward: poses, velocities, velocity-product accelerations, bias forces
        // the joints' sines and cosines first: independent of each other, they overlap
        for ((l, st), &qi) in links.iter().zip(state.iter_mut()).zip(q) {
            if l.revolute {
                let (s, c) = crate::trig::sin_cos(qi + l.offset);
                st.cs = (c, s);
            }
        }
        let mut vp = Motion::zero();
        for ((l, st), (&qi, &qd)) in links.iter().zip(state.iter_mut()).zip(q.iter().zip(v)) {
            if l.revolute {
                st.origin = l.shift;
            } else {
                st.origin = Shift::Any(l.shift.vector() + l.turn.apply(&Vector3::new(0.0, 0.0, qi)));
            }
            let vi = to_child(l, st, &vp) + along_z(l.revolute, qd);
            // vi × the joint's motion: in the xy plane
            let (wz, vz) = (
                Vector3::new(vi.w.y * qd, -vi.w.x * qd, 0.0),
                Vector3::new(vi.v.y * qd, -vi.v.x * qd, 0.0),
            );
            st.c = if l.revolute {
                Motion::new(wz, vz)
            } else {
                Motion::new(Vector3::zeros(), wz)
            };
            st.pa = bias(&l.params, &vi);
            vp = vi;
        }
        // backward: articulated inertias and bias forces, each body's with what its child passes on
        let mut child = Articulated::zero();
        let mut child_pa = Force::zero();
        for (i, ((l, st), &ti)) in links.iter().zip(state.iter_mut()).zip(tau).enumerate().rev() {
            let mut ia = l.body;
            ia.add(&child);
            let pa_i = st.pa + child_pa;
            let u_vec = ia.times_z(l.revolute);
            let d = if l.revolute { u_vec.n.z } else { u_vec.f.z } + armature.map_or(0.0, |a| a[i]);
            if d.is_nan() {
                return Err(invalid!(
                    "joint {}: its articulated inertia is not a number: the joint positions or the inertial parameters are not finite (a closed loop that diverged numerically, as a spring too stiff or too damped for the sample period makes it)",
                    self.joints[i].name
                ));
            }
            if d <= 0.0 {
                return Err(invalid!(
                    "joint {}: its articulated inertia is not positive ({d}): the inertial parameters are not those of physical bodies",
                    self.joints[i].name
                ));
            }
            let inv_d = 1.0 / d;
            let u = ti - if l.revolute { pa_i.n.z } else { pa_i.f.z };
            st.inv_d = inv_d;
            // u − U·c (c has no z components)
            let (c, un, uf) = (&st.c, &u_vec.n, &u_vec.f);
            st.uu = u - ((un.x * c.w.x + un.y * c.w.y) + (uf.x * c.v.x + uf.y * c.v.y));
            st.u_parent = to_parent(l, st, &u_vec);
            if i > 0 {
                ia.subtract_outer(&u_vec, inv_d);
                let ic = ia.apply_xy(&st.c);
                let ud = u * inv_d;
                let pa = Force {
                    n: axpy(&(pa_i.n + ic.n), ud, &u_vec.n),
                    f: axpy(&(pa_i.f + ic.f), ud, &u_vec.f),
                };
                let ia = if l.revolute {
                    let (c, s) = st.cs;
                    ia.rz(c, s)
                } else {
                    ia
                };
                child = ia.turned(&l.turn).shifted(&st.origin);
                child_pa = to_parent(l, st, &pa);
            }
        }
        // forward: accelerations (gravity as an acceleration of the base); `U·a` from the parent's
        // acceleration through `U` seen from the parent, beside that acceleration's transform
        // (two independent chains)
        let mut ap = Motion::new(Vector3::zeros(), -ws.gravity);
        for ((l, st), o) in links.iter().zip(state.iter()).zip(out.iter_mut()) {
            let (un, uf) = (&st.u_parent.n, &st.u_parent.f);
            let ua = (un.x * ap.w.x + un.y * ap.w.y + un.z * ap.w.z)
                + (uf.x * ap.v.x + uf.y * ap.v.y + uf.z * ap.v.z);
            let qdd = (st.uu - ua) * st.inv_d;
            *o = qdd;
            ap = to_child(l, st, &ap) + st.c + along_z(l.revolute, qdd);
        }
        Ok(())
    }
}
