"""Exception classes of didim. The compiled core raises these too."""


class DidimError(Exception):
    """Base class of every error didim raises on purpose."""


class DataError(DidimError, ValueError):
    """Bad input: a file, a signal, a parameter or an option is wrong. The message says which and what to do."""


class SimulationError(DidimError):
    """The closed-loop simulation diverged; the message names the sample and the parameter set."""


class IdentifiabilityError(DidimError):
    """The regressor is rank deficient: some parameters cannot be told apart on this record."""


__all__ = ["DidimError", "DataError", "SimulationError", "IdentifiabilityError"]
