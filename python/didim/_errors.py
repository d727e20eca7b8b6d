"""Exception classes of didim. The compiled core raises these too."""


class DidimError(Exception):
    """Base class of every error didim raises on purpose."""


class DataError(DidimError, ValueError):
    """Bad input: a file, a signal, a parameter or an option is wrong. The message says which and what to do."""


class SimulationError(DidimError):
    """The closed-loop simulation diverged; the message names the sample and the parameter set."""


class IdentifiabilityError(DidimError):
    """The regressor is rank deficient: some parameters cannot be told apart on this record."""


class DidimWarning(UserWarning):
    """Something in the input looks wrong but need not be (a command saturating for long stretches, a force that
    looks like volts where newtons are expected, ...). The message gives the evidence and what to check. Silence
    them with ``warnings.simplefilter("ignore", didim.DidimWarning)`` or turn them into errors with "error"."""


# shown as didim.DataError (their public name) in tracebacks and reprs, not as the private module's
for _cls in (DidimError, DataError, SimulationError, IdentifiabilityError, DidimWarning):
    _cls.__module__ = "didim"
del _cls

__all__ = ["DidimError", "DataError", "SimulationError", "IdentifiabilityError", "DidimWarning"]
