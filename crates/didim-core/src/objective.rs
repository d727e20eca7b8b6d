//! The simulation-based quantities the identification methods iterate on, computed in
//! one call each so that no intermediate signal crosses into Python: the decimated output
//! error of a parameter set (Nelder–Mead, eq. (32)), the decimated DIDIM system of an
//! iterate (eqs. (16)-(20)), the decimated residual and exact Jacobian of the
//! sensitivity solver, and batched forms that spread many parameter sets over the cores
//! (rayon) with the results in input order, so a batch is deterministic.

use crate::controller::Controller;
use crate::error::{invalid, Error, Result};
use crate::filter::Decimation;
use crate::model::Model;
use crate::sim::{simulate, simulate_force, simulate_sensitivity, SensOutput, SimOptions, SimOutput};
use rayon::prelude::*;

/// Which simulated output is compared with the measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// The commanded motor force (criterion J_τ).
    Force,
    /// The motor position q1 (criterion J_q).
    MotorPosition,
}

/// One record's closed loop: the model structure, the controller, the reference, the
/// known external input and the simulator options. Parameter values vary per call.
#[derive(Clone, Copy, Debug)]
pub struct Problem<'a, const N: usize> {
    pub model: &'a Model<N>,
    pub controller: Controller,
    pub qr: &'a [f64],
    pub u_ext: Option<&'a [f64]>,
    pub opts: SimOptions,
}

/// The buffers a batch of `m` simulations is written into ([`Problem::simulate_batch`]): the
/// commanded forces (`m × n`, set after set) and the states (`m × N × n`); the speeds and
/// accelerations only when asked for.
#[derive(Debug)]
pub struct BatchOut<'b> {
    pub force: &'b mut [f64],
    pub q: &'b mut [f64],
    pub qd: Option<&'b mut [f64]>,
    pub qdd: Option<&'b mut [f64]>,
}

/// The decimated DIDIM system of one iterate.
#[derive(Clone, Debug, PartialEq)]
pub struct DidimSystem {
    /// Stacked decimated targets: the measured force minus the frozen terms (motor row),
    /// minus the frozen terms (other rows), dof after dof.
    pub y: Vec<f64>,
    /// Stacked decimated regressor columns of the free parameters, column-major
    /// (`y.len()` rows).
    pub w: Vec<f64>,
    /// The decimated simulated force (for the output error of the iterate).
    pub force_dec: Vec<f64>,
    /// The simulated motor position (dof 0) at the full rate: where the simulation joins the
    /// record (the caller's start row) without simulating the iterate again.
    pub q_motor: Vec<f64>,
}

/// The decimated residual and Jacobian of the output-error criterion.
#[derive(Clone, Debug, PartialEq)]
pub struct Linearization {
    /// `dec(measured − simulated)`.
    pub residual: Vec<f64>,
    /// `dec(∂simulated/∂χ_j)` of the free parameters, column-major (`residual.len()` rows).
    pub jacobian: Vec<f64>,
}

