"""Plate patches: the sheet's own bending as a discrete plate (issue 14).

Hinges alone (core/bending.py) are not a plate on this grid. On its right triangles a
hinge's curvature sits on one end of its edge, so half the vertices of a row carry no
bending across that row: the discrete sheet finds grid-scale shapes that bend for less,
and a clamped strip droops 23 % too far however fine the grid (the hinge energy does not
converge here), while a twist costs twice what plate theory says. So where the sheet is
the intact grid it is built as, it bends as a plate of Poisson's ratio 0 in finite
differences over its material coordinates (u, v):

    E = ½ B Σ_vertices A_v (|x_uu|² + |x_vv|²) + ½ B Σ_cells A_c 2 |x_uv|²

x_uu and x_vv by three vertices in a line through each vertex, x_uv by the four corners of
each cell: exact for quadratic shapes, the same for any direction of bending and either
diagonal of a cell, zero for rigid motion, and no softer grid-scale shapes (a 13-point
stencil, like the biharmonic's). Each term is a fixed linear combination of positions, so
as with hinges the bending system's matrix is constant and a flat rest shape needs no local
step (Bergou et al. 2006's argument); a curved rest shape (an aged sheet) is kept in the
term's frame and turned with it (Bouaziz et al. 2014). A border vertex has the line along
the border only.

A term is a patch: its vertices, its one or two rows of coefficients, the tangents that
give its frame, its weight B A. Damage is left to hinges: a patch whose mesh pieces damage
changed (a break re-meshes them, a fold or crease ties two of its vertices) is dropped for
good, and the triangles it covered are bent by their hinges again (creases at their
reduced stiffness). Units SI.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .topology import edge_key, find_sorted, mesh_edges

FLAT_REST = 1e-6
"""Patches whose rest second derivatives [1/m] are below this everywhere rest flat: their
target is zero and skipped (the whole sheet, until it is aged or set)."""

ROWS = 2
"""Rows of a patch: x_uu and x_vv of a vertex, √2 x_uv (and nothing) of a cell."""

PATCH_WIDTH = 5
"""Most vertices of a patch: a vertex and its four neighbours along the grid's axes."""

AXIS_TOLERANCE = 1e-6
"""An edge lies along a material axis when its offset across it is below this share of
its length."""


def _second_difference(before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, ...]:
    """Coefficients (before, centre, after) of the second derivative through three vertices
    in a line, spacings ``before`` and ``after`` [m] (unequal allowed)."""
    span = before + after
    return 2.0 / (before * span), -2.0 / (before * after), 2.0 / (after * span)


