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

/// The regressor's columns of one body: for each of its ten parameters (as [`inertia_apply`] orders
/// them), the spatial force `I_k·a + v ×* (I_k·v)` of a body whose parameters are that one at 1 and
/// the others 0, moving with speed `v` and acceleration `a` (the body's force is linear in them).
#[inline(always)]
pub fn unit_forces(a: &Motion, v: &Motion) -> [Force; BODY_PARAMS] {
    // I_k applied to a motion m: mass: (0, m.v); first moment along e_d: (e_d × m.v, m.w × e_d);
    // an inertia entry: (E_k m.w, 0)
    let e = [Vector3::x(), Vector3::y(), Vector3::z()];
    let apply = |k: usize, m: &Motion| -> Force {
        let w = &m.w;
        match k {
            0 => Force {
                n: Vector3::zeros(),
                f: m.v,
            },
            1..=3 => Force {
                n: e[k - 1].cross(&m.v),
                f: m.w.cross(&e[k - 1]),
            },
            4 => Force {
                n: Vector3::new(w.x, 0.0, 0.0),
                f: Vector3::zeros(),
            },
            5 => Force {
                n: Vector3::new(w.y, w.x, 0.0),
                f: Vector3::zeros(),
            },
            6 => Force {
                n: Vector3::new(0.0, w.y, 0.0),
                f: Vector3::zeros(),
            },
            7 => Force {
                n: Vector3::new(w.z, 0.0, w.x),
                f: Vector3::zeros(),
            },
            8 => Force {
                n: Vector3::new(0.0, w.z, w.y),
                f: Vector3::zeros(),
            },
            _ => Force {
                n: Vector3::new(0.0, 0.0, w.z),
                f: Vector3::zeros(),
            },
        }
    };
    std::array::from_fn(|k| apply(k, a) + v.cross_force(&apply(k, v)))
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
