"""One numeric field of a text row, with the typed errors every Python-side reader raises (the Rust
readers raise the same classes): :class:`NotNumericError` for text that is not a number,
:class:`NonFiniteError` for NaN or infinity, each naming the file, line, column (1-based) and field."""
from __future__ import annotations

import math

from imu_learn.errors import NonFiniteError, NotNumericError


def number(text: str, path: str, lineno: int, column: int, name: str) -> float:
    """``text`` (stripped) as a finite float, else the typed error naming ``path``:``lineno``, column and field."""
    text = text.strip()
    try:
        x = float(text)
    except ValueError:
        raise NotNumericError(f"{path}:{lineno}: column {column} ({name}): {text!r} is not a number",
                              path, lineno, column, name) from None
    if not math.isfinite(x):
        raise NonFiniteError(f"{path}:{lineno}: column {column} ({name}): {text!r} is not finite",
                             path, lineno, column, name)
    return x