def grid_patches(material: np.ndarray, triangles: np.ndarray,
                 quads: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The plate's patches of a sheet's grid: one per vertex with a neighbour along each
    material axis (its frame), with a row x_uu or x_vv where three vertices lie in a line
    along that axis through it (a border has the one along it, a corner none); one per
    cell, two triangles sharing the cell's diagonal with their four corners on a rectangle
    along the axes (row √2 x_uv).
    ``quads``: the hinges (i, j, r, l). Returns (stencil (P, PATCH_WIDTH) int64 with -1
    padding, rows (P, ROWS, PATCH_WIDTH) [1/m²], tangents (P, 2, PATCH_WIDTH) [1/m], and
    whether each patch is a cell: its stencil is then a hinge (i, j, r, l), its triangles
    (i, j, r) and (j, i, l))."""
    vertex_count = material.shape[0]
    edges, _ = mesh_edges(triangles, vertex_count)
    first, second = edges[:, 0], edges[:, 1]
    # each vertex's neighbour and spacing in the four axis directions
    neighbour = np.full((vertex_count, 4), -1, dtype=np.int64)  # -u, +u, -v, +v
    spacing = np.ones((vertex_count, 4))
    for start, end in ((first, second), (second, first)):
        offset = material[end] - material[start]
        length = np.hypot(offset[:, 0], offset[:, 1])
        for axis in (0, 1):
            along = np.abs(offset[:, 1 - axis]) <= AXIS_TOLERANCE * length
            direction = 2 * axis + (offset[:, axis] > 0)
            neighbour[start[along], direction[along]] = end[along]
            spacing[start[along], direction[along]] = length[along]
    has = neighbour >= 0
    lines = has[:, 0::2] & has[:, 1::2]  # (V, 2): a line along u, along v
    framed = has[:, 0::2] | has[:, 1::2]
    # a corner has no line: its patch only frames it, and lets its triangles be the plate's
    vertex = np.flatnonzero(framed.all(axis=1))
    count = vertex.size
    stencil = np.full((count, PATCH_WIDTH), -1, dtype=np.int64)
    rows = np.zeros((count, ROWS, PATCH_WIDTH))
    tangents = np.zeros((count, 2, PATCH_WIDTH))
    stencil[:, 0] = vertex
    # slots 1..4: -u, +u, -v, +v where they exist (a -1 slot only ever at the end)
    for p, v in enumerate(vertex.tolist()):
        slot = 1
        for axis in (0, 1):
            low, high = neighbour[v, 2 * axis], neighbour[v, 2 * axis + 1]
            low_slot = high_slot = -1
            if low >= 0:
                stencil[p, slot], low_slot = low, slot
                slot += 1
            if high >= 0:
                stencil[p, slot], high_slot = high, slot
                slot += 1
            before, after = spacing[v, 2 * axis], spacing[v, 2 * axis + 1]
            if lines[v, axis]:
                a, centre, b = _second_difference(before, after)
                rows[p, axis, low_slot] += a
                rows[p, axis, 0] += centre
                rows[p, axis, high_slot] += b
                tangents[p, axis, low_slot] -= 1.0 / (before + after)
                tangents[p, axis, high_slot] += 1.0 / (before + after)
            elif low >= 0:
                tangents[p, axis, low_slot] -= 1.0 / before
                tangents[p, axis, 0] += 1.0 / before
            else:
                tangents[p, axis, high_slot] += 1.0 / after
                tangents[p, axis, 0] -= 1.0 / after
    # cells: a hinge across a diagonal whose four corners lie on an axis rectangle
    corners = quads.astype(np.int64)
    centre = material[corners].mean(axis=1)
    relative = material[corners] - centre[:, None, :]  # (H, 4, 2)
    half = np.abs(relative)
    rectangle = (np.all(np.abs(half - half[:, :1]) <= AXIS_TOLERANCE * half[:, :1].sum(
        axis=2, keepdims=True), axis=(1, 2)) & np.all(half > 0, axis=(1, 2)))
    diagonal = np.all(np.abs(material[corners[:, 1]] - material[corners[:, 0]])
                      > AXIS_TOLERANCE * half[:, 0].sum(axis=1, keepdims=True), axis=1)
    cells = np.flatnonzero(rectangle & diagonal)
    sign = np.sign(relative[cells])  # (C, 4, 2)
    width = 2.0 * half[cells, 0]  # (C, 2): the cell's sides along u and v
    cell_rows = np.zeros((cells.size, ROWS, PATCH_WIDTH))
    cell_rows[:, 0, :4] = np.sqrt(2.0) * sign[:, :, 0] * sign[:, :, 1] / (
        width[:, 0] * width[:, 1])[:, None]
    cell_tangents = np.zeros((cells.size, 2, PATCH_WIDTH))
    cell_tangents[:, 0, :4] = sign[:, :, 0] / (2.0 * width[:, 0:1])
    cell_tangents[:, 1, :4] = sign[:, :, 1] / (2.0 * width[:, 1:2])
    cell_stencil = np.full((cells.size, PATCH_WIDTH), -1, dtype=np.int64)
    cell_stencil[:, :4] = corners[cells]
    return (np.concatenate([stencil, cell_stencil]), np.concatenate([rows, cell_rows]),
            np.concatenate([tangents, cell_tangents]),
            np.concatenate([np.zeros(count, dtype=bool), np.ones(cells.size, dtype=bool)]))


def triangle_keys(triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """An order-independent integer key per triangle."""
    ordered = np.sort(triangles.astype(np.int64), axis=1)
    return (ordered[:, 0] * vertex_count + ordered[:, 1]) * vertex_count + ordered[:, 2]


def cell_triangles(stencil: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two triangles (i, j, r) and (j, i, l) of cell patches' stencils."""
    return stencil[:, [0, 1, 2]], stencil[:, [1, 0, 3]]


def patches_standing(stencil: np.ndarray, is_cell: np.ndarray, triangles: np.ndarray,
                     vertex_count: int) -> np.ndarray:
    """Which patches still stand on the mesh of ``triangles``: a vertex patch's edges to
    its neighbours are all edges of it, a cell's two triangles are both triangles of it."""
    edges, _ = mesh_edges(triangles, vertex_count)
    edges = edge_key(edges[:, 0], edges[:, 1], vertex_count)  # sorted, unique
    centre = np.repeat(stencil[:, :1], PATCH_WIDTH - 1, axis=1)
    around = stencil[:, 1:]
    edges_present = (find_sorted(edge_key(centre, np.maximum(around, 0), vertex_count),
                                 edges)[1]
                     | (around < 0)).all(axis=1)
    keys = np.sort(triangle_keys(triangles, vertex_count))
    one, other = cell_triangles(np.maximum(stencil, 0))
    cells_present = (find_sorted(triangle_keys(one, vertex_count), keys)[1]
                     & find_sorted(triangle_keys(other, vertex_count), keys)[1])
    return np.where(is_cell, cells_present, edges_present)


assert ROWS == 2, 'the patches\' kernels write out two rows'


@njit(cache=True, inline='always')
def _stencil_sums(positions, stencil, rows, p):
    """Two rows of stencil coefficients (``rows`` (P, 2, PATCH_WIDTH): the patch's second
    derivatives [1/m], or its ``tangents``) applied to ``positions``, as six scalars (row
    0's x y z, then row 1's)."""
    s00 = s01 = s02 = 0.0
    s10 = s11 = s12 = 0.0
    for slot in range(stencil.shape[1]):
        w = stencil[p, slot]
        if w < 0:
            break
        c0 = rows[p, 0, slot]
        c1 = rows[p, 1, slot]
        x0 = positions[w, 0]
        x1 = positions[w, 1]
        x2 = positions[w, 2]
        s00 += c0 * x0
        s01 += c0 * x1
        s02 += c0 * x2
        s10 += c1 * x0
        s11 += c1 * x1
        s12 += c1 * x2
    return s00, s01, s02, s10, s11, s12


@njit(cache=True, inline='always')
def _patch_axes(positions, stencil, tangents, p):
    """The patch's frame as nine scalars: unit x_a, x_b made orthogonal to it, their
    normal. Scalars, not a small array: an array here is a heap allocation or a store and
    reload per patch, and that was most of the local step's time (65², aged)."""
    ta0, ta1, ta2, tb0, tb1, tb2 = _stencil_sums(positions, stencil, tangents, p)
    inverse = 1.0 / max(np.sqrt(ta0 * ta0 + ta1 * ta1 + ta2 * ta2), 1e-300)
    ta0 *= inverse
    ta1 *= inverse
    ta2 *= inverse
    along = tb0 * ta0 + tb1 * ta1 + tb2 * ta2
    tb0 -= along * ta0
    tb1 -= along * ta1
    tb2 -= along * ta2
    inverse = 1.0 / max(np.sqrt(tb0 * tb0 + tb1 * tb1 + tb2 * tb2), 1e-300)
    tb0 *= inverse
    tb1 *= inverse
    tb2 *= inverse
    return (ta0, ta1, ta2, tb0, tb1, tb2,
            ta1 * tb2 - ta2 * tb1, ta2 * tb0 - ta0 * tb2, ta0 * tb1 - ta1 * tb0)


@njit(cache=True)
def patch_rest_state(positions, stencil, rows, tangents, patches, rest):
    """Each patch's second derivatives at ``positions`` in its frame, into ``rest``."""
    for p in patches:
        axes = _patch_axes(positions, stencil, tangents, p)
        second = _stencil_sums(positions, stencil, rows, p)
        for k in range(ROWS):
            for row in range(3):
                rest[p, k, row] = (axes[3 * row] * second[3 * k]
                                   + axes[3 * row + 1] * second[3 * k + 1]
                                   + axes[3 * row + 2] * second[3 * k + 2])


@njit(cache=True)
def add_patch_targets(positions, stencil, rows, tangents, weight, rest, patches, rhs):
    """The local step: each listed patch's rest second derivatives turned into its current
    frame, w c R r added to ``rhs`` for its vertices. In scalars (ROWS = 2): the hot loop
    of an aged or creased sheet's sub-step (65², aged: 1.15 -> 0.81 ms a call)."""
    for p in patches:
        ta0, ta1, ta2, tb0, tb1, tb2, n0, n1, n2 = _patch_axes(
            positions, stencil, tangents, p)
        w = weight[p]
        r00, r01, r02 = w * rest[p, 0, 0], w * rest[p, 0, 1], w * rest[p, 0, 2]
        r10, r11, r12 = w * rest[p, 1, 0], w * rest[p, 1, 1], w * rest[p, 1, 2]
        t00 = r00 * ta0 + r01 * tb0 + r02 * n0
        t01 = r00 * ta1 + r01 * tb1 + r02 * n1
        t02 = r00 * ta2 + r01 * tb2 + r02 * n2
        t10 = r10 * ta0 + r11 * tb0 + r12 * n0
        t11 = r10 * ta1 + r11 * tb1 + r12 * n1
        t12 = r10 * ta2 + r11 * tb2 + r12 * n2
        for slot in range(stencil.shape[1]):
            v = stencil[p, slot]
            if v < 0:
                break
            c0 = rows[p, 0, slot]
            c1 = rows[p, 1, slot]
            rhs[v, 0] += c0 * t00 + c1 * t10
            rhs[v, 1] += c0 * t01 + c1 * t11
            rhs[v, 2] += c0 * t02 + c1 * t12


@njit(cache=True)
def patch_energy(positions, stencil, rows, tangents, weight, rest, patches):
    """Σ ½ w |x'' − R r|² over the listed patches [J]."""
    total = 0.0
    for p in patches:
        axes = _patch_axes(positions, stencil, tangents, p)
        second = _stencil_sums(positions, stencil, rows, p)
        for k in range(ROWS):
            for axis in range(3):
                turned = (rest[p, k, 0] * axes[axis] + rest[p, k, 1] * axes[3 + axis]
                          + rest[p, k, 2] * axes[6 + axis])
                total += 0.5 * weight[p] * (second[3 * k + axis] - turned) ** 2
    return total


@njit(cache=True)
def departure_bounds(positions, stencil, rows, rest, patches):
    """|x''| + |r| of each listed patch [1/m]: a bound on how far its curvature departs from
    its rest, which passes most patches over before their frames are made."""
    bounds = np.empty(patches.size)
    for index in range(patches.size):
        p = patches[index]
        second = _stencil_sums(positions, stencil, rows, p)
        total = 0.0
        for component in range(3 * ROWS):
            total += second[component] * second[component]
        resting = 0.0
        for k in range(ROWS):
            for row in range(3):
                resting += rest[p, k, row] * rest[p, k, row]
        bounds[index] = np.sqrt(total) + np.sqrt(resting)
    return bounds


@njit(cache=True)
def patches_beyond(positions, stencil, rows, tangents, rest, patches, yield_curvature):
    """Which of the listed patches are bent beyond ``yield_curvature`` [1/m]: their
    curvatures (their rows' components along their normal) depart from their rest ones by
    more than it. The rows' components in the sheet's plane are the grid stretched or
    sheared, not bent."""
    beyond = np.zeros(patches.size, dtype=np.bool_)
    for index in range(patches.size):
        p = patches[index]
        s00, s01, s02, s10, s11, s12 = _stencil_sums(positions, stencil, rows, p)
        _, _, _, _, _, _, n0, n1, n2 = _patch_axes(positions, stencil, tangents, p)
        departure_0 = n0 * s00 + n1 * s01 + n2 * s02 - rest[p, 0, 2]
        departure_1 = n0 * s10 + n1 * s11 + n2 * s12 - rest[p, 1, 2]
        beyond[index] = np.sqrt(departure_0 ** 2 + departure_1 ** 2) > yield_curvature
    return beyond


@njit(cache=True)
def patches_tying(stencil, pairs, vertex_count):
    """Which patches hold both vertices of one of ``pairs`` (a fold's or a crease's AUX
    spring): damage's, not a plate's any more."""
    # per vertex, its partners
    degree = np.zeros(vertex_count + 1, dtype=np.int64)
    for k in range(pairs.shape[0]):
        degree[pairs[k, 0] + 1] += 1
        degree[pairs[k, 1] + 1] += 1
    for v in range(vertex_count):
        degree[v + 1] += degree[v]
    partner = np.empty(degree[vertex_count], dtype=np.int64)
    filled = degree[:vertex_count].copy()
    for k in range(pairs.shape[0]):
        a, b = pairs[k, 0], pairs[k, 1]
        partner[filled[a]] = b
        filled[a] += 1
        partner[filled[b]] = a
        filled[b] += 1
    tied = np.zeros(stencil.shape[0], dtype=np.bool_)
    width = stencil.shape[1]
    for p in range(stencil.shape[0]):
        for slot in range(width):
            w = stencil[p, slot]
            if w < 0 or tied[p]:
                break
            for k in range(degree[w], degree[w + 1]):
                for other in range(width):
                    if stencil[p, other] == partner[k]:
                        tied[p] = True
                        break
    return tied


def _cross(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """z of the cross product of rows of 2-vectors."""
    return first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]


def voronoi_areas(material: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(T, 3) each corner's share of its triangle's area [m²], the mixed Voronoi areas of
    Meyer et al. 2003: the circumcentric share where the triangle is not obtuse, else half
    the area to the obtuse corner and a quarter to the others."""
    corners = material[triangles]  # (T, 3, 2)
    shares = np.empty(triangles.shape)
    area = 0.5 * np.abs(_cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    cotangents = np.empty(triangles.shape)
    squared = np.empty(triangles.shape)  # of the edge opposite each corner
    for k in range(3):
        here, after, before = corners[:, k], corners[:, (k + 1) % 3], corners[:, (k + 2) % 3]
        first, second = after - here, before - here
        cotangents[:, k] = np.sum(first * second, axis=1) / np.maximum(
            np.abs(_cross(first, second)), 1e-300)
        squared[:, k] = np.sum((before - after) ** 2, axis=1)
    for k in range(3):
        after, before = (k + 1) % 3, (k + 2) % 3
        # corner k: its two edges, each weighted by the cotangent of the angle opposite it
        shares[:, k] = (squared[:, before] * cotangents[:, before]
                        + squared[:, after] * cotangents[:, after]) / 8.0
    obtuse = cotangents < 0.0
    any_obtuse = obtuse.any(axis=1)
    shares[any_obtuse] = np.where(obtuse[any_obtuse], 0.5, 0.25) * area[any_obtuse, None]
    return shares
