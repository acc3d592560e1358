"""Bending for the 'constrained' solver (SPEC §1: "the paper is silent on bending
resistance, but paper has it").

A BEND spring resists a fold of angle θ only to second order in θ (its length changes by
O(θ²)), so it makes gentle curvature free: the sheet drapes like cloth, an aged sheet's
waviness flattens under its own weight, and a push folds the sheet locally instead of
arching it. Paper resists curvature to first order. Each interior edge (i, j) with opposite
vertices r and l (a hinge, the paper's Fig. 6) therefore carries a projective-dynamics
bending constraint (Bouaziz et al. 2014; quadratic isometric bending, Bergou et al. 2006):

    κ = Σ_v w_v x_v  (v = i, j, r, l),    E = ½ k |κ - R κ0|²,    k = B |e|² / (A_r + A_l)

with w_v = ∂θ/∂x_v · n (Bridson et al. 2003) measured where the hinge is created, so that
κ ≈ θ n for a near-flat hinge and E ≈ ½ k (θ - θ0)²; κ0 is the rest shape's κ, kept in the
hinge's own frame (edge, mean normal, their cross product) and R turns that frame to the
current one (the local step). B is the bending rigidity [N·m]; k is calibrated so that a
cylinder bent about a grid axis stores ½ B curvature² per unit area. Rest shapes: the sheet's
(flat, or the aged fractal); a hinge that damage creates or changes takes its shape at that
moment, at a tenth of the stiffness: the crease is remembered (SPEC §4), and weak. A folded
hinge (SPEC §4.2) stops bending back: its AUX spring holds it.

Hinges alone do not converge to a plate on this grid (core/patches.py says why): where the
sheet is its intact grid, plate patches bend it, and a hinge bends only the share of its
two triangles no patch covers: none on a fresh sheet, all where damage (or plastic yield)
dropped the patches.

Σ k w wᵀ = Q is constant, so the bending step (M/h² + Q) x = M y / h² + Σ k w R κ0 is
factorised once per mesh change like the springs' global step (core/projective.py), and
one solve per sub-step carries the sheet's weight by bending at once. For a flat rest
shape R κ0 = 0 and the step is exact: bending is linear in x for isometric motion.
"""
from __future__ import annotations

import copy

import numpy as np
from numba import njit

from . import patches
from .projective import term_entries
from .topology import edge_key, find_sorted

FLAT_REST = 1e-9
"""Hinges whose rest |κ0| is below this [rad] rest flat: their target is zero and skipped
(the whole sheet, until it is aged or damaged)."""

CREASE_STIFFNESS_SHARE = 0.1
"""Share of the sheet's bending stiffness left to a hinge damage created: stiffer creases
set off a cascade of folds around them (measured in docs/solver.md)."""

MAX_SHAPE_RATIO = 4.0
"""|e|² / (A_r + A_l) is capped here, and heights are floored at a quarter of the edge: a
sliver hinge left by damage does not get a stiffness out of proportion. A grid hinge has
1 (along an axis) or 2 (a diagonal)."""


def beyond_flat(rest: np.ndarray, flat: float = FLAT_REST) -> np.ndarray:
    """(N,) bool: the rows of ``rest`` (N, K) with a component beyond ``flat`` in
    magnitude. Column by column: a maximum over the rows' few entries costs ten times as
    much (0.6 ms for the hinges at 65², in each frame a hinge yields)."""
    bent = np.zeros(rest.shape[0], dtype=bool)
    for column in range(rest.shape[1]):
        bent |= np.abs(rest[:, column]) > flat
    return bent


