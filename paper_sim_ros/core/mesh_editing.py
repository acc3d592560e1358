"""Mesh surgery on a ``Sheet`` (paper §3.2–3.3, Fig. 4 and 6): the four-triangle split of
a broken HINGE spring and the fold of a hinge. ``MeshEditor`` keeps the mesh a valid,
consistently oriented triangle mesh and conserves the total mass exactly; it does not
decide what breaks or folds (that is ``core/damage.py``).
"""
from __future__ import annotations

import math

import numpy as np

from .sheet import AUX, BEND, HINGE, Sheet
from .topology import vertex_normals

MAX_CREASE_FOLD = 0.95
"""A crease lifts m by at most this × l0/2 (the two halves then meet at ~36°)."""
FLAT_FOLD_RATIO = 0.05
"""A fold pressed flat keeps its two sides this share of their flat distance apart (paper
has a thickness; a spring of zero rest length has no direction and no strain)."""
FLAT_BULGE = 1e-3
"""|Δn · d̂| below which the sheet counts as flat across an edge and the side is random."""


def spring_lengths(positions: np.ndarray, spring_vertices: np.ndarray) -> np.ndarray:
    """(S,) current length of every listed spring [m]."""
    return np.linalg.norm(positions[spring_vertices[:, 1]] - positions[spring_vertices[:, 0]],
                          axis=1)


