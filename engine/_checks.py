"""The one check of a sampling frequency, shared by the WV, the loaders and the app.

A private module whose names are public within the project (``engine.wv``, ``engine.io`` and
``gmwm_app`` call it); users meet it through the messages of ``wavelet_variance(fs=...)``,
``load_log(fs=...)`` and the app's fs field.
"""

from __future__ import annotations

import math
import numbers

__all__ = ["check_fs", "MIN_FS", "MAX_FS"]

#: The range of a sampling frequency (Hz): one sample in 30 years to 1 GHz. Beyond it the
#: times in seconds and the datasheet values overflow or lose every digit (``fs = 1e308``
#: gives ``dt = 1e-308``, a subnormal).
MIN_FS, MAX_FS = 1e-9, 1e9


def check_fs(value: object, name: str = "fs") -> float:
    """``value`` as a sampling frequency in Hz: a real number (not a bool), finite and > 0,
    within :data:`MIN_FS` to :data:`MAX_FS`.

    Parameters
    ----------
    value : object
        The sampling frequency as given.
    name : str
        The argument's name, for the message.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        ``"fs must be a positive number of Hz, got 'abc'"``: names the argument and the value
        (and the range, for a number outside it).

    Examples
    --------
    >>> check_fs(100)
    100.0
    >>> check_fs(0.0)
    Traceback (most recent call last):
    ...
    ValueError: fs must be a positive number of Hz, got 0.0
    """
    v = math.nan
    if isinstance(value, bool):  # True is not 1 Hz
        pass
    elif isinstance(value, numbers.Real):
        v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive number of Hz, got {value!r}")
    if not MIN_FS <= v <= MAX_FS:
        raise ValueError(
            f"{name} must be a positive number of Hz, got {value!r}: outside the range of a "
            f"sampling frequency ({MIN_FS:g} to {MAX_FS:g} Hz)"
        )
    return v