def hinge_quads(triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """(H, 4) int32 rows (i, j, r, l), one per interior edge, with i < j, triangle (i, j, r)
    and (j, i, l) in the mesh's orientation: a canonical order, so that a hinge is
    recognised after any mesh change."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    start = np.concatenate([a, b, c]).astype(np.int64)
    end = np.concatenate([b, c, a]).astype(np.int64)
    across = np.concatenate([c, a, b]).astype(np.int64)
    forward = start < end  # the half-edge running i -> j (i < j) has r across it
    key = edge_key(start, end, vertex_count)
    forward_key, backward_key = key[forward], key[~forward]
    order = np.argsort(backward_key)
    if order.size == 0:
        return np.zeros((0, 4), dtype=np.int32)
    # the other triangle of an interior edge runs it j -> i, with l across
    position, paired = find_sorted(forward_key, backward_key[order])
    match = order[position]
    return np.column_stack([start[forward][paired], end[forward][paired],
                            across[forward][paired],
                            across[~forward][match[paired]]]).astype(np.int32)


@njit(cache=True, inline='always')
def _hinge_axes(positions, i, j, r, left):
    """The hinge's frame as scalars: unit edge (e0, e1, e2), unit mean normal (n0, n1, n2),
    their cross product (b0, b1, b2); then |e| for e = x_j − x_i and the sizes |n_r|, |n_l|
    of the area-weighted normals n_r = e × (x_r − x_i), n_l = (x_l − x_i) × e. Scalars, not
    (3, 3) arrays: stored and read back per hinge, those were most of a pass's time
    (yield_hinges on a crumpled 65² sheet: 0.58 against 0.22 ms)."""
    ex = positions[j, 0] - positions[i, 0]
    ey = positions[j, 1] - positions[i, 1]
    ez = positions[j, 2] - positions[i, 2]
    rx = positions[r, 0] - positions[i, 0]
    ry = positions[r, 1] - positions[i, 1]
    rz = positions[r, 2] - positions[i, 2]
    lx = positions[left, 0] - positions[i, 0]
    ly = positions[left, 1] - positions[i, 1]
    lz = positions[left, 2] - positions[i, 2]
    rnx = ey * rz - ez * ry
    rny = ez * rx - ex * rz
    rnz = ex * ry - ey * rx
    lnx = ly * ez - lz * ey
    lny = lz * ex - lx * ez
    lnz = lx * ey - ly * ex
    edge_length = max(np.sqrt(ex * ex + ey * ey + ez * ez), 1e-300)
    size_r = max(np.sqrt(rnx * rnx + rny * rny + rnz * rnz), 1e-300)
    size_l = max(np.sqrt(lnx * lnx + lny * lny + lnz * lnz), 1e-300)
    inverse_edge = 1.0 / edge_length
    inverse_r = 1.0 / size_r
    inverse_l = 1.0 / size_l
    e0 = ex * inverse_edge
    e1 = ey * inverse_edge
    e2 = ez * inverse_edge
    n0 = rnx * inverse_r + lnx * inverse_l
    n1 = rny * inverse_r + lny * inverse_l
    n2 = rnz * inverse_r + lnz * inverse_l
    size = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if size < 1e-6:  # folded flat on itself: the mean normal is lost; take r's
        n0 = rnx * inverse_r
        n1 = rny * inverse_r
        n2 = rnz * inverse_r
        size = 1.0
    inverse = 1.0 / size
    n0 *= inverse
    n1 *= inverse
    n2 *= inverse
    return (e0, e1, e2, n0, n1, n2, n1 * e2 - n2 * e1, n2 * e0 - n0 * e2, n0 * e1 - n1 * e0,
            edge_length, size_r, size_l)


@njit(cache=True, inline='always')
def _curvature(positions, quads, weights, h):
    """κ = Σ w_v x_v of hinge ``h`` in world coordinates."""
    kx = 0.0
    ky = 0.0
    kz = 0.0
    for corner in range(4):
        v = quads[h, corner]
        kx += weights[h, corner] * positions[v, 0]
        ky += weights[h, corner] * positions[v, 1]
        kz += weights[h, corner] * positions[v, 2]
    return kx, ky, kz


@njit(cache=True, inline='always')
def _in_frame(axes, kx, ky, kz):
    """World vector (kx, ky, kz) in the coordinates of a hinge's frame (_hinge_axes)."""
    return (axes[0] * kx + axes[1] * ky + axes[2] * kz,
            axes[3] * kx + axes[4] * ky + axes[5] * kz,
            axes[6] * kx + axes[7] * ky + axes[8] * kz)


@njit(cache=True, inline='always')
def _curvature_in_frame(positions, quads, weights, h):
    """κ of hinge ``h`` in its frame's coordinates."""
    axes = _hinge_axes(positions, quads[h, 0], quads[h, 1], quads[h, 2], quads[h, 3])
    kx, ky, kz = _curvature(positions, quads, weights, h)
    return _in_frame(axes, kx, ky, kz)


@njit(cache=True)
def hinge_rest_state(positions, quads, rigidity, weights, stiffness, rest_curvature):
    """For every hinge at ``positions``: the weights w (H, 4) [1/m], the stiffness k [N·m]
    and κ in the hinge's frame (H, 3) [rad]."""
    for h in range(quads.shape[0]):
        i, j, r, left = quads[h, 0], quads[h, 1], quads[h, 2], quads[h, 3]
        axes = _hinge_axes(positions, i, j, r, left)
        edge_length = axes[9]
        height_r = max(axes[10] / edge_length, 0.25 * edge_length)
        height_l = max(axes[11] / edge_length, 0.25 * edge_length)
        # where r and l project onto the edge, as a fraction of it
        along_r = 0.0
        along_l = 0.0
        for axis in range(3):
            along_r += (positions[r, axis] - positions[i, axis]) * axes[axis]
            along_l += (positions[left, axis] - positions[i, axis]) * axes[axis]
        along_r /= edge_length
        along_l /= edge_length
        weights[h, 0] = (1.0 - along_r) / height_r + (1.0 - along_l) / height_l
        weights[h, 1] = along_r / height_r + along_l / height_l
        weights[h, 2] = -1.0 / height_r
        weights[h, 3] = -1.0 / height_l
        ratio = 2.0 * edge_length / (height_r + height_l)  # |e|² / (A_r + A_l)
        stiffness[h] = rigidity * min(ratio, MAX_SHAPE_RATIO)
        kx, ky, kz = _curvature(positions, quads, weights, h)
        curvature = _in_frame(axes, kx, ky, kz)
        for row in range(3):
            rest_curvature[h, row] = curvature[row]


@njit(cache=True)
def hinge_shape_now(positions, quads, weights, hinges, rest_curvature):
    """κ of each of ``hinges`` at ``positions``, in its frame, into ``rest_curvature``."""
    for h in hinges:
        curvature = _curvature_in_frame(positions, quads, weights, h)
        for row in range(3):
            rest_curvature[h, row] = curvature[row]


@njit(cache=True)
def add_bending_targets(positions, quads, weights, stiffness, rest_curvature, hinges, rhs):
    """The local step: the target R κ0 of every hinge in ``hinges`` in its current frame,
    k w_v R κ0 added to ``rhs`` for its four vertices."""
    for h in hinges:
        axes = _hinge_axes(positions, quads[h, 0], quads[h, 1], quads[h, 2], quads[h, 3])
        k0 = stiffness[h] * rest_curvature[h, 0]
        k1 = stiffness[h] * rest_curvature[h, 1]
        k2 = stiffness[h] * rest_curvature[h, 2]
        for axis in range(3):
            target = k0 * axes[axis] + k1 * axes[3 + axis] + k2 * axes[6 + axis]
            for corner in range(4):
                rhs[quads[h, corner], axis] += weights[h, corner] * target


@njit(cache=True)
def bending_energy(positions, quads, weights, stiffness, rest_curvature):
    """Σ ½ k |κ - R κ0|² [J]."""
    total = 0.0
    for h in range(quads.shape[0]):
        if stiffness[h] == 0.0:  # a hinge a patch covers (all of an intact sheet's)
            continue
        curvature = _curvature_in_frame(positions, quads, weights, h)
        total += 0.5 * stiffness[h] * ((curvature[0] - rest_curvature[h, 0]) ** 2
                                       + (curvature[1] - rest_curvature[h, 1]) ** 2
                                       + (curvature[2] - rest_curvature[h, 2]) ** 2)
    return total


@njit(cache=True, inline='always')
def _edge_floor(positions, quads, h):
    """|e| of hinge ``h`` [m]: its heights are floored at a quarter of it, and so is the
    width yield_hinges gives it."""
    i = quads[h, 0]
    j = quads[h, 1]
    dx = positions[j, 0] - positions[i, 0]
    dy = positions[j, 1] - positions[i, 1]
    dz = positions[j, 2] - positions[i, 2]
    return np.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True)
