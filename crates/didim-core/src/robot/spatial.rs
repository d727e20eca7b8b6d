//! Spatial (6-D) motion and force vectors, rigid transforms and body inertia, as Featherstone
//! writes them: a motion is (angular ω, linear v at the frame's origin), a force (moment n about
//! the origin, force f).

use std::ops::Add;

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

use super::BODY_PARAMS;

#[derive(Clone, Copy, Debug)]
pub struct Motion {
    pub w: Vector3<f64>,
    pub v: Vector3<f64>,
}

#[derive(Clone, Copy, Debug)]
pub struct Force {
    pub n: Vector3<f64>,
    pub f: Vector3<f64>,
}

impl Motion {
    #[inline(always)]
    pub fn new(w: Vector3<f64>, v: Vector3<f64>) -> Self {
        Motion { w, v }
    }

    #[inline(always)]
    pub fn zero() -> Self {
        Motion::new(Vector3::zeros(), Vector3::zeros())
    }

    #[inline(always)]
    pub fn scale(&self, s: f64) -> Self {
        Motion::new(self.w * s, self.v * s)
    }

    /// The motion cross product `self × m` (the rate of change of `m` carried by this motion).
    #[inline(always)]
    pub fn cross(&self, m: &Motion) -> Motion {
        Motion::new(self.w.cross(&m.w), self.w.cross(&m.v) + self.v.cross(&m.w))
    }

    /// The force cross product `self ×* f`.
    #[inline(always)]
    pub fn cross_force(&self, f: &Force) -> Force {
        Force {
            n: self.w.cross(&f.n) + self.v.cross(&f.f),
            f: self.w.cross(&f.f),
        }
    }

    /// The power pairing with a force.
    #[inline(always)]
    pub fn dot(&self, f: &Force) -> f64 {
        self.w.dot(&f.n) + self.v.dot(&f.f)
    }
}

impl Force {
    #[inline(always)]
    pub fn zero() -> Self {
        Force {
            n: Vector3::zeros(),
            f: Vector3::zeros(),
        }
    }
}

impl Add for Motion {
    type Output = Motion;
    #[inline(always)]
    fn add(self, o: Motion) -> Motion {
        Motion::new(self.w + o.w, self.v + o.v)
    }
}

impl Add for Force {
    type Output = Force;
    #[inline(always)]
    fn add(self, o: Force) -> Force {
        Force {
            n: self.n + o.n,
            f: self.f + o.f,
        }
    }
}

/// A child frame's pose in its parent's: its axes (columns of `rotation`) and its origin
/// (`translation`), both in the parent's coordinates.
#[derive(Clone, Copy, Debug)]
pub struct Pose {
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
}

impl Pose {
    pub fn identity() -> Self {
        Pose {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// This pose followed by `other` (a pose in this one's frame).
    #[inline(always)]
    pub fn compose(&self, other: &Pose) -> Pose {
        Pose {
            rotation: self.rotation * other.rotation,
            translation: self.translation + self.rotation * other.translation,
        }
    }

    /// A motion of the parent's frame, in the child's coordinates at the child's origin.
    #[inline(always)]
    pub fn motion_to_child(&self, m: &Motion) -> Motion {
        let rt = self.rotation.transpose();
        Motion::new(rt * m.w, rt * (m.v + m.w.cross(&self.translation)))
    }

    /// A force in the child's coordinates about its origin, in the parent's about the parent's.
    #[inline(always)]
    pub fn force_to_parent(&self, f: &Force) -> Force {
        let fr = self.rotation * f.f;
        Force {
            n: self.rotation * f.n + self.translation.cross(&fr),
            f: fr,
        }
    }
}

/// The rotation by `angle` about `axis` (normalised here).
pub fn rotation_about(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    Rotation3::from_axis_angle(&Unit::new_normalize(*axis), angle).into_inner()
}

/// URDF's roll-pitch-yaw: Rz(yaw) · Ry(pitch) · Rx(roll).
pub fn rpy(r: f64, p: f64, y: f64) -> Matrix3<f64> {
    Rotation3::from_euler_angles(r, p, y).into_inner()
}

/// The symmetric inertia matrix of `[Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`.
pub fn inertia_matrix(i: &[f64]) -> Matrix3<f64> {
    Matrix3::new(i[0], i[1], i[3], i[1], i[2], i[4], i[3], i[4], i[5])
}

/// The spatial force `I · m` of a body with parameters `[m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz,
/// Izz]` (h = m·c; the inertia about the frame's origin) moving with `m`.
pub fn inertia_apply(p: &[f64; BODY_PARAMS], m: &Motion) -> Force {
    let h = Vector3::new(p[1], p[2], p[3]);
    let io = inertia_matrix(&p[4..10]);
    Force {
        n: io * m.w + h.cross(&m.v),
        f: m.v * p[0] - h.cross(&m.w),
    }
}

/// A body's parameters from its mass, centre of mass and inertia about the centre of mass, all in
/// the frame the parameters are expressed in.
pub fn params_of(mass: f64, com: &Vector3<f64>, inertia_com: &Matrix3<f64>) -> [f64; BODY_PARAMS] {
    let io = inertia_com + (Matrix3::identity() * com.norm_squared() - com * com.transpose()) * mass;
    [
        mass,
        mass * com.x,
        mass * com.y,
        mass * com.z,
        io[(0, 0)],
        io[(0, 1)],
        io[(1, 1)],
        io[(0, 2)],
        io[(1, 2)],
        io[(2, 2)],
    ]
}

fn skew(x: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -x.z, x.y, x.z, 0.0, -x.x, -x.y, x.x, 0.0)
}

/// A spatial (articulated) inertia as 3 × 3 blocks `[A, B; Bᵀ, C]` (A, C symmetric): the force of
/// a motion (ω, v) is (A ω + B v, Bᵀ ω + C v).
#[derive(Clone, Copy, Debug)]
pub struct Articulated {
    a: Matrix3<f64>,
    b: Matrix3<f64>,
    c: Matrix3<f64>,
}

impl Articulated {
    #[inline(always)]
    pub fn zero() -> Self {
        Articulated {
            a: Matrix3::zeros(),
            b: Matrix3::zeros(),
            c: Matrix3::zeros(),
        }
    }