def _cross_2d(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z of the cross product of flat (…, 2) vectors."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


class _Rows:
    """A numpy array that grows by appending rows (capacity doubling)."""

    def __init__(self, array: np.ndarray) -> None:
        self.count = array.shape[0]
        self.data = np.empty((max(16, 2 * self.count),) + array.shape[1:], dtype=array.dtype)
        self.data[:self.count] = array

    def append(self, row: object) -> int:
        if self.count == self.data.shape[0]:
            grown = np.empty((2 * self.count,) + self.data.shape[1:], dtype=self.data.dtype)
            grown[:self.count] = self.data[:self.count]
            self.data = grown
        self.data[self.count] = row
        self.count += 1
        return self.count - 1

    def array(self) -> np.ndarray:
        return self.data[:self.count].copy()


class MeshEditor:
    """Breaks and folds applied to one sheet; ``commit()`` writes the grown arrays back.

    Arrays grow by doubling; adjacency is looked up with vectorised searches when an
    operation needs it (O(mesh) numpy per operation, no Python-level maps to build), so
    opening an editor for a check that finds one fold costs next to nothing.
    """

    def __init__(self, sheet: Sheet, aux_stiffness: float) -> None:
        self.sheet = sheet
        self.aux_stiffness = aux_stiffness
        self.positions = _Rows(sheet.positions)
        self.velocities = _Rows(sheet.velocities)
        self.mass = _Rows(sheet.vertex_mass)
        self.pinned = _Rows(sheet.pinned)
        self.material = _Rows(sheet.material)
        self.triangles = _Rows(sheet.triangles)
        self.spring_vertices = _Rows(sheet.spring_vertices)
        self.rest_length = _Rows(sheet.spring_rest_length)
        self.stiffness = _Rows(sheet.spring_stiffness)
        self.damping = _Rows(sheet.spring_damping)
        self.kind = _Rows(sheet.spring_kind)
        self._normals: _Rows | None = None
        self._fan_area: _Rows | None = None
        self.changed = False
        self.creases: list[tuple[int, int, int]] = []
        """(i, m, j) of every break made by this editor: the ridge vertex between its ends."""

    @property
    def vertex_count(self) -> int:
        return self.positions.count

    @property
    def normals(self) -> _Rows:
        """Unit vertex normals (computed when first needed: a fold needs none)."""
        if self._normals is None:
            self._normals = _Rows(vertex_normals(self.positions.data[:self.positions.count],
                                                 self.triangles.data[:self.triangles.count]))
        return self._normals

    @property
    def fan_area(self) -> _Rows:
        """Material area of the triangles around each vertex (the lumping rule's fan)."""
        if self._fan_area is None:
            triangles = self.triangles.data[:self.triangles.count]
            corner = self.material.data[triangles]
            area = 0.5 * np.abs(_cross_2d(corner[:, 1] - corner[:, 0],
                                          corner[:, 2] - corner[:, 0]))
            self._fan_area = _Rows(np.bincount(triangles.ravel(), np.repeat(area, 3),
                                               minlength=self.positions.count))
        return self._fan_area

    # ------------------------------------------------------------------------- queries
    def edge_triangles(self, a: int, b: int) -> list[int]:
        """The (one or two) triangles that have the edge (a, b), in index order."""
        triangles = self.triangles.data[:self.triangles.count]
        around = np.flatnonzero((triangles[:, 0] == a) | (triangles[:, 1] == a)
                                | (triangles[:, 2] == a))
        return [int(t) for t in around if b in triangles[t]]

    def springs_between(self, a: int, b: int, kind: int) -> list[int]:
        """The springs of ``kind`` joining a and b, in index order."""
        count = self.kind.count
        ends = self.spring_vertices.data[:count]
        touching = np.flatnonzero((ends[:, 0] == a) | (ends[:, 1] == a))
        return [int(s) for s in touching
                if self.kind.data[s] == kind and b in (ends[s, 0], ends[s, 1])]

    def hinge_between(self, r: int, left: int) -> tuple[int, int] | None:
        """The edge (a, b) with triangles (a, b, r) and (b, a, l) on its two sides."""
        triangles = self.triangles.data[:self.triangles.count]

        def around(vertex: int) -> list[set[int]]:
            rows = np.flatnonzero((triangles[:, 0] == vertex) | (triangles[:, 1] == vertex)
                                  | (triangles[:, 2] == vertex))
            return [set(triangles[t].tolist()) - {vertex} for t in rows]

        far_edges = around(left)
        for edge in around(r):
            if edge in far_edges:
                a, b = sorted(edge)
                return a, b
        return None

    def length(self, spring: int) -> float:
        i, j = self.spring_vertices.data[spring]
        return float(np.linalg.norm(self.positions.data[j] - self.positions.data[i]))

    def _oriented(self, t: int, first: int, second: int) -> int | None:
        """The third corner of triangle ``t`` if it runs first → second, else None."""
        a, b, c = (int(x) for x in self.triangles.data[t])
        for u, v, w in ((a, b, c), (b, c, a), (c, a, b)):
            if u == first and v == second:
                return w
        return None

    def _add_spring(self, i: int, j: int, rest: float, stiffness: float, damping: float,
                    kind: int) -> int:
        self.rest_length.append(rest)
        self.stiffness.append(stiffness)
        self.damping.append(damping)
        self.kind.append(kind)
        return self.spring_vertices.append((i, j))

    def _rest_median(self, i: int, j: int, corner: int, base: float) -> float:
        """Rest distance from the midpoint of (i, j) to ``corner`` in the rest triangle."""
        rest = self.rest_length.data
        a = float(rest[self.springs_between(i, corner, HINGE)[0]])
        b = float(rest[self.springs_between(j, corner, HINGE)[0]])
        return 0.5 * math.sqrt(max(2.0 * a * a + 2.0 * b * b - base * base, 0.0))

    def _set_triangle(self, t: int | None, corners: tuple[int, int, int]) -> int:
        """Overwrite triangle ``t`` (or append one)."""
        if t is None:
            return self.triangles.append(corners)
        self.triangles.data[t] = corners
        return t

    def _material_area(self, a: int, b: int, c: int) -> float:
        m = self.material.data
        return 0.5 * abs(float(_cross_2d(m[b] - m[a], m[c] - m[a])))

    def _wings(self, spring: int) -> tuple[int, int, int, int | None, int, int | None]:
        """(i, j, r, l, t_r, t_l) of a HINGE spring: its ends ordered as the triangle
        t_r = (i, j, r) runs them, and the triangle t_l = (j, i, l) (None on the border)."""
        i, j = (int(x) for x in self.spring_vertices.data[spring])
        triangles = self.edge_triangles(i, j)
        right = self._oriented(triangles[0], i, j)
        if right is None:
            i, j = j, i
            right = self._oriented(triangles[0], i, j)
        t_left = triangles[1] if len(triangles) == 2 else None
        left = self._oriented(t_left, j, i) if t_left is not None else None
        return i, j, right, left, triangles[0], t_left

    def can_break(self, spring: int, min_length: float) -> bool:
        """Whether breaking ``spring`` leaves no edge shorter than ``min_length`` / 2 (the
        halves, and the medians to r and l): repeated splits must not make slivers."""
        l0 = float(self.rest_length.data[spring])
        if l0 < min_length:
            return False
        i, j, right, left, _, _ = self._wings(spring)
        return all(self._rest_median(i, j, corner, l0) >= 0.5 * min_length
                   for corner in (right, left) if corner is not None)

    # ------------------------------------------------------------------------ breaking
    def break_spring(self, spring: int, crease_length: float, rng: np.random.Generator,
                     psi: float) -> int:
        """Break HINGE ``spring`` (i, j) at crease length l_t (Fig. 4, Eq. 8); returns m.

        Inserts m at the midpoint of i, j, moved along the local normal by
        h = ψ/2·sqrt(l0² − l_t²) to the side the sheet bulges; (i, j) becomes (i, m) and
        (m, j) of rest l0/2; (m, r) and (m, l) keep the mesh a triangle mesh; an AUX spring
        (i, j) remembers the crease.

        Rest lengths (decisions the paper leaves open): (m, r) and (m, l) get the rest
        distance from the midpoint of (i, j) to r, l in the rest triangle (its median), so
        the four new triangles are the rest triangles cut in two and the crease is a
        fold about them. The AUX spring gets the rest length that puts the two halves
        exactly at rest with m at height h: sqrt(l0² − 4h²), which is l_t for ψ = 1
        (SPEC §4.1). For ψ ≠ 1 it differs from l_t on purpose: in a sheet held
        inextensible the halves always end at rest length, so an AUX spring of l_t would
        undo ψ; this way ψ sets how much of the compression the crease keeps (ψ = 0:
        none, the sheet springs back like a bank note; ψ > 1: more, like card board)."""
        i, j, right, left, t_right, t_left = self._wings(spring)
        x = self.positions.data
        xi, xj = x[i].copy(), x[j].copy()
        l0 = float(self.rest_length.data[spring])

        # local surface normal: the two faces' normals, else the vertex normals
        normal = np.cross(xj - xi, x[right] - xi)
        if left is not None:
            normal += np.cross(xi - xj, x[left] - xj)
        if np.linalg.norm(normal) < 1e-30:
            normal = self.normals.data[i] + self.normals.data[j]
        size = np.linalg.norm(normal)
        normal = normal / size if size > 1e-30 else np.array([0.0, 0.0, 1.0])
        # the side the sheet bulges: normals that spread from i to j mean a surface convex
        # towards +n (a dome seen from outside); a flat sheet gets a seeded random side
        axis = xj - xi
        axis_length = np.linalg.norm(axis)
        spread = float(np.dot(self.normals.data[j] - self.normals.data[i], axis)) \
            / max(axis_length, 1e-30)
        side = math.copysign(1.0, spread) if abs(spread) > FLAT_BULGE \
            else (1.0 if rng.random() < 0.5 else -1.0)
        height = min(0.5 * psi * math.sqrt(max(l0 * l0 - crease_length * crease_length, 0.0)),
                     0.5 * MAX_CREASE_FOLD * l0)
        xm = 0.5 * (xi + xj) + side * height * normal

        # mass: the lumping rule (a third of each triangle's area per corner) gives m
        # (A1 + A2)/3 and takes half of it from each of i and j. The amounts are rounded
        # to a power-of-two quantum above the masses' last bit, so every sum and
        # difference below is exact and the total is conserved to the last bit.
        area = self._material_area(i, j, right)
        if left is not None:
            area += self._material_area(j, i, left)
        mass = self.mass.data
        quantum = 2.0 * float(np.spacing(max(mass[i], mass[j])))
        takes = []
        for v in (i, j):
            share = min(0.5, 0.5 * area / max(self.fan_area.data[v], 1e-300))
            takes.append(round(float(mass[v]) * share / quantum) * quantum)
        mass[i] -= takes[0]
        mass[j] -= takes[1]
        mass_m = takes[0] + takes[1]
        v = self.velocities.data
        velocity = (takes[0] * v[i] + takes[1] * v[j]) / mass_m if mass_m > 0 \
            else 0.5 * (v[i] + v[j])
        self.fan_area.data[i] -= 0.5 * area
        self.fan_area.data[j] -= 0.5 * area

        m = self.positions.append(xm)
        self.velocities.append(velocity)
        self.mass.append(mass_m)
        self.pinned.append(False)
        self.material.append(0.5 * (self.material.data[i] + self.material.data[j]))
        self.normals.append(normal)
        self.fan_area.append(area)

        # springs: the two halves, the two that keep a triangle mesh, the crease memory
        stiffness = float(self.stiffness.data[spring])
        damping = float(self.damping.data[spring])
        self.spring_vertices.data[spring] = (i, m)
        self.rest_length.data[spring] = 0.5 * l0
        self._add_spring(m, j, 0.5 * l0, stiffness, damping, HINGE)
        for corner in (right, left):
            if corner is not None:
                rest = self._rest_median(i, j, corner, l0)
                self._add_spring(m, corner, rest, stiffness, damping, HINGE)
        memory = math.sqrt(max(l0 * l0 - 4.0 * height * height, 0.0))
        self._add_spring(i, j, memory, self.aux_stiffness, damping, AUX)

        # BEND springs across the four outer edges: their inner end moves to m (the one
        # across (i, j), between r and l, now serves (i, m) and (m, j) unchanged; across
        # (m, r) and (m, l) the AUX spring (i, j) is the bending memory)
        # (edges as their own triangle runs them; the far triangle runs them backwards)
        outer = [(j, right, i), (right, i, j)]
        if left is not None:
            outer += [(i, left, j), (left, j, i)]
        for a, b, old in outer:
            far = [t for t in self.edge_triangles(a, b) if t not in (t_right, t_left)]
            if far:
                across = self._oriented(far[0], b, a)
                self._retarget_bend(old, across, m)

        # triangles: (i, j, r) → (i, m, r) + (m, j, r); (j, i, l) → (j, m, l) + (m, i, l)
        self._set_triangle(t_right, (i, m, right))
        self._set_triangle(None, (m, j, right))
        if left is not None:
            self._set_triangle(t_left, (j, m, left))
            self._set_triangle(None, (m, i, left))
        self.changed = True
        self.creases.append((i, m, j))
        return m

    def _retarget_bend(self, old: int, far: int, new: int) -> None:
        """The BEND spring (old, far) becomes (new, far); its rest length scales with the
        flat (material) distance, so an aged sheet's rest shape keeps its proportions."""
        springs = self.springs_between(old, far, BEND)
        if not springs:
            return  # folded already (now AUX, kept as memory) or never had one
        s = springs[0]
        material = self.material.data
        flat_old = float(np.linalg.norm(material[far] - material[old]))
        flat_new = float(np.linalg.norm(material[far] - material[new]))
        scale = float(self.rest_length.data[s]) / flat_old if flat_old > 0 else 1.0
        self.spring_vertices.data[s] = (new, far)
        self.rest_length.data[s] = scale * flat_new

    # ------------------------------------------------------------------------- folding
    def fold(self, spring: int, rest_length: float | None = None) -> None:
        """The BEND spring across an edge becomes an AUX spring (Fig. 6) of rest length
        ``rest_length`` (default: its length now, at least FLAT_FOLD_RATIO of its rest
        length): the fold stays."""
        self.kind.data[spring] = AUX
        floor = FLAT_FOLD_RATIO * float(self.rest_length.data[spring])
        self.rest_length.data[spring] = max(
            self.length(spring) if rest_length is None else rest_length, floor)
        self.stiffness.data[spring] = self.aux_stiffness
        self.changed = True

    def folds_by_bending(self, spring: int, min_area_ratio: float) -> bool:
        """Whether the BEND spring (r, l) came short because its edge bends, not because the
        solver crushed its two triangles: both keep ``min_area_ratio`` of their flat area."""
        r, left = (int(x) for x in self.spring_vertices.data[spring])
        hinge = self.hinge_between(r, left)
        if hinge is None:
            return False
        a, b = hinge
        x = self.positions.data
        for corner in (r, left):
            area = 0.5 * float(np.linalg.norm(np.cross(x[b] - x[a], x[corner] - x[a])))
            if area < min_area_ratio * self._material_area(a, b, corner):
                return False
        return True

    # -------------------------------------------------------------------------- commit
    def commit(self) -> None:
        """Write the edited arrays back into the sheet (new arrays, so views stay valid)."""
        sheet = self.sheet
        sheet.positions = self.positions.array()
        sheet.velocities = self.velocities.array()
        sheet.vertex_mass = self.mass.array()
        sheet.pinned = self.pinned.array()
        sheet.material = self.material.array()
        sheet.triangles = self.triangles.array()
        sheet.spring_vertices = self.spring_vertices.array()
        sheet.spring_rest_length = self.rest_length.array()
        sheet.spring_stiffness = self.stiffness.array()
        sheet.spring_damping = self.damping.array()
        sheet.spring_kind = self.kind.array()


def breakable_springs(kind: np.ndarray, ends: np.ndarray, rest_length: np.ndarray,
                      pinned: np.ndarray, min_length: float) -> np.ndarray:
    """HINGE springs that may break: long enough, and not held at both ends."""
    return np.flatnonzero((kind == HINGE) & (rest_length >= min_length)
                          & ~(pinned[ends[:, 0]] & pinned[ends[:, 1]]))
