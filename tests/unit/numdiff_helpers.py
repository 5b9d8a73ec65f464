"""Shared helper of the Jacobian tests (imported by test modules, not collected)."""

import numpy as np


def central_jacobian(fun, x0, h):
    """∂fun/∂x at x0 by central differences with per-component steps ``h``."""
    cols = []
    for i in range(len(x0)):
        e = np.zeros(len(x0))
        e[i] = h[i]
        cols.append((fun(x0 + e) - fun(x0 - e)) / (2 * h[i]))
    return np.column_stack(cols)
