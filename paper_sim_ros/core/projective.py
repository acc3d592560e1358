"""The global step of the 'projective' solver (Liu et al. 2013, "Fast Simulation of
Mass-Spring Systems"; Bouaziz et al. 2014): implicit Euler for springs as alternating
local and global steps.

  local:  each spring's target vector d_s = its rest length × its current direction;
  global: (M/h² + Σ k_s A_sᵀ A_s) x = M y / h² + Σ k_s A_sᵀ d_s,  y = x + h v + h² f_ext / m.

Bending is solved in between (after the first iteration) with the same machinery
(core/bending.py); docs/solver.md gives the order of the passes.

The matrix depends only on masses, springs and h, so it is factorised once per mesh
change and every iteration is two sparse triangular solves: a correction reaches the
whole sheet in one iteration, where Jacobi (Eq. 6) or Gauss–Seidel sweeps move it one
vertex per sweep. That reach is what paper's stiffness needs (SPEC §2).
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from numba import njit
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg

from .kernels import EPSILON_LENGTH
from .sparse_ldl import ldl_factor


@njit(cache=True)
def local_targets(positions, weighted_inertia, spring_vertices, rest_length, weight, rhs,
                  compression_threshold=0.0):
    """The springs' part of the global step's right-hand side into ``rhs``: M y / h²
    (``weighted_inertia``) plus k_s A_sᵀ d_s for every spring. Returns, from the same
    lengths, how squeezed the springs are: Σ max(0, 1 − l/l0 − compression_threshold)."""
    flat_rhs = rhs.reshape(-1)  # element by element: numba's 2-D slice copy is 5× slower
    flat_inertia = weighted_inertia.reshape(-1)
    for k in range(flat_rhs.shape[0]):
        flat_rhs[k] = flat_inertia[k]
    excess = 0.0
    count = spring_vertices.shape[0]
    s = 0
    while s < count:
        # a vertex's springs as first end come in a run (the sheet lists them so): its
        # position and sums stay in registers, the same additions in the same order as
        # through memory, without waiting on the last store each time
        i = spring_vertices[s, 0]
        xi = positions[i, 0]
        yi = positions[i, 1]
        zi = positions[i, 2]
        sum0 = rhs[i, 0]
        sum1 = rhs[i, 1]
        sum2 = rhs[i, 2]
        while s < count and spring_vertices[s, 0] == i:
            j = spring_vertices[s, 1]
            dx = positions[j, 0] - xi
            dy = positions[j, 1] - yi
            dz = positions[j, 2] - zi
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            rest = rest_length[s]
            scale = weight[s] * rest / length if length > EPSILON_LENGTH else 0.0
            rhs[j, 0] += scale * dx
            rhs[j, 1] += scale * dy
            rhs[j, 2] += scale * dz
            sum0 -= scale * dx
            sum1 -= scale * dy
            sum2 -= scale * dz
            if length < rest:  # only a shorter spring can add to the sum
                excess += max(0.0, -(length / rest - 1.0) - compression_threshold)
            s += 1
        rhs[i, 0] = sum0
        rhs[i, 1] = sum1
        rhs[i, 2] = sum2
    return excess


@njit(cache=True)
def _solve_factored(pointer, index, value, diagonal, permutation, coupling_pointer,
                    coupling_index, coupling_value, free, rhs, positions, work):
    """positions[free] ← A⁻¹ (rhs - A_fp x_p)[free] from P A Pᵀ = L D Lᵀ, on the three
    columns at once. L (unit diagonal, held apart) is in CSC: the forward substitution
    streams it by columns, the backward one (Lᵀ) reads the same columns as rows, so the
    factor is read twice and stored once. A_fp (free rows × pinned vertices) is in CSR."""
    count = free.shape[0]
    for k in range(count):  # work = P (rhs - A_fp x_p)
        v = free[k]
        b0 = rhs[v, 0]
        b1 = rhs[v, 1]
        b2 = rhs[v, 2]
        for c in range(coupling_pointer[k], coupling_pointer[k + 1]):
            p = coupling_index[c]
            b0 -= coupling_value[c] * positions[p, 0]
            b1 -= coupling_value[c] * positions[p, 1]
            b2 -= coupling_value[c] * positions[p, 2]
        row = permutation[k]
        work[row, 0] = b0
        work[row, 1] = b1
        work[row, 2] = b2
    for column in range(count):  # L z = work
        z0 = work[column, 0]
        z1 = work[column, 1]
        z2 = work[column, 2]
        if z0 == 0.0 and z1 == 0.0 and z2 == 0.0:
            # nothing to carry: a unit right-hand side (unit_responses) reaches only the
            # columns on its elimination-tree path, a few hundred of thousands
            continue
        for p in range(pointer[column], pointer[column + 1]):
            row = index[p]
            entry = value[p]
            work[row, 0] -= entry * z0
            work[row, 1] -= entry * z1
            work[row, 2] -= entry * z2
    for column in range(count):  # D y = z
        scale = 1.0 / diagonal[column]
        work[column, 0] *= scale
        work[column, 1] *= scale
        work[column, 2] *= scale
    # Lᵀ w = y. The factor is read from its end to its start, entry by entry: read
    # backwards column by column but forwards within each, the prefetcher lost the stream
    # (129² bending: 4.2 against 2.3 ms). Two partial sums halve the chain of dependent
    # additions.
    for step in range(count):
        column = count - 1 - step
        w0 = work[column, 0]
        w1 = work[column, 1]
        w2 = work[column, 2]
        u0 = 0.0
        u1 = 0.0
        u2 = 0.0
        start = pointer[column]
        p = pointer[column + 1] - 1
        while p > start:
            row = index[p]
            entry = value[p]
            w0 -= entry * work[row, 0]
            w1 -= entry * work[row, 1]
            w2 -= entry * work[row, 2]
            row = index[p - 1]
            entry = value[p - 1]
            u0 += entry * work[row, 0]
            u1 += entry * work[row, 1]
            u2 += entry * work[row, 2]
            p -= 2
        if p == start:
            row = index[p]
            entry = value[p]
            w0 -= entry * work[row, 0]
            w1 -= entry * work[row, 1]
            w2 -= entry * work[row, 2]
        work[column, 0] = w0 - u0
        work[column, 1] = w1 - u1
        work[column, 2] = w2 - u2
    for k in range(count):  # x = Pᵀ w
        source = permutation[k]
        v = free[k]
        positions[v, 0] = work[source, 0]
        positions[v, 1] = work[source, 1]
        positions[v, 2] = work[source, 2]


def _strictly_lower(matrix) -> tuple:
    """CSC arrays of the strictly lower part of a lower-triangular matrix. The indices are
    unsigned: numba checks a signed index for a negative value on every access, and in
    the substitutions that check cost 40 % of the time (129² bending, forward: 2.37 against
    1.38 ms)."""
    matrix = matrix.tocsc()
    matrix.sort_indices()
    size = matrix.shape[0]
    column = np.repeat(np.arange(size), np.diff(matrix.indptr))
    kept = matrix.indices > column
    pointer = np.zeros(size + 1, dtype=np.uint32)
    np.cumsum(np.bincount(column[kept], minlength=size), out=pointer[1:])
    return pointer, matrix.indices[kept].astype(np.uint32), matrix.data[kept]


@njit(cache=True)
def inertial_step(positions, velocities, pinned, mass, h, air_damping, gravity,
                  weighted_inertia):
    """y = x + h (1 - h·air) v + h² g for free vertices (pinned ones stay), written into
    ``positions`` as the starting iterate, and M y / h² into ``weighted_inertia``."""
    damping = h * (1.0 - h * air_damping)
    for v in range(positions.shape[0]):
        scale = mass[v] / (h * h)
        for axis in range(3):
            if not pinned[v]:
                positions[v, axis] += damping * velocities[v, axis] + h * h * gravity[axis]
            weighted_inertia[v, axis] = scale * positions[v, axis]


def system_matrix(vertex_mass: np.ndarray,
                  stiffness: tuple[np.ndarray, np.ndarray, np.ndarray],
                  h: float) -> sparse.csr_matrix:
    """M/h² + K in CSR, K from (rows, columns, values [N/m]) whose duplicates add up."""
    vertex_count = vertex_mass.shape[0]
    rows, columns, values = stiffness
    stiffness_matrix = sparse.coo_matrix((values, (rows, columns)),
                                         shape=(vertex_count, vertex_count)).tocsr()
    return (sparse.diags(vertex_mass / (h * h)) + stiffness_matrix).tocsr()


def spring_entries(spring_vertices: np.ndarray,
                   weight: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, columns, values) of Σ k_s A_sᵀ A_s, the springs' graph Laplacian [N/m]."""
    first, second = spring_vertices[:, 0], spring_vertices[:, 1]
    return (np.concatenate([first, second, first, second]),
            np.concatenate([first, second, second, first]),
            np.concatenate([weight, weight, -weight, -weight]))