def yield_hinges(positions, quads, weights, stiffness, rest_curvature, yield_curvature):
    """Perfect plasticity of bending: a hinge whose curvature κ departs from its rest κ0 by
    more than ``yield_curvature`` × its width (κ is an angle; the width turns it into a
    curvature [1/m]) has κ0 moved towards κ until it departs by just that.
    Returns how many hinges yielded."""
    yielded = 0
    for h in range(quads.shape[0]):
        if stiffness[h] == 0.0:
            continue
        # |κ − κ0| ≤ |κ| + |κ0|, and |κ| needs no frame: most hinges of a sheet bend far
        # less than the yield and are passed over at the cost of Σ w x
        kx, ky, kz = _curvature(positions, quads, weights, h)
        bound = np.sqrt(kx * kx + ky * ky + kz * kz) + np.sqrt(
            rest_curvature[h, 0] ** 2 + rest_curvature[h, 1] ** 2 + rest_curvature[h, 2] ** 2)
        if bound <= yield_curvature * 0.25 * _edge_floor(positions, quads, h):
            continue
        axes = _hinge_axes(positions, quads[h, 0], quads[h, 1], quads[h, 2], quads[h, 3])
        curvature = _in_frame(axes, kx, ky, kz)
        edge_length = axes[9]
        # the mean height of its triangles over the edge, (A_r + A_l) / |e| (each height
        # floored at |e| / 4, as for the stiffness): the angle a hinge across a cylinder of
        # unit curvature takes (test_bending checks the energy)
        width = 0.5 * (max(axes[10] / edge_length, 0.25 * edge_length)
                       + max(axes[11] / edge_length, 0.25 * edge_length))
        excess = 0.0
        for row in range(3):
            excess += (curvature[row] - rest_curvature[h, row]) ** 2
        excess = np.sqrt(excess)
        limit = yield_curvature * width
        if excess > limit:
            share = 1.0 - limit / excess
            for row in range(3):
                rest_curvature[h, row] += share * (curvature[row] - rest_curvature[h, row])
            yielded += 1
    return yielded