impl<const N: usize> Problem<'_, N> {
    /// The closed-loop simulation with parameters `chi`.
    pub fn simulate(&self, chi: &[f64]) -> Result<SimOutput> {
        simulate(self.model, chi, &self.controller, self.qr, self.u_ext, &self.opts)
    }

    /// The closed-loop simulation with parameters `chi` and its forward sensitivities.
    pub fn simulate_sensitivity(&self, chi: &[f64]) -> Result<SensOutput> {
        simulate_sensitivity(self.model, chi, &self.controller, self.qr, self.u_ext, &self.opts)
    }

    /// Simulations of many parameter sets, in parallel, each written into its rows of `out` as
    /// soon as it is made (no set's signals wait for the others': holding them all, then copying
    /// them, cost a third of a batch's time on one thread). The result of each set in input order;
    /// a set that fails leaves NaN in its rows.
    pub fn simulate_batch(&self, chis: &[Vec<f64>], out: BatchOut<'_>) -> Vec<Result<()>> {
        let n = self.opts.outputs(self.qr.len());
        let m = chis.len();
        let per = N * n;
        let sizes_ok = out.force.len() == m * n
            && out.q.len() == m * per
            && out.qd.as_ref().is_none_or(|b| b.len() == m * per)
            && out.qdd.as_ref().is_none_or(|b| b.len() == m * per);
        if !sizes_ok || n == 0 {
            let why = if n == 0 {
                invalid!("a batch of simulations of a reference without samples")
            } else {
                invalid!("a batch's buffers do not hold {m} sets of {n} samples of {N} dof(s)")
            };
            return (0..m).map(|_| Err(why.clone())).collect();
        }
        fn rows(b: Option<&mut [f64]>, per: usize, m: usize) -> Vec<Option<&mut [f64]>> {
            match b {
                Some(b) => b.chunks_mut(per).map(Some).collect(),
                None => (0..m).map(|_| None).collect(),
            }
        }
        let slots: Vec<_> = chis
            .iter()
            .zip(out.force.chunks_mut(n))
            .zip(out.q.chunks_mut(per))
            .zip(rows(out.qd, per, m))
            .zip(rows(out.qdd, per, m))
            .collect();
        slots
            .into_par_iter()
            .map(|((((chi, force), q), qd), qdd)| match self.simulate(chi) {
                Ok(o) => {
                    force.copy_from_slice(&o.force);
                    for (dst, src) in [(Some(q), &o.q), (qd, &o.qd), (qdd, &o.qdd)] {
                        if let Some(dst) = dst {
                            for (row, s) in dst.chunks_mut(n).zip(src.iter()) {
                                row.copy_from_slice(s);
                            }
                        }
                    }
                    Ok(())
                }
                Err(e) => {
                    force.fill(f64::NAN);
                    for dst in [Some(q), qd, qdd].into_iter().flatten() {
                        dst.fill(f64::NAN);
                    }
                    Err(e)
                }
            })
            .collect()
    }

    /// `‖measured_dec − dec(simulated output)‖²`, the criterion of eq. (32) on decimated signals,
    /// summed over the decimated rows from `skip` on (the rows before it are a record's start that
    /// the simulation, at rest on the reference, has not joined yet; 0 for every row).
    pub fn squared_error(
        &self,
        chi: &[f64],
        output: Output,
        measured_dec: &[f64],
        dec: &Decimation,
        skip: usize,
    ) -> Result<f64> {
        let sim = match output {
            Output::Force => dec.apply(&simulate_force(
                self.model,
                chi,
                &self.controller,
                self.qr,
                self.u_ext,
                &self.opts,
            )?)?,
            Output::MotorPosition => dec.apply(&self.simulate(chi)?.q[0])?,
        };
        if sim.len() != measured_dec.len() {
            return Err(invalid!(
                "the decimated measurement has {} samples but the decimated simulation {}; decimate the measurement with the same decimator",
                measured_dec.len(),
                sim.len()
            ));
        }
        Ok(measured_dec
            .iter()
            .zip(&sim)
            .skip(skip)
            .map(|(a, b)| (a - b) * (a - b))
            .sum())
    }

    /// [`Problem::squared_error`] of many parameter sets, in parallel, in input order.
    pub fn squared_error_batch(
        &self,
        chis: &[Vec<f64>],
        output: Output,
        measured_dec: &[f64],
        dec: &Decimation,
        skip: usize,
    ) -> Vec<Result<f64>> {
        chis.par_iter()
            .map(|chi| self.squared_error(chi, output, measured_dec, dec, skip))
            .collect()
    }

    /// Simulates with `chi`, builds the IDM regressor of the simulated states and
    /// decimates, dof by dof, the target (`force` on the motor row, 0 on the others,
    /// minus the frozen terms) and the columns `free`, all together.
    pub fn didim_system(
        &self,
        chi: &[f64],
        force: &[f64],
        free: &[usize],
        dec: &Decimation,
    ) -> Result<DidimSystem> {
        let n = self.opts.outputs(self.qr.len());
        if force.len() != n {
            return Err(invalid!(
                "the measured force has {} samples but the reference has {n}",
                force.len()
            ));
        }
        let p = self.model.n_params();
        if let Some(&j) = free.iter().find(|&&j| j >= p) {
            return Err(invalid!(
                "free parameter index {j} is out of range (the model has {p})"
            ));
        }
        let out = self.simulate(chi)?;
        let w = self
            .model
            .regressor(&out.q.rows(), &out.qd.rows(), &out.qdd.rows())?;
        let col = |d: usize, j: usize| &w[(d * p + j) * n..(d * p + j + 1) * n];
        let frozen: Vec<usize> = (0..p).filter(|j| !free.contains(j)).collect();
        let targets: Vec<Vec<f64>> = (0..N)
            .map(|d| {
                (0..n)
                    .map(|k| {
                        let y = if d == 0 { force[k] } else { 0.0 };
                        y - frozen.iter().map(|&j| col(d, j)[k] * chi[j]).sum::<f64>()
                    })
                    .collect()
            })
            .collect();
        let mut cols: Vec<&[f64]> = vec![&out.force];
        for d in 0..N {
            cols.push(&targets[d]);
            cols.extend(free.iter().map(|&j| col(d, j)));
        }
        let names = self.model.names();
        let per = 1 + free.len();
        let dcols = dec.apply_columns(&cols, |i| match i {
            0 => "simulated force".to_string(),
            i if (i - 1) % per == 0 => format!("target of dof {}", (i - 1) / per),
            i => format!(
                "regressor column {} of dof {}",
                names[free[(i - 1) % per - 1]],
                (i - 1) / per
            ),
        })?;
        let mut it = dcols.into_iter();
        let force_dec = it.next().unwrap_or_default();
        let blocks: Vec<Vec<f64>> = it.collect();
        let m = force_dec.len();
        let mut y = Vec::with_capacity(N * m);
        for d in 0..N {
            y.extend_from_slice(&blocks[d * per]);
        }
        let mut wd = Vec::with_capacity(N * m * free.len());
        for f in 0..free.len() {
            for d in 0..N {
                wd.extend_from_slice(&blocks[d * per + 1 + f]);
            }
        }
        let mut q_motor = out.q.into_flat();
        q_motor.truncate(n);
        Ok(DidimSystem {
            y,
            w: wd,
            force_dec,
            q_motor,
        })
    }

    /// The decimated residual `dec(measured − simulated)` and Jacobian `dec(∂simulated/∂χ_free)`
    /// from the forward sensitivities, at `chi`.
    pub fn linearize(
        &self,
        chi: &[f64],
        output: Output,
        measured: &[f64],
        free: &[usize],
        dec: &Decimation,
    ) -> Result<Linearization> {
        let n = self.opts.outputs(self.qr.len());
        if measured.len() != n {
            return Err(invalid!(
                "the measured output has {} samples but the reference has {n}",
                measured.len()
            ));
        }
        let p = self.model.n_params();
        if let Some(&j) = free.iter().find(|&&j| j >= p) {
            return Err(invalid!(
                "free parameter index {j} is out of range (the model has {p})"
            ));
        }
        let s = simulate_sensitivity(self.model, chi, &self.controller, self.qr, self.u_ext, &self.opts)?;
        let (sim, sens): (&[f64], &[f64]) = match output {
            Output::Force => (&s.sim.force, &s.dforce),
            Output::MotorPosition => (&s.sim.q[0], &s.dq[..p * n]),
        };
        let r: Vec<f64> = measured.iter().zip(sim).map(|(a, b)| a - b).collect();
        let mut cols: Vec<&[f64]> = vec![&r];
        cols.extend(free.iter().map(|&j| &sens[j * n..(j + 1) * n]));
        let names = self.model.names();
        let mut d = dec
            .apply_columns(&cols, |i| {
                if i == 0 {
                    "residual".to_string()
                } else {
                    format!("sensitivity to {}", names[free[i - 1]])
                }
            })?
            .into_iter();
        let residual = d.next().unwrap_or_default();
        Ok(Linearization {
            residual,
            jacobian: d.flatten().collect(),
        })
    }
}

