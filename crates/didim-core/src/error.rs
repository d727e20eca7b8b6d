//! The core's error type. Every fallible public function returns [`Result`];
//! the bindings map each variant to a Python exception class.

/// Errors of the numerical core.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// Bad input: wrong lengths, non-finite values, out-of-range options.
    /// The message names the argument and what to do.
    #[error("{0}")]
    InvalidInput(String),
    /// The closed-loop simulation diverged or produced a non-finite state.
    #[error("{0}")]
    Simulation(String),
    /// The regressor is rank deficient (or otherwise unusable) for the requested estimate.
    #[error("{0}")]
    Identifiability(String),
    /// The user asked to stop (see [`crate::interrupt`]).
    #[error("interrupted")]
    Interrupted,
    /// An allocation failed; the message names what and how much.
    #[error("{0}")]
    OutOfMemory(String),
}

/// An empty vector with room for `len` values, or [`Error::OutOfMemory`] naming `what` and the
/// size (instead of aborting the process as `Vec::with_capacity` does).
pub fn room(len: usize, what: &str) -> Result<Vec<f64>> {
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| {
        Error::OutOfMemory(format!(
            "cannot allocate {what}: {len} values ({:.3} GB); use a shorter record or fewer parameter sets per call",
            len as f64 * 8e-9
        ))
    })?;
    Ok(v)
}

/// `len` copies of `value`, or [`Error::OutOfMemory`] (see [`room`]).
pub fn filled(len: usize, value: f64, what: &str) -> Result<Vec<f64>> {
    let mut v = room(len, what)?;
    v.resize(len, value);
    Ok(v)
}

/// Result alias of the core.
pub type Result<T> = std::result::Result<T, Error>;

/// Shorthand to build an [`Error::InvalidInput`] from a format string.
macro_rules! invalid {
    ($($arg:tt)*) => { $crate::error::Error::InvalidInput(format!($($arg)*)) };
}
pub(crate) use invalid;