def _bending_entries(quads, weights, hinge_stiffness, stencil, coefficients, patch_weight
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, columns, values) of Σ k w wᵀ over hinges and Σ w c cᵀ over patches' rows (a
    patch's rows summed into one block before they are listed)."""
    rows, columns, values = term_entries(_hinge_terms(quads, weights, hinge_stiffness))
    vertex = _patch_vertices(stencil)
    patch_values = np.einsum('p,pka,pkb->pab', patch_weight, coefficients, coefficients)
    width = vertex.shape[1]
    return (np.concatenate([rows, np.repeat(vertex, width, axis=1).ravel()]),
            np.concatenate([columns, np.tile(vertex, (1, width)).ravel()]),
            np.concatenate([values, patch_values.ravel()]))


def _hinge_terms(quads, weights, stiffness) -> tuple:
    """Each hinge's k w wᵀ as a rank-one term (projective.term_entries)."""
    return quads.astype(np.int64), weights, stiffness


def _patch_vertices(stencil: np.ndarray) -> np.ndarray:
    """A patch stencil's vertices, its padding (-1) replaced by its centre (whose
    coefficients there are 0)."""
    return np.where(stencil >= 0, stencil, stencil[:, :1]).astype(np.int64)


def _patch_terms(stencil, coefficients, weight) -> tuple:
    """Each patch row's w c cᵀ as a rank-one term."""
    rows = coefficients.shape[1]
    return (np.repeat(_patch_vertices(stencil), rows, axis=0),
            coefficients.reshape(-1, coefficients.shape[2]), np.repeat(weight, rows))


