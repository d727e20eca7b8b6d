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
}

/// Result alias of the core.
pub type Result<T> = std::result::Result<T, Error>;

/// Shorthand to build an [`Error::InvalidInput`] from a format string.
macro_rules! invalid {
    ($($arg:tt)*) => { $crate::error::Error::InvalidInput(format!($($arg)*)) };
}
pub(crate) use invalid;
