"""Fast projection of the held springs onto the strain band (Goldenthal et al. 2007), the
``solver.length_projection`` option: Newton steps on the springs' lengths in the sheet's
mass metric, each a solve of the Schur complement J M⁻¹ Jᵀ by preconditioned conjugate
gradients, matrix-free (J: the active springs' unit directions).

Run between the bending solve and the springs' local/global iterations, it lets the edges
turn as a constraint projection does, where the iterations only rebuild the sheet from the
directions its edges had after the bending solve: a drooping strip then settles at the
elastica's tip angle at large deflections too (docs/solver.md, "The cantilever"). Units SI.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .kernels import EPSILON_LENGTH

NEWTON_STEPS = 5
"""Newton steps a sub-step, at most (measured: 3 leave a 200 mm strip of 2.5 mm cells 4 %
short of the elastica, 5 within 2 %)."""
CG_ITERATIONS = 30
"""Conjugate-gradient iterations a Newton step, at most (30 and 100 give the same tip
angles to 0.1 %)."""
CG_TOLERANCE = 1e-6
"""Relative residual at which the conjugate gradients stop."""
SLACK = 0.5
"""A spring beyond the band aims at this share of the band, not its edge: aimed at the edge,
springs hover across it and the active set never settles."""
COMPLIANCE = 1e-2
"""Regularisation of the Schur complement, × its diagonal: a triangle mesh whose every
edge is active is over-constrained, and at 2.5 mm cells the unregularised steps blew up
(1e-3: 11 mm/s left after 4 s; 1e-2: at rest)."""


@njit(cache=True)
def _transposed_product(count, active, ends, directions, x, gathered):
    """``gathered`` = Jᵀ x per vertex over the ``count`` active springs."""
    gathered[:, :] = 0.0
    for a in range(count):
        i = ends[active[a], 0]
        j = ends[active[a], 1]
        for axis in range(3):
            gathered[j, axis] += directions[a, axis] * x[a]
            gathered[i, axis] -= directions[a, axis] * x[a]


@njit(cache=True)
def _schur_product(count, active, ends, directions, inverse_mass, weights, x, out, gathered):
    """out = (J W Jᵀ + COMPLIANCE diag(J W Jᵀ)) x over the ``count`` active springs."""
    _transposed_product(count, active, ends, directions, x, gathered)
    for a in range(count):
        i = ends[active[a], 0]
        j = ends[active[a], 1]
        total = 0.0
        for axis in range(3):
            total += directions[a, axis] * (inverse_mass[j] * gathered[j, axis]
                                            - inverse_mass[i] * gathered[i, axis])
        out[a] = total + COMPLIANCE * weights[a] * x[a]


@njit(cache=True)
def project_lengths(positions, inverse_mass, ends, rest_length, shortest, longest):
    """Move ``positions`` so that the springs beyond the band [shortest, longest] × rest
    length come back into it, each spring once beyond staying held for the sub-step (an
    active set that only grows converges where one re-chosen each step flips). A spring
    between two vertices of zero inverse mass (pinned, gripped) is left alone. Returns the
    Newton steps taken."""
    spring_count = ends.shape[0]
    held = np.zeros(spring_count, dtype=np.bool_)
    stretched = np.zeros(spring_count, dtype=np.bool_)
    active = np.empty(spring_count, dtype=np.int64)
    directions = np.empty((spring_count, 3))
    violation = np.empty(spring_count)
    weights = np.empty(spring_count)
    multiplier = np.empty(spring_count)
    residual = np.empty(spring_count)
    search = np.empty(spring_count)
    product = np.empty(spring_count)
    preconditioned = np.empty(spring_count)
    gathered = np.zeros((positions.shape[0], 3))
    for step in range(NEWTON_STEPS):
        outside = False
        count = 0
        for s in range(spring_count):
            i = ends[s, 0]
            j = ends[s, 1]
            weight = inverse_mass[i] + inverse_mass[j]
            if weight == 0.0:
                continue
            edge = (positions[j, 0] - positions[i, 0], positions[j, 1] - positions[i, 1],
                    positions[j, 2] - positions[i, 2])
            length = np.sqrt(edge[0] * edge[0] + edge[1] * edge[1] + edge[2] * edge[2])
            if length < EPSILON_LENGTH:
                continue
            ratio = length / rest_length[s]
            if ratio > longest or ratio < shortest:
                outside = True
                held[s] = True
                stretched[s] = ratio > longest
            if not held[s]:
                continue
            aim = 1.0 + SLACK * (longest - 1.0) if stretched[s] \
                else 1.0 - SLACK * (1.0 - shortest)
            active[count] = s
            directions[count, 0] = edge[0] / length
            directions[count, 1] = edge[1] / length
            directions[count, 2] = edge[2] / length
            violation[count] = length - aim * rest_length[s]
            weights[count] = weight
            count += 1
        if not outside:
            return step
        # (J W Jᵀ + C) λ = violation by Jacobi-preconditioned conjugate gradients, λ₀ = 0
        norm = 0.0
        rho = 0.0
        for a in range(count):
            multiplier[a] = 0.0
            residual[a] = violation[a]
            preconditioned[a] = residual[a] / ((1.0 + COMPLIANCE) * weights[a])
            search[a] = preconditioned[a]
            rho += residual[a] * preconditioned[a]
            norm += residual[a] * residual[a]
        stop = CG_TOLERANCE * CG_TOLERANCE * norm
        for _ in range(CG_ITERATIONS):
            _schur_product(count, active, ends, directions, inverse_mass, weights, search,
                           product, gathered)
            curvature = 0.0
            for a in range(count):
                curvature += search[a] * product[a]
            if curvature <= 0.0:
                break
            alpha = rho / curvature
            left = 0.0
            for a in range(count):
                multiplier[a] += alpha * search[a]
                residual[a] -= alpha * product[a]
                left += residual[a] * residual[a]
            if left <= stop:
                break
            next_rho = 0.0
            for a in range(count):
                preconditioned[a] = residual[a] / ((1.0 + COMPLIANCE) * weights[a])
                next_rho += residual[a] * preconditioned[a]
            beta = next_rho / rho
            rho = next_rho
            for a in range(count):
                search[a] = preconditioned[a] + beta * search[a]
        # x −= W Jᵀ λ
        _transposed_product(count, active, ends, directions, multiplier, gathered)
        for v in range(positions.shape[0]):
            for axis in range(3):
                positions[v, axis] -= inverse_mass[v] * gathered[v, axis]
    return NEWTON_STEPS
