"""The solver library's exceptions, in a leaf module so that ``base`` and ``options`` can both use
them without importing each other."""


class MwisInputError(ValueError):
    """Malformed MWIS input; the message names the field and the offending value."""


class BackendUnavailable(RuntimeError):
    """The backend cannot run here (missing package, missing credentials); message says why."""