/// Turns a batch's results into values and per-member errors (`None` where it succeeded).
pub fn split_errors<T>(results: Vec<Result<T>>) -> (Vec<Option<T>>, Vec<Option<Error>>) {
    results
        .into_iter()
        .map(|r| match r {
            Ok(v) => (Some(v), None),
            Err(e) => (None, Some(e)),
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterForm;
    use crate::model::flexible;

    fn reference(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64 * 1e-3;
                0.1 * (1.0 - (t * 2.0).cos()) + 0.002 * (t * 150.0).sin()
            })
            .collect()
    }

    #[test]
    fn batch_results_equal_single_runs_in_input_order() {
        let model = flexible(1e-4).unwrap();
        let qr = reference(3000);
        let pb = Problem {
            model: &model,
            controller: Controller::EMPS,
            qr: &qr,
            u_ext: None,
            opts: SimOptions::new(1e-3),
        };
        let base = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5];
        let chis: Vec<Vec<f64>> = (0..6)
            .map(|i| base.iter().map(|x| x * (1.0 + 0.05 * i as f64)).collect())
            .collect();
        let n = qr.len();
        let (mut force, mut q, mut qd, mut qdd) = (
            vec![0.0; 6 * n],
            vec![0.0; 12 * n],
            vec![0.0; 12 * n],
            vec![0.0; 12 * n],
        );
        let out = BatchOut {
            force: &mut force,
            q: &mut q,
            qd: Some(&mut qd),
            qdd: Some(&mut qdd),
        };
        assert!(pb.simulate_batch(&chis, out).iter().all(|r| r.is_ok()));
        for (i, chi) in chis.iter().enumerate() {
            let one = pb.simulate(chi).unwrap();
            assert_eq!(&force[i * n..(i + 1) * n], &one.force[..]);
            for d in 0..2 {
                let at = (2 * i + d) * n;
                assert_eq!(&q[at..at + n], &one.q[d][..]);
                assert_eq!(&qd[at..at + n], &one.qd[d][..]);
                assert_eq!(&qdd[at..at + n], &one.qdd[d][..]);
            }
        }
        // a failing set leaves NaN in its rows and its neighbours as they are
        let mut bad = chis.clone();
        bad[1][0] = -1.0;
        let (mut f2, mut q2) = (vec![0.0; 6 * n], vec![0.0; 12 * n]);
        let out = BatchOut {
            force: &mut f2,
            q: &mut q2,
            qd: None,
            qdd: None,
        };
        let res = pb.simulate_batch(&bad, out);
        assert!(res[1].is_err() && res[0].is_ok() && res[2].is_ok());
        assert!(f2[n..2 * n].iter().all(|x| x.is_nan()) && q2[2 * n..4 * n].iter().all(|x| x.is_nan()));
        assert_eq!(&f2[2 * n..3 * n], &force[2 * n..3 * n]);
        let dec = Decimation::butterworth(4, 60.0, 1000.0, 6, FilterForm::Sos).unwrap();
        let meas = dec.apply(&force[..n]).unwrap();
        let costs = pb.squared_error_batch(&chis, Output::Force, &meas, &dec, 0);
        assert_eq!(*costs[0].as_ref().unwrap(), 0.0);
        assert!(costs[1..].iter().all(|c| *c.as_ref().unwrap() > 0.0));
        // a failing member does not spoil the others
        let mut bad = chis.clone();
        bad[2][0] = -1.0;
        let (vals, errs) = split_errors(pb.squared_error_batch(&bad, Output::Force, &meas, &dec, 0));
        assert!(errs[2].is_some() && vals[2].is_none());
        assert_eq!(vals[3], Some(*costs[3].as_ref().unwrap()));
    }

    #[test]
    fn didim_system_stacks_the_decimated_rows_of_each_dof() {
        let model = flexible(1e-4).unwrap();
        let qr = reference(2000);
        let pb = Problem {
            model: &model,
            controller: Controller::EMPS,
            qr: &qr,
            u_ext: None,
            opts: SimOptions::new(1e-3),
        };
        let chi = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5];
        let out = pb.simulate(&chi).unwrap();
        let dec = Decimation::butterworth(4, 60.0, 1000.0, 6, FilterForm::Sos).unwrap();
        let free = [0, 1, 2, 3, 6];
        let sys = pb.didim_system(&chi, &out.force, &free, &dec).unwrap();
        let m = dec.output_len(qr.len());
        assert_eq!(sys.y.len(), 2 * m);
        assert_eq!(sys.w.len(), 2 * m * free.len());
        // The simulated states satisfy the IDM, so the true parameters solve the system.
        let fit: Vec<f64> = (0..2 * m)
            .map(|i| (0..free.len()).map(|f| sys.w[f * 2 * m + i] * chi[free[f]]).sum())
            .collect();
        let scale = sys.y.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let err = fit
            .iter()
            .zip(&sys.y)
            .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        assert!(err < 1e-6 * scale, "{err} of {scale}");
        assert_eq!(sys.force_dec, dec.apply(&out.force).unwrap());
    }
}
