//! `didim-core`: the numerical kernels of DIDIM identification of position-controlled
//! drives and flexible-joint axes (M. Gautier, A. Jubien, A. Janot, P.-Ph. Robet,
//! "Dynamic identification of flexible joint manipulators with an efficient closed
//! loop output error method based on motor torque output data").
//!
//! - [`model`]: linear-in-parameters models, one definition for the direct dynamics,
//!   the inverse dynamic model and its regressor;
//! - [`controller`] and [`sim`]: the closed-loop simulator (digital controller with
//!   zero-order hold; exponential integrator by default, RK4 as the reference);
//! - [`filter`]: zero-phase filters and parallel decimation (paper section III);
//! - [`lstsq`]: QR least squares with base parameters and covariance (eqs. (11)-(15));
//! - [`objective`]: output errors, DIDIM systems and Jacobians computed in one call, and
//!   their batched parallel forms.
//!
//! Pure Rust: no Python types. SI units on the load side throughout.

// Numerical kernels index like the equations they implement.
#![allow(clippy::needless_range_loop)]

pub mod controller;
pub(crate) mod cpu;
pub mod error;
pub mod filter;
pub mod interrupt;
pub mod lstsq;
pub mod model;
pub mod objective;
pub mod robot;
pub mod sim;
pub mod trig;

pub use controller::Controller;
pub use error::{Error, Result};
pub use model::{Basis, Model};
pub use sim::{simulate, SimOptions, SimOutput};
