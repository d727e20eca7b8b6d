//! The closed loop, once for every plant: a plant of joints ([`Plant`]), each joint driven by its
//! own [`JointDrive`] (encoder, controller, delay, force lag, external force). Per sample `k`:
//!
//! 1. each drive reads its joint's position and computes its command, logged in the record, and
//!    the force applied over the coming period;
//! 2. the plant records its state at `t_k` (with the accelerations under the applied forces);
//! 3. the plant advances over the period with the applied forces held;
//! 4. the loop has diverged when the state is not finite or a joint left its reference at
//!    `t_{k+1}` by more than its bound.
//!
//! Two plants implement [`Plant`]: one axis (`sim::driver::Axis`, a [`crate::Model`] of `N`
//! degrees of freedom whose first is the one joint, integrated by the exponential integrator or
//! RK4 with its forward sensitivities riding along) and a robot (`robot::closed_loop`'s chain of
//! rigid bodies with its drives' inertia and friction, RK4 on fixed substeps). Each plant's
//! arithmetic is its own; the drives' and the loop's are these, written once. The loop is
//! `#[inline(always)]` and generic over the plant, so one axis's fast path stays one monomorphic,
//! const-generic loop compiled into the processor's widest build (`sim::driver::simd`), with its
//! one drive held in an array of one, as fast as the loop it replaced.

use super::drive::JointDrive;
use crate::error::{Error, Result};
use crate::interrupt;

/// A plant of joints under the loop of [`run`]: its state, how it records and advances it.
pub(crate) trait Plant {
    /// One value per joint (the forces applied): an array for a plant of a fixed number of
    /// joints (one axis's `[f64; 1]`, which the compiler unrolls), a `Vec` otherwise.
    type Joints: AsRef<[f64]> + AsMut<[f64]>;

    /// Zeros, one per joint.
    fn joints(&self) -> Self::Joints;

    /// The true position of joint `j` (what its encoder reads).
    fn position(&self, j: usize) -> f64;

    /// Joint `j`'s drive computed its command of sample `k` (`active`: not saturated) and applies
    /// `applied` over the coming period. Nothing by default; one axis's sensitivities follow the
    /// controller here.
    #[inline(always)]
    fn commanded(&mut self, _k: usize, _j: usize, _drive: &JointDrive, _active: bool, _applied: f64) {}

    /// Records the state at sample `k`, the forces `applied` over the coming period.
    fn record(&mut self, k: usize, applied: &[f64]) -> Result<()>;

    /// Advances the state over one sample period with the forces `applied` held.
    fn advance(&mut self, applied: &[f64]) -> Result<()>;

    /// Whether the state is finite.
    fn finite(&self) -> bool;

    /// The error of a loop found diverged at sample `k`, its references `qr` there and the
    /// joints' `bound`s on their departure from them.
    fn diverged(&self, k: usize, qr: &[f64], bound: &[f64]) -> Error;
}

/// The closed loop of `plant` with one drive per joint in `drives`, following the references `qr`
/// (`samples × joints`, row-major) with the known external forces `u_ext` (the same layout; `None`
/// for none), from its state at the first sample. The commands are logged into `force` (the same
/// layout). A joint farther than its `bound` from its reference has diverged.
#[inline(always)]
pub(crate) fn run<P: Plant>(
    plant: &mut P,
    drives: &mut [JointDrive],
    qr: &[f64],
    u_ext: Option<&[f64]>,
    bound: &[f64],
    force: &mut [f64],
) -> Result<()> {
    let nj = drives.len();
    let samples = qr.len() / nj;
    let mut applied = plant.joints();
    for k in 0..samples {
        if k % interrupt::EVERY == 0 {
            interrupt::check()?;
        }
        let row = k * nj;
        for (j, drive) in drives.iter_mut().enumerate() {
            let ext = u_ext.map_or(0.0, |u| u[row + j]);
            let (command, f, active) = drive.step(qr[row + j], plant.position(j), ext);
            force[row + j] = command;
            applied.as_mut()[j] = f;
            plant.commanded(k, j, drive, active, f);
        }
        plant.record(k, applied.as_ref())?;
        if k + 1 == samples {
            break;
        }
        plant.advance(applied.as_ref())?;
        let next = &qr[row + nj..row + 2 * nj];
        if !(plant.finite() && (0..nj).all(|j| (plant.position(j) - next[j]).abs() <= bound[j])) {
            return Err(plant.diverged(k + 1, next, bound));
        }
    }
    Ok(())
}