    /// A rigid body's: `[I_O, [h]×; −[h]×, m·1]`.
    pub fn of_body(p: &[f64; BODY_PARAMS]) -> Self {
        Articulated {
            a: inertia_matrix(&p[4..10]),
            b: skew(&Vector3::new(p[1], p[2], p[3])),
            c: Matrix3::identity() * p[0],
        }
    }

    #[inline(always)]
    pub fn apply(&self, m: &Motion) -> Force {
        Force {
            n: self.a * m.w + self.b * m.v,
            f: self.b.tr_mul(&m.w) + self.c * m.v,
        }
    }

    /// The force of the joint's unit motion: about the axis (`revolute`) or along it.
    #[inline(always)]
    pub fn times_axis(&self, axis: &Vector3<f64>, revolute: bool) -> Force {
        if revolute {
            Force {
                n: self.a * axis,
                f: self.b.tr_mul(axis),
            }
        } else {
            Force {
                n: self.b * axis,
                f: self.c * axis,
            }
        }
    }

    /// `self − k·u·uᵀ` for a force `u` (the articulated inertia less what the joint takes up).
    #[inline(always)]
    pub fn subtract_outer(&mut self, u: &Force, k: f64) {
        self.a -= u.n * u.n.transpose() * k;
        self.b -= u.n * u.f.transpose() * k;
        self.c -= u.f * u.f.transpose() * k;
    }

    #[inline(always)]
    pub fn add(&mut self, o: &Articulated) {
        self.a += o.a;
        self.b += o.b;
        self.c += o.c;
    }

    /// The same inertia seen from the parent's frame, the child's pose being `pose`: rotated into the
    /// parent's axes, then moved from the child's origin to the parent's (`Xᵀ·I·X`):
    /// `A' + S + Sᵀ − P·C'·P`, `B' + P·C'`, `C'` with `P = [p]×`, `S = P·B'ᵀ`, the skew products
    /// as cross products.
    #[inline(always)]
    pub fn in_parent(&self, pose: &Pose) -> Articulated {
        let r = &pose.rotation;
        let rt = r.transpose();
        let a = r * self.a * rt;
        let b = r * self.b * rt;
        let c = r * self.c * rt;
        let p = &pose.translation;
        // P·X column by column
        let px = |x: &Matrix3<f64>| {
            Matrix3::from_columns(&[
                p.cross(&x.column(0).into_owned()),
                p.cross(&x.column(1).into_owned()),
                p.cross(&x.column(2).into_owned()),
            ])
        };
        let s = px(&b.transpose());
        let q = px(&c);
        // P·C'·P = Q·P = −(P·Qᵀ)ᵀ
        let qp = -px(&q.transpose()).transpose();
        Articulated {
            a: a + s + s.transpose() - qp,
            b: b + q,
            c,
        }
    }
}
