"""Endpoint correspondence (thesis Algorithm 2) and its alternatives.

Phi(v_i, w_j) = || (a_i, dv_i, dc_i) - (a~_j, dv~_j, dc~_j) || (Euclidean).

- ``greedy`` (default): repeatedly pair the globally closest remaining endpoints;
  independent of the order in which endpoints are listed.
- ``greedy_sequential``: the literal Algorithm 2, "for each endpoint of E, find
  the closest remaining endpoint of E~, pair them, delete both", with E in the
  order of the skeleton's endpoint list (by node id, i.e. by band).
- ``optimal``: minimum total cost assignment (``scipy.optimize.linear_sum_assignment``).

Each pairs min(n1, n2) endpoints.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

Correspondence = Literal["greedy", "greedy_sequential", "optimal"]


def endpoint_costs(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Phi for every pair: (n1, n2) Euclidean distances between feature rows."""
    if len(A) == 0 or len(B) == 0:
        return np.zeros((len(A), len(B)))
    return cdist(A, B)


def correspond(C: np.ndarray, method: Correspondence = "greedy") -> tuple[np.ndarray, np.ndarray]:
    """Matched (rows, cols) of the cost matrix ``C`` (n1, n2); min(n1, n2) pairs."""
    n1, n2 = C.shape
    if n1 == 0 or n2 == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if method == "optimal":
        r, c = linear_sum_assignment(C)
        return r.astype(np.int64), c.astype(np.int64)
    rows, cols = [], []
    free_r, free_c = np.ones(n1, bool), np.ones(n2, bool)
    if method == "greedy_sequential":
        for i in range(n1):
            if not free_c.any():
                break
            j = int(np.argmin(np.where(free_c, C[i], np.inf)))
            rows.append(i)
            cols.append(j)
            free_c[j] = False
    else:
        order = np.argsort(C, axis=None, kind="stable")
        for flat in order:
            i, j = divmod(int(flat), n2)
            if free_r[i] and free_c[j]:
                rows.append(i)
                cols.append(j)
                free_r[i] = free_c[j] = False
                if len(rows) == min(n1, n2):
                    break
    return np.array(rows, np.int64), np.array(cols, np.int64)