def _widened(terms: tuple, width: int) -> tuple:
    """``terms`` padded to ``width`` entries each (the first vertex, a zero value)."""
    vertices, values, coefficients = terms
    pad = width - vertices.shape[1]
    if pad == 0:
        return terms
    return (np.concatenate([vertices, np.repeat(vertices[:, :1], pad, axis=1)], axis=1),
            np.concatenate([values, np.zeros((values.shape[0], pad))], axis=1), coefficients)


class SheetBending:
    """The bending state of one mesh: vertex patches where the sheet is intact
    (core/patches.py), hinges where damage changed it, their weights, stiffness and rest
    shapes. Rebuilt whenever the mesh changes; a hinge or patch that survives keeps its
    rest shape."""

    def __init__(self, positions: np.ndarray, triangles: np.ndarray, material: np.ndarray,
                 rigidity: float, fold_pairs: np.ndarray,
                 previous: 'SheetBending | None' = None, keep_stiffness: bool = False) -> None:
        """``material``: (V, 2) where each vertex sits on the flat sheet [m];
        ``fold_pairs``: (F, 2) vertex pairs of AUX springs; a hinge whose opposite
        vertices are one of them is a fold, and a patch holding both is damaged. A hinge
        that ``previous`` had, with the same opposite vertices and fold state, keeps its
        weights, stiffness and rest curvature; any other is measured now (at reset, with no
        ``previous``: the rest shape; after damage, a crease: CREASE_STIFFNESS_SHARE,
        unless ``keep_stiffness``: a copy of the same mesh). Patches are made at reset
        only; after it a patch lives on while its neighbourhood is what it was."""
        vertex_count = positions.shape[0]
        # a fold leaves the triangles as they were (most changes in a squeeze): the hinges,
        # and the pieces the patches stand on, are the previous mesh's
        same_triangles = previous is not None \
            and previous._material.shape[0] == vertex_count \
            and np.array_equal(previous._triangles, triangles)
        self.quads = previous.quads if same_triangles else hinge_quads(triangles, vertex_count)
        count = self.quads.shape[0]
        self.folded = find_sorted(
            edge_key(self.quads[:, 2], self.quads[:, 3], vertex_count),
            np.sort(edge_key(fold_pairs[:, 0], fold_pairs[:, 1], vertex_count)))[1]
        if same_triangles:
            self._carry_over_hinges(previous, positions, rigidity, keep_stiffness)
        else:
            self.weights = np.empty((count, 4))
            self.stiffness = np.empty(count)
            self.rest_curvature = np.empty((count, 3))
            hinge_rest_state(positions, self.quads, rigidity, self.weights, self.stiffness,
                             self.rest_curvature)
            if previous is not None and previous.quads.shape[0] and count:
                self._carry_over(previous, vertex_count, keep_stiffness)
        # a fold is a hinge that gave way: its AUX spring holds it (SPEC §4.2), it no
        # longer bends back
        self.stiffness[self.folded] = 0.0
        self.matrix_changed = False
        self.yield_change = None
        """When ``matrix_changed``: Q less Q before the patches yielded, as rank-one terms
        (matrix_change)."""
        self._waited = 0
        self._triangles = triangles
        self._material = np.asarray(material, dtype=np.float64)
        self._rigidity = rigidity
        self._previous_patch = None
        """Where each patch was in ``previous``'s arrays, if made from it on the same
        triangles (matrix_change)."""
        self._geometry = previous._geometry if same_triangles else self._mesh_geometry()
        """What _cover needs of the triangles alone: each one's key and corners' Voronoi
        areas, and the keys of each hinge's two triangles."""
        self._build_patches(positions, fold_pairs, previous, same_triangles)
        self._cover()

    _PATCH_ARRAYS = ('stencil', 'rows', 'tangents', 'is_cell', 'patch_rest', 'yielding')

    def _build_patches(self, positions, fold_pairs, previous, same_triangles: bool) -> None:
        vertex_count = positions.shape[0]
        if previous is None:
            self.stencil, self.rows, self.tangents, self.is_cell = patches.grid_patches(
                self._material, self._triangles, self.quads)
            self.patch_rest = np.zeros((self.stencil.shape[0], patches.ROWS, 3))
            patches.patch_rest_state(positions, self.stencil, self.rows, self.tangents,
                                     np.arange(self.stencil.shape[0]), self.patch_rest)
            self.yielding = np.zeros(self.stencil.shape[0], dtype=bool)
        else:
            # a patch lives on only on the mesh pieces it was made on, and not once it
            # yielded
            for name in self._PATCH_ARRAYS:
                setattr(self, name, getattr(previous, name))
            standing = ~self.yielding
            if not same_triangles:  # (on the same triangles, every patch still stands)
                standing &= patches.patches_standing(self.stencil, self.is_cell,
                                                     self._triangles, vertex_count)
            self._keep_patches(standing)
            if same_triangles:
                self._previous_patch = np.flatnonzero(standing)
        if fold_pairs.shape[0]:  # a fold or a crease in a patch: damage's, not a plate's
            self._keep_patches(~patches.patches_tying(self.stencil, fold_pairs.astype(np.int64),
                                                      vertex_count))

    def _keep_patches(self, kept: np.ndarray) -> None:
        for name in self._PATCH_ARRAYS:
            setattr(self, name, getattr(self, name)[kept])
        if self._previous_patch is not None:
            self._previous_patch = self._previous_patch[kept]

    def _mesh_geometry(self) -> tuple:
        triangles, vertex_count = self._triangles, self._material.shape[0]
        return (patches.triangle_keys(triangles, vertex_count),
                patches.voronoi_areas(self._material, triangles),
                tuple(patches.triangle_keys(self.quads[:, half], vertex_count)
                      for half in ([0, 1, 2], [1, 0, 3])))

    def _cover(self) -> None:
        """Who bends which triangle. A triangle is bent by patches where its corners have
        vertex patches and its cell a cell patch; each vertex patch bends its Voronoi share
        of those triangles (a third each would weigh a grid's vertices 2:1 by valence, and
        the sheet would zigzag between them), each cell patch its two triangles. A hinge
        bends the share of its two triangles that no patch covers."""
        triangles, vertex_count = self._triangles, self._material.shape[0]
        centres = self.stencil[~self.is_cell, 0]
        has_vertex_patch = np.zeros(vertex_count, dtype=bool)
        has_vertex_patch[centres] = True
        one, other = patches.cell_triangles(self.stencil[self.is_cell])
        corners = np.concatenate([one, other])
        covered_keys = np.sort(patches.triangle_keys(corners, vertex_count)[
            np.all(has_vertex_patch[corners], axis=1)])
        keys, all_corner_areas, hinge_halves = self._geometry
        covered = find_sorted(keys, covered_keys)[1]
        corner_area = all_corner_areas[covered]
        vertex_area = np.bincount(triangles[covered].ravel(), weights=corner_area.ravel(),
                                  minlength=vertex_count)
        area = np.zeros(self.stencil.shape[0])
        area[~self.is_cell] = vertex_area[centres]
        # a cell's area: its two triangles' where they are covered
        covered_keys_order = np.argsort(keys[covered])
        sorted_keys = keys[covered][covered_keys_order]
        sorted_area = corner_area.sum(axis=1)[covered_keys_order]
        cell_area = np.zeros(one.shape[0])
        for half in (one, other):
            key = patches.triangle_keys(half, vertex_count)
            at, found = find_sorted(key, sorted_keys)
            if sorted_keys.size:
                cell_area += np.where(found, sorted_area[at], 0.0)
        area[self.is_cell] = cell_area
        self.patch_weight = self._rigidity * area
        self._patches = np.flatnonzero(self.patch_weight > 0.0)
        self._curved_patches = self._patches[beyond_flat(
            self.patch_rest[self._patches].reshape(self._patches.size, patches.ROWS * 3),
            patches.FLAT_REST)]
        uncovered = sum((~find_sorted(half, covered_keys)[1]).astype(int)
                        for half in hinge_halves)
        self.hinge_share = 0.5 * uncovered
        self._hinge_stiffness = self.stiffness * self.hinge_share
        self._find_curved()

    def _find_curved(self) -> None:
        """The hinges with a bent rest and a stiffness: the only ones whose targets
        add_targets adds."""
        self._curved = np.flatnonzero(beyond_flat(self.rest_curvature)
                                      & (self._hinge_stiffness > 0.0))

    def _carry_over_hinges(self, previous: 'SheetBending', positions: np.ndarray,
                           rigidity: float, keep_stiffness: bool) -> None:
        """The hinges of the same triangles: each keeps its state but those whose fold
        state changed, which are measured now (what _carry_over gives them, at the cost of
        those few)."""
        self.weights = previous.weights.copy()
        self.stiffness = previous.stiffness.copy()
        self.rest_curvature = previous.rest_curvature.copy()
        changed = np.flatnonzero(previous.folded != self.folded)
        if changed.size:
            weights = np.empty((changed.size, 4))
            stiffness = np.empty(changed.size)
            rest_curvature = np.empty((changed.size, 3))
            hinge_rest_state(positions, self.quads[changed], rigidity, weights, stiffness,
                             rest_curvature)
            self.weights[changed] = weights
            self.stiffness[changed] = stiffness if keep_stiffness \
                else stiffness * CREASE_STIFFNESS_SHARE
            self.rest_curvature[changed] = rest_curvature

    def _carry_over(self, previous: 'SheetBending', vertex_count: int,
                    keep_stiffness: bool) -> None:
        # a hinge is known by its edge; vertex indices never change and only grow, so
        # keys over the current vertex count identify the previous mesh's edges too
        old_key = edge_key(previous.quads[:, 0], previous.quads[:, 1], vertex_count)
        new_key = edge_key(self.quads[:, 0], self.quads[:, 1], vertex_count)
        order = np.argsort(old_key)
        position, same = find_sorted(new_key, old_key[order])
        match = order[position]
        same &= np.all(previous.quads[match, 2:] == self.quads[:, 2:], axis=1) \
            & (previous.folded[match] == self.folded)
        for name in ('weights', 'stiffness', 'rest_curvature'):
            getattr(self, name)[same] = getattr(previous, name)[match[same]]
        # a hinge damage made is a crease: its fibres are broken, it bends back weakly
        if not keep_stiffness:
            self.stiffness[~same] *= CREASE_STIFFNESS_SHARE

    def matrix_entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, columns, values) [N/m] of Q = Σ k w wᵀ over the hinges and Σ w c cᵀ over
        the patches' rows."""
        return _bending_entries(self.quads, self.weights, self._hinge_stiffness,
                                self.stencil[self._patches], self.rows[self._patches],
                                self.patch_weight[self._patches])

    def matrix_change(self, previous: 'SheetBending'
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Q less ``previous``'s Q as rank-one terms (vertices (T, W), values (T, W),
        coefficients (T,) [N/m]: projective.term_entries) from the few hinges and patches
        that changed (a fold's): each changed hinge's k w wᵀ out and in again, each patch
        row's w c cᵀ for a changed or dropped patch. None unless this bending was made from
        ``previous`` on the same triangles."""
        if self._previous_patch is None or previous.quads is not self.quads:
            return None
        return self._change_from(previous, self._previous_patch)

    def _change_from(self, previous: 'SheetBending', kept: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Q less ``previous``'s Q (the same hinges; ``kept``: where each patch was in
        ``previous``'s arrays) as rank-one terms."""
        hinges = np.flatnonzero((self._hinge_stiffness != previous._hinge_stiffness)
                                | np.any(self.weights != previous.weights, axis=1))
        reweighted = np.flatnonzero(self.patch_weight != previous.patch_weight[kept])
        dropped = np.ones(previous.stencil.shape[0], dtype=bool)
        dropped[kept] = False
        dropped &= previous.patch_weight > 0.0
        old_patches = np.concatenate([kept[reweighted], np.flatnonzero(dropped)])
        parts = [_hinge_terms(self.quads[hinges], self.weights[hinges],
                              self._hinge_stiffness[hinges]),
                 _hinge_terms(previous.quads[hinges], previous.weights[hinges],
                              -previous._hinge_stiffness[hinges]),
                 _patch_terms(self.stencil[reweighted], self.rows[reweighted],
                              self.patch_weight[reweighted]),
                 _patch_terms(previous.stencil[old_patches], previous.rows[old_patches],
                              -previous.patch_weight[old_patches])]
        width = max(part[0].shape[1] for part in parts)
        return tuple(np.concatenate([_widened(part, width)[k] for part in parts])
                     for k in range(3))

    def add_targets(self, positions: np.ndarray, rhs: np.ndarray) -> None:
        """The local step's bending part of the global step's right-hand side."""
        add_bending_targets(positions, self.quads, self.weights, self._hinge_stiffness,
                            self.rest_curvature, self._curved, rhs)
        patches.add_patch_targets(positions, self.stencil, self.rows, self.tangents,
                                  self.patch_weight, self.patch_rest, self._curved_patches,
                                  rhs)

    def take_shape(self, positions: np.ndarray, vertices: np.ndarray) -> None:
        """Plastic set: the hinges and patches that hold any of ``vertices`` rest in their
        shape at ``positions`` (random damage's deformation, core/damage.py)."""
        vertex_count = positions.shape[0]
        moved = np.zeros(vertex_count, dtype=bool)
        moved[vertices] = True
        hinges = np.flatnonzero(moved[self.quads].any(axis=1))
        hinge_shape_now(positions, self.quads, self.weights, hinges, self.rest_curvature)
        stencil = self.stencil
        held = moved[np.where(stencil >= 0, stencil, 0)] & (stencil >= 0)
        patches.patch_rest_state(positions, stencil, self.rows, self.tangents,
                                 np.flatnonzero(held.any(axis=1)), self.patch_rest)
        self._cover()

    def yield_to(self, positions: np.ndarray, yield_curvature: float, batch: int = 1) -> int:
        """Plasticity: the hinges bent beyond ``yield_curvature`` [1/m] keep the excess as
        their rest shape, and a patch bent beyond it is damage: dropped for good, its
        triangles bent by their hinges from then on (which yield in turn). Dropping patches
        changes the bending system, so they are dropped together once ``batch`` calls have
        passed since the first of them yielded. Returns how many hinges and patches
        yielded; ``matrix_changed`` tells whether patches were dropped (the bending system
        must then be factorised again)."""
        bound = patches.departure_bounds(positions, self.stencil, self.rows, self.patch_rest,
                                         self._patches)
        candidates = self._patches[bound > yield_curvature]
        beyond = patches.patches_beyond(positions, self.stencil, self.rows, self.tangents,
                                        self.patch_rest, candidates, yield_curvature)
        self.yielding[candidates[beyond]] = True
        self._waited = self._waited + 1 if self.yielding.any() else 0
        self.matrix_changed = self._waited >= batch
        if self.matrix_changed:
            # the system as factored: _keep_patches and _cover make new arrays, not change
            # these; the change is a few patches' and hinges' terms, which the factor can
            # take in place (a new factor: 44 ms at 65²)
            factored = copy.copy(self)
            kept = np.flatnonzero(~self.yielding)
            self._keep_patches(~self.yielding)
            self._cover()
            self.yield_change = self._change_from(factored, kept)
            self._waited = 0
        yielded = int(yield_hinges(positions, self.quads, self.weights,
                                   self._hinge_stiffness, self.rest_curvature,
                                   yield_curvature))
        if yielded:
            self._find_curved()
        return yielded + int(beyond.sum())

    def energy(self, positions: np.ndarray) -> float:
        """Σ ½ k |κ - R κ0|² over the hinges and ½ w |x'' − R r|² over the patches [J]."""
        return float(bending_energy(positions, self.quads, self.weights,
                                    self._hinge_stiffness, self.rest_curvature)
                     + patches.patch_energy(positions, self.stencil, self.rows, self.tangents,
                                            self.patch_weight, self.patch_rest,
                                            self._patches))
