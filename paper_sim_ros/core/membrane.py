"""The held springs as a membrane inside the bending solve (docs/solver.md, "The membrane").

The bending solve alone sees no springs: every edge may stretch in it, and the springs'
iterations that follow rebuild the sheet from the directions its edges took, so a drooping
strip ends short of the elastica and a squeezed sheet's arch is crushed. Here each held
spring adds ½ w (uᵀ(x_j − x_i) − l0)² to the bending solve's energy, u its direction at the
sub-step's start: stiff along the edge, free to turn (linear in x, so the system stays
quadratic). Its weight is ``membrane_weight`` × B / l0² [N/m] (B the bending rigidity): the
same share of the bending stiffness on every grid.

That term couples x, y and z, which the bending factor (one matrix for the three
coordinates) cannot take: the coupled system is solved by conjugate gradients
preconditioned by the bending solve itself, under the same constraint rows (a constraint
preconditioner: every iterate meets the rows). Units SI.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from numba import njit


@njit(cache=True)
def edge_units(positions, ends, unit):
    """``unit`` (E, 3) ← the unit direction of each edge (i, j) at ``positions``."""
    for e in range(ends.shape[0]):
        i, j = ends[e, 0], ends[e, 1]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        dz = positions[j, 2] - positions[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length < 1e-12:
            unit[e, 0] = unit[e, 1] = unit[e, 2] = 0.0  # a collapsed edge holds nothing
        else:
            unit[e, 0] = dx / length
            unit[e, 1] = dy / length
            unit[e, 2] = dz / length


@njit(cache=True)
def add_membrane_product(ends, unit, weight, x, out):
    """``out`` += the membrane's Hessian times ``x``: w u uᵀ (x_j − x_i) at j, minus at i."""
    for e in range(ends.shape[0]):
        i, j = ends[e, 0], ends[e, 1]
        along = weight[e] * (unit[e, 0] * (x[j, 0] - x[i, 0])
                             + unit[e, 1] * (x[j, 1] - x[i, 1])
                             + unit[e, 2] * (x[j, 2] - x[i, 2]))
        for axis in range(3):
            out[j, axis] += along * unit[e, axis]
            out[i, axis] -= along * unit[e, axis]


@njit(cache=True)
def add_membrane_rhs(ends, unit, weight, rest_length, out):
    """``out`` += the membrane's right-hand side: w l0 u at j, minus at i."""
    for e in range(ends.shape[0]):
        i, j = ends[e, 0], ends[e, 1]
        pull = weight[e] * rest_length[e]
        for axis in range(3):
            out[j, axis] += pull * unit[e, axis]
            out[i, axis] -= pull * unit[e, axis]


@njit(cache=True)
def _dot(a, b):
    total = 0.0
    for v in range(a.shape[0]):
        total += a[v, 0] * b[v, 0] + a[v, 1] * b[v, 1] + a[v, 2] * b[v, 2]
    return total


@njit(cache=True)
def _largest(a):
    largest = 0.0
    for v in range(a.shape[0]):
        for axis in range(3):
            largest = max(largest, abs(a[v, axis]))
    return largest


@njit(cache=True)
def _step_along(x, residual, direction, product, step_length):
    """x += α p, r −= α A p (one pass)."""
    for v in range(x.shape[0]):
        for axis in range(3):
            x[v, axis] += step_length * direction[v, axis]
            residual[v, axis] -= step_length * product[v, axis]


@njit(cache=True)
def _next_direction(direction, preconditioned, beta):
    """p ← z + β p."""
    for v in range(direction.shape[0]):
        for axis in range(3):
            direction[v, axis] = preconditioned[v, axis] + beta * direction[v, axis]


MEMBRANE_TOLERANCE = 1e-7
"""The conjugate gradients stop once the bending solve of the residual moves no vertex by
more than this [m] (a ninetieth of the strain band on a 3 mm edge)."""


def membrane_weights(rest_length: np.ndarray, bending_rigidity: float,
                     membrane_weight: float) -> np.ndarray:
    """(E,) w [N/m] of each held spring: ``membrane_weight`` × B / l0²."""
    return membrane_weight * bending_rigidity / np.maximum(rest_length, 1e-9) ** 2


class Membrane:
    """The held springs' membrane of one sub-step (directions from its start) and the
    coupled solve by preconditioned conjugate gradients."""

    def __init__(self, ends: np.ndarray, rest_length: np.ndarray, weight: np.ndarray,
                 start_positions: np.ndarray) -> None:
        self.ends, self.rest_length, self.weight = ends, rest_length, weight
        self.unit = np.empty((ends.shape[0], 3))
        edge_units(start_positions, ends, self.unit)

    def product(self, system, x: np.ndarray, out: np.ndarray) -> None:
        """``out`` ← (system ⊗ I₃ + membrane) x."""
        out[:] = system @ x
        add_membrane_product(self.ends, self.unit, self.weight, x, out)

    def solve(self, system, precondition: Callable[[np.ndarray, np.ndarray], None],
              rhs: np.ndarray, positions: np.ndarray, pinned: np.ndarray,
              iterations: int) -> int:
        """``iterations`` of conjugate gradients on (system ⊗ I₃ + membrane) x = rhs +
        membrane's, from ``positions`` (which must meet the rows ``precondition`` keeps
        and hold the pinned vertices), overwriting it. ``precondition(r, z)``: z ← the
        bending solve of r under the rows with zero values, zero at pinned vertices.
        Returns the iterations run (fewer once P r moves no vertex by MEMBRANE_TOLERANCE)."""
        total_rhs = rhs.copy()
        add_membrane_rhs(self.ends, self.unit, self.weight, self.rest_length, total_rhs)
        product = np.empty_like(positions)
        self.product(system, positions, product)
        residual = total_rhs - product
        residual[pinned] = 0.0
        preconditioned = np.zeros_like(positions)
        precondition(residual, preconditioned)
        direction = preconditioned.copy()
        along = _dot(residual, preconditioned)
        for iteration in range(iterations):
            # z = P r is the move the bending solve would make of what is left [m]
            if not _largest(preconditioned) > MEMBRANE_TOLERANCE or not np.isfinite(along):
                return iteration
            self.product(system, direction, product)
            product[pinned] = 0.0
            curvature = _dot(direction, product)
            if not curvature > 0.0:
                return iteration
            _step_along(positions, residual, direction, product, along / curvature)
            preconditioned[:] = 0.0
            precondition(residual, preconditioned)
            next_along = _dot(residual, preconditioned)
            _next_direction(direction, preconditioned, next_along / along)
            along = next_along
        return iterations
