"""Exception types shared by the whole package.

Every loader (TOML, OBJ/STL, CSV, HDF5, albedo maps) raises :class:`InputError` for bad
input, with a message that names the file, the field, the offending value and what is
allowed. It subclasses :class:`ValueError` so that callers who only know the standard
library still catch it.
"""

from __future__ import annotations

__all__ = ["InputError", "ConvergenceError"]


class InputError(ValueError):
    """Bad user input: a file, a field or an argument outside what is allowed.

    Parameters
    ----------
    message : str
        What was wrong, in plain words.
    file : str or os.PathLike, optional
        The file being read, if any.
    field : str, optional
        The key, column or dataset name (``"orbit.e"``, ``"line 12"``...).
    value : object, optional
        The offending value (shortened in the message if long).
    allowed : str, optional
        What would have been accepted (``"0 <= e < 1"``).
    """

    def __init__(self, message, *, file=None, field=None, value=None, allowed=None):
        self.file = None if file is None else str(file)
        self.field = field
        self.value = value
        self.allowed = allowed
        parts = []
        if self.file:
            parts.append(self.file)
        if field:
            parts.append(f"field '{field}'")
        prefix = ": ".join(parts)
        text = f"{prefix}: {message}" if prefix else message
        if value is not None:
            shown = value.item() if getattr(value, "ndim", None) == 0 else value  # NumPy scalar
            v = repr(shown)
            if len(v) > 80:
                v = v[:77] + "..."
            text += f" (got {v})"
        if allowed:
            text += f"; allowed: {allowed}"
        self.bare_message = message
        super().__init__(text)


class ConvergenceError(RuntimeError):
    """A numerical procedure failed (factorisation, divergence, an MCMC chain that did not
    converge) and could not recover.

    Parameters
    ----------
    message : str
        What failed and why.
    diagnostics : object, optional
        The procedure's diagnostics (e.g. the chain diagnostics of
        :func:`lightcurve.studies.fit_reflection.fit_reflection`), kept as ``.diagnostics``.
    """

    def __init__(self, message, diagnostics=None):
        super().__init__(message)
        self.diagnostics = diagnostics
