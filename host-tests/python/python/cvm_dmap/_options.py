"""Keyword arguments to dmap's command-line words, and the warnings."""

import math
import numbers
import os
import warnings
from typing import Any, Dict, List, Optional


class DmapWarning(UserWarning):
    """What dmap prints as ``dmap: warning: ...`` after a run's output."""


def word(value: Any) -> str:
    """One option value as dmap reads it on its command line."""
    if isinstance(value, bool):
        raise ValueError(f"{value!r} is not a value (a flag is given as True)")
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):  # float, and NumPy's float scalars
        f = float(value)
        return "NaN" if math.isnan(f) else repr(f)
    if isinstance(value, (tuple, list)):
        return ",".join(word(v) for v in value)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return str(value)


def argv(options: Dict[str, Any]) -> List[str]:
    """``{"power_threshold": 0.2, "scores": True}`` as
    ``["--power-threshold", "0.2", "--scores"]``: None and False leave an
    option out, True gives a flag, a list of values repeats it."""
    out: List[str] = []
    for name, value in options.items():
        flag = "--" + name.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            out.append(flag)
        elif isinstance(value, list) and value and isinstance(value[0], (tuple, list)):
            out += [f"{flag}={word(v)}" for v in value]
        else:
            # One word, so that a negative number stays a value.
            out.append(f"{flag}={word(value)}")
    return out


def scoring(kernels: Optional[str], weights: Optional[str], bmax: Optional[int], raw: bool) -> Dict[str, Any]:
    """The scoring options shared by score, stream and calibrate."""
    return {"kernels": kernels, "weights": weights, "bmax": bmax, "raw": raw}


def warn(messages: List[str], stacklevel: int = 3) -> None:
    """Each of dmap's warnings as a Python warning."""
    for m in messages:
        warnings.warn(m, DmapWarning, stacklevel=stacklevel)