def term_entries(terms: tuple[np.ndarray, np.ndarray, np.ndarray]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, columns, values) of Σ c v vᵀ over rank-one ``terms`` = (vertices (T, W),
    values (T, W), coefficients (T,)); a zero value pads a term to the width W."""
    vertices, values, coefficients = terms
    width = vertices.shape[1]
    return (np.repeat(vertices, width, axis=1).ravel(), np.tile(vertices, (1, width)).ravel(),
            (coefficients[:, None, None] * values[:, :, None] * values[:, None, :]).ravel())


@njit(cache=True)
def _terms_fit_pattern(pointer, index, rows, entries) -> bool:
    """Whether the factor's pattern holds every term's update: the rows of a term's
    nonzero entries all lie in the column of its first row (in the factor's order). The
    pattern being closed under the elimination tree (the rows of a column less its
    parent lie in the parent's column), the update then stays inside it along the whole
    path; a term coupling two vertices the factor does not couple needs fill (a fold's
    new spring between two vertices a row apart, often)."""
    for t in range(rows.shape[0]):
        first_row = -1
        for k in range(rows.shape[1]):
            if entries[t, k] != 0.0 and (first_row < 0 or rows[t, k] < first_row):
                first_row = rows[t, k]
        for k in range(rows.shape[1]):
            row = rows[t, k]
            if entries[t, k] == 0.0 or row == first_row:
                continue
            found = False
            for q in range(pointer[first_row], pointer[first_row + 1]):
                if index[q] == row:
                    found = True
                    break
            if not found:
                return False
    return True


@njit(cache=True)
def _update_work_within(pointer, index, rows, entries, coefficients, limit) -> bool:
    """Whether _rank_one_updates of these terms reads at most ``limit`` factor entries
    (each term walks its elimination-tree path and reads every entry of the columns on
    it). Stops counting at the limit, so its own cost stays a fraction of the updates'."""
    work = 0
    for t in range(coefficients.shape[0]):
        if coefficients[t] == 0.0:
            continue
        j = -1
        for k in range(rows.shape[1]):
            if entries[t, k] != 0.0:
                j = rows[t, k] if j < 0 else min(j, rows[t, k])
        while j >= 0:
            first = pointer[j]
            last = pointer[j + 1]
            work += last - first + 1
            if work > limit:
                return False
            j = index[first] if first < last else -1
    return True


@njit(cache=True)
def _rank_one_updates(pointer, index, value, diagonal, rows, entries, coefficients, work):
    """L D Lᵀ += c v vᵀ for each term in turn (an update where c > 0, a downdate where
    c < 0: Gill, Golub, Murray & Saunders 1974, method C1), only along the elimination-tree
    path from the term's first row (Davis & Hager 1999), in the pattern as it is
    (_terms_fit_pattern). ``rows``: each term's rows in the factor's order. False where D
    would turn non-positive: the arrays are then spoilt, so they are copies."""
    for t in range(coefficients.shape[0]):
        alpha = coefficients[t]
        if alpha == 0.0:
            continue
        j = -1
        for k in range(rows.shape[1]):
            if entries[t, k] != 0.0:
                work[rows[t, k]] += entries[t, k]
                j = rows[t, k] if j < 0 else min(j, rows[t, k])
        while j >= 0:
            p = work[j]
            work[j] = 0.0
            d = diagonal[j]
            new_d = d + alpha * p * p
            if not new_d > 0.0:
                return False
            beta = p * alpha / new_d
            alpha = alpha * d / new_d
            diagonal[j] = new_d
            first = pointer[j]
            last = pointer[j + 1]
            for q in range(first, last):
                r = index[q]
                work[r] -= p * value[q]
                value[q] += beta * work[r]
            j = index[first] if first < last else -1  # the parent: rows are sorted
    return True


class GlobalStep:
    """The prefactored system M/h² + K of one mesh, pin set and sub-step length: the
    springs' global step (K = Σ k AᵀA) or the bending step (K = Q, core/bending.py)."""

    def __init__(self, vertex_mass: np.ndarray, pinned: np.ndarray,
                 stiffness: tuple[np.ndarray, np.ndarray, np.ndarray], h: float) -> None:
        """``stiffness``: (rows, columns, values [N/m]) of K (duplicates add up). Each
        coupling reaching two cells across (BEND springs, the bending step) about triples
        the factor's fill and each solve's cost: the springs' step has none."""
        self._factor(system_matrix(vertex_mass, stiffness, h), pinned)

    def _factor(self, system: sparse.csr_matrix, pinned: np.ndarray,
                previous: 'GlobalStep | None' = None) -> None:
        """Factor ``system`` with the ``pinned`` vertices held; in ``previous``'s
        elimination order where it has one (the mesh's first factor's, core/sparse_ldl.py),
        else in a new minimum degree order."""
        self.system = system
        """M/h² + K over all vertices (what an UpdatedStep compares a changed mesh's with)."""
        self.pinned_mask = pinned.copy()
        self.free = np.flatnonzero(~pinned).astype(np.int64)
        self.pinned = np.flatnonzero(pinned).astype(np.int64)
        # pinned vertices are not unknowns: their couplings go to the right-hand side
        free_rows = system[self.free]
        coupling = free_rows[:, self.pinned].tocsr()
        self._coupling = (coupling.indptr.astype(np.int64),
                          self.pinned[coupling.indices].astype(np.int64), coupling.data)
        if previous is not None and self._factor_in_order(system, previous):
            return
        reduced = free_rows[:, self.free].tocsc()
        # symmetric positive definite: no pivoting needed, minimum degree on Aᵀ + A
        factor = sparse_linalg.splu(reduced, permc_spec='MMD_AT_PLUS_A',
                                    diag_pivot_thresh=0.0,
                                    options={'SymmetricMode': True})
        # symmetric mode without pivoting permutes rows and columns alike, and then
        # U = D Lᵀ: L and U's diagonal are all a solve needs
        if not np.array_equal(factor.perm_r, factor.perm_c):
            raise RuntimeError('the global step lost its symmetric ordering')
        self._set_factors(_strictly_lower(factor.L) + (factor.U.diagonal(),
                                                       factor.perm_r.astype(np.int32)))
        rank = np.full(system.shape[0], -1, dtype=np.int64)
        rank[self.free] = factor.perm_r
        self.elimination_rank = _ranked_everywhere(rank, system)
        """Each vertex's place in the elimination order (pinned ones too, where a later
        pin set frees them): the order every factor of this mesh is made in."""
        self.ordered_entries = self.factor_entries / max(self.free.size, 1)
        """The factor's entries per unknown when its order was made."""

    def _factor_in_order(self, system: sparse.csr_matrix, previous: 'GlobalStep') -> bool:
        """Factor ``system`` on the free vertices in ``previous``'s elimination order (the
        vertices added since placed by their neighbours); False where its fill has grown
        beyond REORDER_FILL (a new order is then due), the system is not positive definite,
        or ``previous`` had more vertices (another mesh: its order would be of others)."""
        rank = previous.elimination_rank
        if rank.size > system.shape[0]:
            return False
        if rank.size < system.shape[0]:
            rank = _ranked_everywhere(np.concatenate(
                [rank, np.full(system.shape[0] - rank.size, -1, dtype=np.int64)]), system)
        order = np.argsort(rank[self.free], kind='stable')
        factors = ldl_factor(system, self.free[order], REORDER_FILL * previous.ordered_entries
                             * self.free.size)
        if factors is None:
            return False
        permutation = np.empty(order.size, dtype=np.int32)
        permutation[order] = np.arange(order.size, dtype=np.int32)
        self._set_factors(factors + (permutation,))
        self.elimination_rank = rank
        self.ordered_entries = previous.ordered_entries
        return True

    def _set_factors(self, factors: tuple) -> None:
        """(pointer, index, value, diagonal, permutation): L's strictly lower part in CSC,
        D, and each free vertex's row in the factor's order."""
        self._factors = factors
        self.factor_entries = self._factors[1].size
        self.terms_taken = 0
        """Rank-one terms the factor has taken in place since it was made (``updated``)."""
        self.stale = False
        """Whether to factor anew: once the factor has taken more than IN_PLACE_TERMS
        × its unknowns in place (UpdatedStep.stale for an UpdatedStep)."""
        self._work = np.zeros((self.free.size, 3))

    def updated(self, terms: tuple[np.ndarray, np.ndarray, np.ndarray],
                pinned: np.ndarray) -> 'GlobalStep | None':
        """This step for its system plus Σ c v vᵀ (rank-one ``terms``, term_entries: a
        fold's), its factor updated instead of made anew (_rank_one_updates): a few
        milliseconds where a factor takes tens, and the solves stay a factor's. None where
        the pins changed, a term holds a pinned vertex, or one needs an entry the factor's
        pattern lacks (UpdatedStep then answers)."""
        if not np.array_equal(pinned, self.pinned_mask):
            return None
        vertices, values, coefficients = terms
        position = np.full(pinned.size, -1, dtype=np.int64)
        pointer, index, value, diagonal, permutation = self._factors
        position[self.free] = permutation
        rows = position[vertices]
        if np.any(rows < 0) or not _terms_fit_pattern(pointer, index, rows, values) \
                or not _update_work_within(pointer, index, rows, values, coefficients,
                                           UPDATE_WORK_LIMIT * index.size):
            return None
        # updates before downdates: every matrix on the way is then positive definite
        order = np.argsort(-coefficients, kind='stable')
        value, diagonal = value.copy(), diagonal.copy()
        if not _rank_one_updates(pointer, index, value, diagonal, rows[order], values[order],
                                 coefficients[order], np.zeros(diagonal.size)):
            return None
        step = GlobalStep.__new__(GlobalStep)
        step.__dict__.update(self.__dict__)
        entry_rows, entry_columns, entries = term_entries(terms)
        step.system = self.system + sparse.coo_matrix(
            (entries, (entry_rows, entry_columns)), shape=self.system.shape).tocsr()
        step._factors = (pointer, index, value, diagonal, permutation)
        step._work = np.zeros_like(self._work)
        step.terms_taken = self.terms_taken + np.count_nonzero(coefficients)
        step.stale = step.terms_taken > IN_PLACE_TERMS * diagonal.size
        return step

    def solve(self, rhs: np.ndarray, positions: np.ndarray) -> None:
        """Overwrite the free vertices of ``positions`` with the global step's solution."""
        _solve_factored(*self._factors, *self._coupling, self.free, rhs, positions,
                        self._work)


REORDER_FILL = 1.05
"""A factor made in a mesh's kept elimination order (GlobalStep._factor_in_order) whose
entries per unknown exceed this × those of the factor the order was made for is made in a
new minimum degree order instead. Another pin set or sub-step length keeps the fill
(65² springs: 1.003 ×); the vertices breaks add, placed by their neighbours, fill more (a
crumple of 50 at 65²: 1.2 × in the bending factor), and every solve after costs that
much more: at 5 % more entries, a few seconds of solves pay for the new order."""
IN_PLACE_TERMS = 1.0
"""A factor updated in place is made anew once it has taken this many rank-one terms per
unknown: downdates lose digits (squeeze, 129²: a known x solved to 1.5e-9 after 17 190
terms; bench/bench_damage.py drift)."""
UPDATE_WORK_LIMIT = 40.0
"""A change updates a factor in place only while its terms' paths read at most this many
times the factor's entries: a factorisation costs about 85-165 times them in the
updates' time per entry read (33², 65², 129², either system), and the paths of a change
of a few thousand terms (a check that folds many hinges at once) read 490 times them:
327 ms against a new factor's 47 (squeeze, 65²). Counted, not timed: a run stays
deterministic."""
MAX_UPDATE_VERTICES = 64
"""A changed mesh reuses the last factor while its change touches at most this many
vertices (UpdatedStep); beyond, it is factored afresh."""
REFACTOR_COST = 50.0
"""A factorisation costs about this many solves (65², either system; docs/solver.md): an
UpdatedStep whose solves have paid that much extra is ``stale``, and the next change, or
the simulator at the end of the frame, factors afresh (so what updates save is never
spent twice over)."""
TOUCHED_SOLVE_SHARE = 0.3
"""One touched vertex adds this × (vertex count / factor entries) of a solve to every
solve (measured: a pass over the sheet against a factor entry's share)."""
CHANGE_TOLERANCE = 1e-12
"""Entries of two systems that differ by less than this × the largest diagonal entry are
the same (the rounding of a different summation order)."""


def _surely_touched(rows: np.ndarray, columns: np.ndarray, values: np.ndarray,
                    previous: 'GlobalStep | UpdatedStep', count: int) -> int:
    """How many vertices a change (rows, columns, values) surely touches beyond those an
    UpdatedStep ``previous`` touched already: those whose diagonal entry it moves by
    twice the tolerance (summed in any order, such a change stays beyond it). A lower
    bound on what ``UpdatedStep.changed_by`` finds, at a fraction of its cost."""
    on_diagonal = rows == columns
    diagonal_change = np.bincount(rows[on_diagonal], weights=values[on_diagonal],
                                  minlength=count)
    tolerance = 2.0 * CHANGE_TOLERANCE * np.abs(previous.system.diagonal()
                                                + diagonal_change).max()
    beyond = np.abs(diagonal_change) > tolerance
    if isinstance(previous, UpdatedStep):
        beyond[previous._touched] = False
    return int(np.count_nonzero(beyond))


def global_step(vertex_mass: np.ndarray, pinned: np.ndarray,
                stiffness: tuple[np.ndarray, np.ndarray, np.ndarray], h: float,
                previous: 'GlobalStep | UpdatedStep | None' = None
                ) -> 'GlobalStep | UpdatedStep':
    """The global step of a mesh: ``previous``'s factor updated when the mesh changed
    little since it was factored (same pins, a few vertices touched: UpdatedStep), else a
    new factor."""
    system = system_matrix(vertex_mass, stiffness, h)
    if previous is not None:
        step = UpdatedStep.of(previous, system, pinned)
        if step is not None:
            return step
    step = GlobalStep.__new__(GlobalStep)
    step._factor(system, pinned,
                 previous.base if isinstance(previous, UpdatedStep) else previous)
    return step


def _ranked_everywhere(rank: np.ndarray, system: sparse.csr_matrix) -> np.ndarray:
    """``rank`` (each vertex's place in an elimination order, -1 where it has none: a pinned
    vertex, one a break added) with every vertex placed: an unplaced vertex just before its
    earliest placed neighbour, so that it is eliminated while its neighbours are all still
    there and fills only among them, as a minimum degree order would take a vertex of
    few neighbours early. Returned as places 0 .. V-1."""
    key = rank.astype(np.float64)
    placed = rank >= 0
    for vertex in np.flatnonzero(~placed):
        neighbours = system.indices[system.indptr[vertex]:system.indptr[vertex + 1]]
        neighbours = neighbours[placed[neighbours]]
        key[vertex] = key[neighbours].min() - 0.5 if neighbours.size else key.max() + 1.0
        placed[vertex] = True
    ranked = np.empty(rank.size, dtype=np.int64)
    ranked[np.argsort(key, kind='stable')] = np.arange(rank.size)
    return ranked


class UpdatedStep:
    """A changed mesh's global step answered by an earlier factor (Woodbury's identity).
    The new system is A' = A + E Δ Eᵀ: A the factored system extended by the vertices
    added since, each on its own with the diagonal entry it first had; Δ the change on the
    touched vertices T (E selects them). With x₀ = A⁻¹ b and the columns Z = A⁻¹ E,

        x = x₀ − Z Δ x_T,   (Z_TT⁻¹ + Δ) x_T = Z_TT⁻¹ x₀_T,

    both T × T matrices symmetric positive definite (Z_TT⁻¹ + Δ is A' reduced to T). A
    break or fold touches a few vertices: their columns cost a solve per three (kept for
    the next change), instead of a factorisation; each solve then costs one pass over the
    sheet per touched vertex, so beyond MAX_UPDATE_VERTICES the mesh is factored anew."""

    @classmethod
    def of(cls, previous: 'GlobalStep | UpdatedStep', system: sparse.csr_matrix,
           pinned: np.ndarray) -> 'UpdatedStep | None':
        """``system`` answered by ``previous``'s factor, or None if it cannot be (vertices
        removed, pins changed, a pinned vertex touched, too many touched)."""
        if previous.stale:
            return None
        base = previous.base if isinstance(previous, UpdatedStep) else previous
        base_count = base.system.shape[0]
        count = system.shape[0]
        if count < base_count or np.any(pinned[base_count:]) \
                or not np.array_equal(pinned[:base_count], base.pinned_mask):
            return None
        diagonal = system.diagonal()
        known = previous.added_diagonal if isinstance(previous, UpdatedStep) \
            else np.zeros(0)
        added_diagonal = np.concatenate([known, diagonal[base_count + known.size:]])
        extended = sparse.block_diag((base.system, sparse.diags(added_diagonal)),
                                     format='csr')
        difference = (system - extended).tocoo()
        changed = np.abs(difference.data) > CHANGE_TOLERANCE * np.abs(diagonal).max()
        touched = np.unique(np.concatenate([difference.row[changed],
                                            difference.col[changed]])).astype(np.int64)
        if touched.size > MAX_UPDATE_VERTICES or np.any(pinned[touched]):
            return None
        if touched.size == 0 and count == previous.system.shape[0]:
            return previous  # the same system (pins set again, say)
        change = (system[touched][:, touched] - extended[touched][:, touched]).toarray()
        return cls(base, system, pinned, added_diagonal, touched, change,
                   previous if isinstance(previous, UpdatedStep) else None)

    @classmethod
    def changed_by(cls, previous: 'GlobalStep | UpdatedStep',
                   change: tuple[np.ndarray, np.ndarray, np.ndarray],
                   pinned: np.ndarray) -> 'GlobalStep | UpdatedStep | None':
        """``previous``'s system plus ``change`` (rows, columns, values [N/m] on the same
        vertices: a fold's few terms), answered by its factor: what ``of`` finds from the
        whole new system, without assembling it and comparing it with the factored one.
        None where ``of`` would give None."""
        count = previous.system.shape[0]
        if previous.stale or pinned.size != count \
                or not np.array_equal(pinned, previous.pinned_mask):
            return None
        rows, columns, values = change
        if _surely_touched(rows, columns, values, previous, count) > MAX_UPDATE_VERTICES:
            return None  # a yield of hundreds of patches: not worth assembling it first
        system = (previous.system + sparse.coo_matrix(
            (values, (rows, columns)), shape=(count, count)).tocsr()).tocsr()
        # the change on T since the factor: the previous update's and this one's
        updated = isinstance(previous, UpdatedStep)
        known = previous._touched if updated else np.zeros(0, dtype=np.int64)
        union = np.union1d(known, np.concatenate([rows, columns])).astype(np.int64)
        at = np.searchsorted(union, known)
        total = np.zeros((union.size, union.size))
        if updated:
            total[np.ix_(at, at)] = previous.change
        np.add.at(total, (np.searchsorted(union, rows), np.searchsorted(union, columns)),
                  values)
        beyond = np.abs(total) > CHANGE_TOLERANCE * np.abs(system.diagonal()).max()
        keep = beyond.any(axis=0) | beyond.any(axis=1)
        touched = union[keep]
        if touched.size > MAX_UPDATE_VERTICES or np.any(pinned[touched]):
            return None
        if touched.size == 0 and not updated:
            return previous  # no change beyond rounding
        base = previous.base if updated else previous
        added_diagonal = previous.added_diagonal if updated else np.zeros(0)
        return cls(base, system, pinned, added_diagonal, touched, total[np.ix_(keep, keep)],
                   previous if updated else None)

    def __init__(self, base: GlobalStep, system: sparse.csr_matrix, pinned: np.ndarray,
                 added_diagonal: np.ndarray, touched: np.ndarray, change: np.ndarray,
                 previous: 'UpdatedStep | None' = None) -> None:
        self.base = base
        self.change = change
        """Δ on the touched vertices: the system less the factored one there."""
        self.system = system
        self.pinned_mask = pinned.copy()
        self.free = np.flatnonzero(~pinned).astype(np.int64)
        self.added_diagonal = added_diagonal
        """The diagonal entry of each vertex added since ``base`` when it first appeared."""
        base_count = base.system.shape[0]
        self._added = np.arange(base_count, system.shape[0], dtype=np.int64)
        self._touched = touched
        self._extra_per_solve = TOUCHED_SOLVE_SHARE * touched.size * system.shape[0] \
            / max(base.factor_entries, 1)
        self._extra = previous._extra if previous is not None else 0.0
        """Solves' worth of work the updates cost since ``base`` was factored."""
        # Z = A⁻¹ E: the previous update's columns (A is the same; an added vertex's column
        # is zero on the vertices added after it), three more per solve of the factor
        count = system.shape[0]
        self._columns = np.zeros((touched.size, count))
        known = np.zeros(touched.size, dtype=bool)
        if previous is not None:
            row_of = np.full(count, -1)
            row_of[previous._touched] = np.arange(previous._touched.size)
            known = row_of[touched] >= 0
            self._columns[known, :previous._columns.shape[1]] = \
                previous._columns[row_of[touched[known]]]
        missing = np.flatnonzero(~known)
        self._columns[missing] = unit_responses(self._solve_extended, touched[missing], count)
        # x_T's map: Δ (Z_TT⁻¹ + Δ)⁻¹ Z_TT⁻¹, so that x = x₀ − Z (map x₀_T)
        self._map = np.empty((touched.size, touched.size))
        _woodbury_map(self._columns[:, touched], change, self._map)
        self._correction = np.empty((touched.size, 3))

    def _solve_extended(self, rhs: np.ndarray, positions: np.ndarray) -> None:
        self.base.solve(rhs, positions)
        positions[self._added] = rhs[self._added] / self.added_diagonal[:, None]

    @property
    def stale(self) -> bool:
        """The updates have cost more than a new factor would have."""
        return self._extra > REFACTOR_COST

    def solve(self, rhs: np.ndarray, positions: np.ndarray) -> None:
        """Overwrite the free vertices of ``positions`` with the changed system's solution."""
        self._extra += self._extra_per_solve
        self._solve_extended(rhs, positions)
        _apply_woodbury(self._map, self._columns, self._touched, positions, self._correction)


@njit(cache=True)
def _cholesky(matrix, lower):
    """Lower Cholesky factor of a small symmetric positive definite matrix, read from its
    lower triangle (``lower`` may be ``matrix``: in place). In numba, not LAPACK: the same
    bits on any thread count."""
    size = matrix.shape[0]
    for r in range(size):
        for c in range(r + 1):
            total = matrix[r, c]
            for k in range(c):
                total -= lower[r, k] * lower[c, k]
            if r == c:
                lower[r, r] = np.sqrt(max(total, 1e-300))
            else:
                lower[r, c] = total / lower[c, c]
        for c in range(r + 1, size):
            lower[r, c] = 0.0


@njit(cache=True)
def _cholesky_solve(lower, rhs):
    """rhs ← (G Gᵀ)⁻¹ rhs, column by column."""
    size = lower.shape[0]
    for column in range(rhs.shape[1]):
        for r in range(size):
            total = rhs[r, column]
            for k in range(r):
                total -= lower[r, k] * rhs[k, column]
            rhs[r, column] = total / lower[r, r]
        for step in range(size):
            r = size - 1 - step
            total = rhs[r, column]
            for k in range(r + 1, size):
                total -= lower[k, r] * rhs[k, column]
            rhs[r, column] = total / lower[r, r]


@njit(cache=True)
def _woodbury_map(inverse_on_touched, change, out):
    """out = Δ (Z_TT⁻¹ + Δ)⁻¹ Z_TT⁻¹ (UpdatedStep), Z_TT = ``inverse_on_touched``."""
    size = change.shape[0]
    lower = np.empty((size, size))
    _cholesky(inverse_on_touched, lower)
    reduced = np.eye(size)  # Z_TT⁻¹, then Z_TT⁻¹ + Δ
    _cholesky_solve(lower, reduced)
    inverse_term = reduced.copy()
    for r in range(size):
        for c in range(size):
            reduced[r, c] = 0.5 * (inverse_term[r, c] + inverse_term[c, r]) + change[r, c]
    _cholesky(reduced, lower)
    _cholesky_solve(lower, inverse_term)  # (Z_TT⁻¹ + Δ)⁻¹ Z_TT⁻¹
    for r in range(size):
        for c in range(size):
            total = 0.0
            for k in range(size):
                total += change[r, k] * inverse_term[k, c]
            out[r, c] = total


@njit(cache=True)
def _apply_woodbury(woodbury_map, columns, touched, positions, correction):
    """positions ← positions − Z (map · positions_T), on the three columns."""
    size = touched.shape[0]
    for r in range(size):
        for axis in range(3):
            total = 0.0
            for k in range(size):
                total += woodbury_map[r, k] * positions[touched[k], axis]
            correction[r, axis] = total
    _subtract_columns(columns, correction, np.ones(size, dtype=np.bool_), positions)


@njit(cache=True)
def _subtract_columns(columns, weight, used, positions):
    """positions ← positions − Σ_c columns[c] ⊗ weight[c] over the ``used`` columns: one
    pass over the sheet per column."""
    for c in range(columns.shape[0]):
        if not used[c]:
            continue
        w0 = weight[c, 0]
        w1 = weight[c, 1]
        w2 = weight[c, 2]
        column = columns[c]
        for v in range(positions.shape[0]):
            z = column[v]
            if z != 0.0:
                positions[v, 0] -= z * w0
                positions[v, 1] -= z * w1
                positions[v, 2] -= z * w2


def unit_responses(solve: Callable[[np.ndarray, np.ndarray], None], vertices: np.ndarray,
                   vertex_count: int) -> np.ndarray:
    """(len(vertices), V): the columns A⁻¹ e_v of ``solve`` (rhs, positions), three per
    solve (one on each axis), the pinned vertices at zero."""
    columns = np.zeros((vertices.size, vertex_count))
    unit = np.zeros((vertex_count, 3))
    response = np.zeros((vertex_count, 3))
    for start in range(0, vertices.size, 3):
        batch = vertices[start:start + 3]
        unit[:] = 0.0
        unit[batch, np.arange(batch.size)] = 1.0
        solve(unit, response)
        columns[start:start + batch.size] = response[:, :batch.size].T
    return columns


KEPT_COLUMN_ENTRIES = 8_000_000
"""Entries of the columns A⁻¹ e_v a ConstrainedSolve keeps, at most (64 MB: 1 893 columns at
65², 480 at 129²); beyond, it keeps those of the rows of the solve at hand only."""


class ConstrainedSolve:
    """A global step's solution with some vertices constrained, without a new factor: each
    constraint row r asks dᵣ · x[vᵣ] = cᵣ (a held vertex is three rows, e_x, e_y, e_z; a
    probe contact one, along its normal). For the step's system A x = b that is the KKT
    system A x + Σ λᵣ dᵣ e_vᵣ = b, so with x₀ = A⁻¹ b and the columns z_v = A⁻¹ e_v

        x = x₀ − Σᵣ λᵣ dᵣ z_vᵣ,   S λ = (dᵣ · x₀[vᵣ] − cᵣ)ᵣ,   Sᵣₛ = (dᵣ · dₛ) z_vₛ[vᵣ],

    exactly what a factor with those vertices held would give. A column costs a third of
    a solve and is kept while the factor stands, so a probe moving over the sheet pays for
    the vertices it reaches, not a factorisation per change of what it touches."""

    def __init__(self, step: GlobalStep, vertex_count: int) -> None:
        self.step = step
        self._column_of = np.full(vertex_count, -1, dtype=np.int64)
        self._columns = np.zeros((0, vertex_count))
        """Row c: z_v of the vertex whose ``_column_of`` is c (zero at pinned vertices)."""
        self._column_count = 0
        self._factored_rows: tuple = ()
        """The rows (vertex, direction arrays) whose S is factored in ``_lower``: the same
        rows come back for every iteration of a sub-step."""
        self._lower = np.zeros((0, 0))
        self._covered_rows: tuple = ()
        """(row vertices, their column indices) of the last solve: the same array comes
        back for every solve of a sub-step (only a reset of the columns forgets it)."""
        self._unconstrained: np.ndarray | None = None
        """x₀ = A⁻¹ b of the last solve (all vertices), for a solve again under other rows."""

    def missing_columns(self, vertices: np.ndarray) -> int:
        """How many of ``vertices`` (distinct) have no column yet: rows on them cost a
        third of a solve each the first time."""
        return int(np.count_nonzero(self._column_of[vertices] < 0))

    def _row_columns(self, vertices: np.ndarray) -> np.ndarray:
        """The column indices of the row ``vertices``, their columns made where missing."""
        covered = self._covered_rows
        if covered and covered[0] is vertices:  # the rule in a sub-step's iterations
            return covered[1]
        self._ensure_columns(vertices)
        self._covered_rows = (vertices, self._column_of[vertices])
        return self._covered_rows[1]

    def _ensure_columns(self, vertices: np.ndarray) -> None:
        absent = self._column_of[vertices] < 0
        if not absent.any():
            return
        missing = np.unique(vertices[absent])
        vertex_count = self._column_of.size
        if (self._column_count + missing.size) * vertex_count > KEPT_COLUMN_ENTRIES:
            # a sheet that has touched much in its time: start again from what is held now
            self._column_of[:] = -1
            self._column_count = 0
            self._factored_rows = ()
            missing = np.unique(vertices)
        needed = self._column_count + missing.size
        if needed > self._columns.shape[0]:
            grown = np.zeros((max(needed, 2 * self._columns.shape[0], 16), vertex_count))
            grown[:self._column_count] = self._columns[:self._column_count]
            self._columns = grown
        self._columns[self._column_count:needed] = unit_responses(self.step.solve, missing,
                                                                  vertex_count)
        self._column_of[missing] = np.arange(self._column_count, needed)
        self._column_count = needed

    def solve(self, rhs: np.ndarray, positions: np.ndarray, row_vertex: np.ndarray,
              row_direction: np.ndarray, row_value: np.ndarray,
              same_rhs: bool = False) -> np.ndarray:
        """Overwrite the free vertices of ``positions`` with the solution under the rows
        (vertex, unit direction, value [m]); returns the multipliers λ (one per row; a row
        pushes its vertex along its direction where λ < 0). ``same_rhs``: ``rhs`` and the
        pinned vertices are those of the last call, only the rows changed, so x₀ is the
        last call's: rows settled over several passes cost one solve, not one a pass."""
        known = self._unconstrained is not None and self._unconstrained.shape == positions.shape
        if same_rhs and known:
            np.copyto(positions, self._unconstrained)
        else:
            self.step.solve(rhs, positions)
            if not known:
                self._unconstrained = np.empty_like(positions)
            np.copyto(self._unconstrained, positions)
        if row_vertex.size == 0:
            return np.zeros(0)
        row_column = self._row_columns(row_vertex)
        rows = self._factored_rows
        if not (rows and rows[0] is row_vertex and rows[1] is row_direction):
            self._lower = np.empty((row_vertex.size, row_vertex.size))
            _factor_rows(self._columns, row_vertex, row_column, row_direction, self._lower)
            self._factored_rows = (row_vertex, row_direction)
        multipliers = np.empty(row_vertex.size)
        _constrain(self._lower, self._columns, row_vertex, row_column, row_direction,
                   row_value, positions, multipliers)
        return multipliers


@njit(cache=True)
def _factor_rows(columns, row_vertex, row_column, row_direction, lower):
    """Cholesky factor G (lower triangle of ``lower``) of S = G Gᵀ, Sᵣₛ = (dᵣ · dₛ) z_vₛ[vᵣ]
    (ConstrainedSolve): A⁻¹ seen through the rows, symmetric positive definite while no two
    rows of one vertex are parallel. In numba, not BLAS: the same bits on any thread
    count."""
    rows = row_vertex.shape[0]
    for r in range(rows):
        for s in range(r + 1):
            alignment = (row_direction[r, 0] * row_direction[s, 0]
                         + row_direction[r, 1] * row_direction[s, 1]
                         + row_direction[r, 2] * row_direction[s, 2])
            lower[r, s] = alignment * columns[row_column[s], row_vertex[r]]
    _cholesky(lower, lower)


@njit(cache=True)
def _constrain(lower, columns, row_vertex, row_column, row_direction, row_value, positions,
               multipliers):
    """x ← x − Σ λᵣ dᵣ z_vᵣ with G Gᵀ λ = d · x₀ − c (ConstrainedSolve, ``_factor_rows``)."""
    rows = row_vertex.shape[0]
    for r in range(rows):
        multipliers[r] = (row_direction[r, 0] * positions[row_vertex[r], 0]
                          + row_direction[r, 1] * positions[row_vertex[r], 1]
                          + row_direction[r, 2] * positions[row_vertex[r], 2]) - row_value[r]
    _cholesky_solve(lower, multipliers.reshape((rows, 1)))
    # one pass over the sheet per distinct column: the rows of a vertex add up first
    weight = np.zeros((columns.shape[0], 3))
    used = np.zeros(columns.shape[0], dtype=np.bool_)
    for r in range(rows):
        c = row_column[r]
        used[c] = True
        for axis in range(3):
            weight[c, axis] += multipliers[r] * row_direction[r, axis]
    _subtract_columns(columns, weight, used, positions)
