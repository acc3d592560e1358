"""Damage that stays: breakable hinge springs, hinge folds and random crumpling
(SPEC §4, paper §3.2–3.3, Eq. 7–8, Fig. 4–8).

- ``DamageModel`` decides, at a fixed rate in simulated time, which HINGE springs break
  (Eq. 7, drawn from a seeded generator) and which interior edges fold, and applies them.
- ``MeshEditor`` performs the mesh surgery on a ``Sheet``: the four-triangle split of a
  broken spring (Fig. 4) and the fold of a hinge (Fig. 6). It keeps the mesh a valid,
  consistently oriented triangle mesh and conserves the total mass exactly.
- ``relax`` / ``relaxed_deviation`` / ``damage_metrics``: the headless runner's measure of
  whether damage stayed (the sheet is let go and relaxes; a creased sheet stays bumpy).

Which compression Eq. 7 sees (a decision the paper, written for a soft spring mesh,
leaves open). With the 'paper' and 'explicit' solvers, springs are forces and Eq. 7 sees
the literal r = l/l0 at each check. With the 'constrained' solver HINGE springs are held
within ``max_compression`` (0.3 %) of their rest length, so l/l0 says nothing about how
hard the sheet is pushed together; and what the projection removes in a sub-step depends
on the sub-step (measured: 5× more at 1 sub-step than at 4 in the squeeze), because an
inextensible sheet has no compressive strain to speak of. So there Eq. 7 sees the
compression the probes impose: over each frame, each probe pushes some vertices by a
displacement u, of which only the part tangent to the sheet counts (the push straight
into the sheet does not compress it; its bending is what folds it, §4.2), and a HINGE
spring (i, j) is shortened by (u_i − u_j)·(x_j − x_i)/l; summed over the frames since
the last check and divided by l0, that is 1 − r. Which vertices a probe pushes:
- a probe that pinches the sheet against the table (a fingertip pressing it down, which
  grips it: ``Simulator._grip``) pushes the patch it pinches by its own travel, so the
  springs from that patch into the free sheet ahead of it take the compression. The
  patch is set by where the probe meets the table, not by how the free sheet lies
  against the probe's front: counting the vertices touching the front (the rule below)
  made a squeeze break ~1.4× as many springs with 1 sub-step as with 4 at 65² (seeds
  0–8), because with the larger step the sheet rides further up the fingertip's front;
- any other probe pushes the vertices within ``PROBE_REACH`` of it by u = max(0, Δc·n) n
  (Δc: its travel, n: the contact normal).
It is what the spring would have been compressed by had the sheet not moved out of the
way: kinematic, so it does not depend on the solver's convergence, and zero without a
moving probe, so a sheet at rest never breaks from numerical noise. The table is not a
source of damage. A break then remembers the crease as if the spring had been pushed to
l_t = max(r, ``min_crease_ratio``)·l0.
"""
from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit

from .config import DamageConfig
from .sheet import AUX, BEND, HINGE, Sheet
from .topology import check_mesh, vertex_normals

log = logging.getLogger(__name__)

MATERIAL_PRESETS: dict[str, dict[str, dict]] = {
    # (the paper's Fig. 12–13: large ψ folds like card board, small ψ bends like a bank
    # note; large φ is rubbery, small φ fragile)
    'printer_paper': {
        'sheet': {'grammage': 0.080, 'stretch_stiffness': 3.0e5, 'bend_stiffness': 2.0,
                  'bending_rigidity': 4.0e-4},
        'damage': {'fragility': 2.0, 'area_conservation': 1.0, 'fold_threshold': 0.6},
    },
    'cardboard': {
        'sheet': {'grammage': 0.300, 'stretch_stiffness': 1.5e6, 'bend_stiffness': 40.0,
                  'bending_rigidity': 1.0e-2},
        'damage': {'fragility': 1.5, 'area_conservation': 1.6, 'fold_threshold': 0.7},
    },
    'banknote': {
        'sheet': {'grammage': 0.090, 'stretch_stiffness': 4.0e5, 'bend_stiffness': 1.0,
                  'bending_rigidity': 2.0e-4},
        'damage': {'fragility': 4.0, 'area_conservation': 0.4, 'fold_threshold': 0.5},
    },
}
"""Named materials: overrides of the ``sheet`` and ``damage`` sections of a scenario."""

MAX_CREASE_FOLD = 0.95
"""A crease lifts m by at most this × l0/2 (the two halves then meet at ~36°)."""

PROBE_REACH = 1.1
"""A vertex within this × radius of a probe counts as touched by it (contact leaves touched
vertices on the sphere, give or take the stretch projection's last corrections)."""

FOLD_MIN_AREA = 0.7
"""An edge folds only while its two triangles keep this share of their flat area: a BEND
spring also comes short when the solver momentarily crushes a region under a probe, and
that is not a fold to remember."""

FLAT_BULGE = 1e-3
"""|Δn · d̂| below which the sheet counts as flat across an edge and the side is random."""


def material_preset(name: str) -> dict[str, dict]:
    """A copy of the ``sheet`` and ``damage`` overrides of a named material."""
    if name not in MATERIAL_PRESETS:
        raise ValueError(f'unknown material {name!r}; known: {", ".join(MATERIAL_PRESETS)}')
    return {section: dict(values) for section, values in MATERIAL_PRESETS[name].items()}


@njit(cache=True)
def accumulate_probe_compression(positions, normals, spring_vertices, rest_length, springs,
                                 probe_start, probe_end, probe_radius, probe_active,
                                 grip_probe, reach, compression):
    """Add to ``compression[s]`` the compression the probes' motion over one frame imposes
    on each listed spring (see the module docstring). Each vertex gets a push u, of which
    only the part in the sheet's tangent plane counts (``normals``: the sheet's unit vertex
    normals; a push straight into the sheet does not compress it):
    - a probe that pinches the sheet against the table (``grip_probe[v] == p`` for some v)
      pushes the vertices it pinches by its travel Δc;
    - any other probe pushes a vertex within ``reach`` × radius of its end centre by
      u = max(0, Δc · n) n (n: the contact normal).
    The spring (i, j) shortens by (u_i − u_j) · (x_j − x_i)/l, counted when > 0, over l0."""
    vertex_count = positions.shape[0]
    probe_count = probe_radius.shape[0]
    pinching = np.zeros(probe_count, dtype=np.bool_)
    for v in range(vertex_count):
        if grip_probe[v] >= 0:
            pinching[grip_probe[v]] = True
    push = np.zeros((vertex_count, 3))
    for p in range(probe_count):
        if not probe_active[p]:
            continue
        limit = reach * probe_radius[p]
        tx = probe_end[p, 0] - probe_start[p, 0]
        ty = probe_end[p, 1] - probe_start[p, 1]
        tz = probe_end[p, 2] - probe_start[p, 2]
        for v in range(vertex_count):
            if pinching[p]:
                if grip_probe[v] != p:
                    continue
                ux = tx
                uy = ty
                uz = tz
            else:
                dx = positions[v, 0] - probe_end[p, 0]
                dy = positions[v, 1] - probe_end[p, 1]
                dz = positions[v, 2] - probe_end[p, 2]
                distance = np.sqrt(dx * dx + dy * dy + dz * dz)
                if distance > limit or distance < 1e-12:
                    continue
                normal_travel = (tx * dx + ty * dy + tz * dz) / distance
                if normal_travel <= 0.0:
                    continue
                scale = normal_travel / distance
                ux = scale * dx
                uy = scale * dy
                uz = scale * dz
            across = ux * normals[v, 0] + uy * normals[v, 1] + uz * normals[v, 2]
            push[v, 0] += ux - across * normals[v, 0]
            push[v, 1] += uy - across * normals[v, 1]
            push[v, 2] += uz - across * normals[v, 2]
    for n in range(springs.shape[0]):
        s = springs[n]
        i = spring_vertices[s, 0]
        j = spring_vertices[s, 1]
        ux = push[i, 0] - push[j, 0]
        uy = push[i, 1] - push[j, 1]
        uz = push[i, 2] - push[j, 2]
        if ux == 0.0 and uy == 0.0 and uz == 0.0:
            continue
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        dz = positions[j, 2] - positions[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length < 1e-12:
            continue
        shortening = (ux * dx + uy * dy + uz * dz) / length
        if shortening > 0.0:
            compression[s] += shortening / rest_length[s]


def spring_lengths(positions: np.ndarray, spring_vertices: np.ndarray) -> np.ndarray:
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

    def append(self, row) -> int:
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
        ``rest_length`` (default: its length now): the fold stays."""
        self.kind.data[spring] = AUX
        self.rest_length.data[spring] = self.length(spring) if rest_length is None \
            else rest_length
        self.stiffness.data[spring] = self.aux_stiffness
        self.changed = True

    def folds_by_bending(self, spring: int, min_area_ratio: float) -> bool:
        """Whether the BEND spring (r, l) came short because its edge bends, not because the
        solver crushed its two triangles: both keep ``min_area_ratio`` of their flat area."""
        r, left = (int(x) for x in self.spring_vertices.data[spring])
        hinge = _hinge_between(self, r, left)
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


class DamageModel:
    """Breaks and folds of one simulated sheet, at ``check_rate`` in simulated time.

    ``advance`` is called once per frame, after the sub-steps, with the probes' motion in
    that frame; ``crumple`` applies random damage. ``breaks``, ``folds`` and ``creases``
    count since construction (the simulator builds a new model on reset).
    """

    def __init__(self, config: DamageConfig, seed: int, aux_stiffness: float,
                 held_inextensible: bool = False) -> None:
        """``held_inextensible``: the solver holds HINGE springs at their rest length (the
        'constrained' one), so Eq. 7 sees only the compression the probes impose."""
        self.config = config
        self.aux_stiffness = aux_stiffness
        self.held_inextensible = held_inextensible
        self.rng = np.random.default_rng([seed, 0x0DA3A6E])
        self.breaks = 0
        self.folds = 0
        self.creases: list[tuple[int, int, int]] = []
        """(i, m, j) of every break: m is the vertex inserted between i and j."""
        self.capped = False
        self._clock = 0.0
        self._pushed = np.zeros(0)

    # --------------------------------------------------------------------- observation
    def observe_probes(self, sheet: Sheet, probes, grip_probe: np.ndarray) -> None:
        """Add up the compression the probes' motion over this frame imposes on the HINGE
        springs they push (``probes``: the simulator's, with ``start`` and ``end``;
        ``grip_probe``: per vertex, the probe that pinches it against the table, or -1)."""
        if self._pushed.shape[0] != sheet.spring_count:
            self._pushed = np.zeros(sheet.spring_count)
        if not np.any(probes.active):
            return
        accumulate_probe_compression(
            sheet.positions, vertex_normals(sheet.positions, sheet.triangles),
            sheet.spring_vertices, sheet.spring_rest_length,
            np.flatnonzero(sheet.spring_kind == HINGE), probes.start, probes.end,
            probes.radius, probes.active, grip_probe, PROBE_REACH, self._pushed)

    def compression(self, sheet: Sheet) -> np.ndarray:
        """1 − r of every spring as Eq. 7 sees it (see the module docstring)."""
        if not self.held_inextensible:
            lengths = spring_lengths(sheet.positions, sheet.spring_vertices)
            return 1.0 - lengths / sheet.spring_rest_length
        if self._pushed.shape[0] == sheet.spring_count:
            return self._pushed.copy()
        return np.zeros(sheet.spring_count)

    # ------------------------------------------------------------------------ stepping
    def advance(self, sheet: Sheet, dt: float, probes, grip_probe: np.ndarray) -> bool:
        """A frame of ``dt`` has passed (``probes``: where they went in it; ``grip_probe``:
        per vertex, the probe pinching it, or -1); run the checks that fall due. Returns
        True if the mesh changed (the caller must then rebuild what derives from it)."""
        if not self.config.enabled:
            return False
        if self.held_inextensible and probes.count:
            self.observe_probes(sheet, probes, grip_probe)
        self._clock += dt * self.config.check_rate
        periods = int(math.floor(self._clock + 1e-9))
        if periods == 0:
            return False
        self._clock -= periods
        changed = self.check(sheet, periods)
        self._pushed = np.zeros(0)
        return changed

    def check(self, sheet: Sheet, periods: int = 1) -> bool:
        """One damage check (``periods`` checks' worth of probability): Eq. 7 breaks, then
        hinge folds. Returns True if the mesh changed."""
        config = self.config
        if self._at_cap(sheet.vertex_count):
            return False
        compression = self.compression(sheet)
        candidates = breakable_springs(sheet.spring_kind, sheet.spring_vertices,
                                       sheet.spring_rest_length, sheet.pinned,
                                       config.min_breakable_length)
        candidates = candidates[compression[candidates] > config.compression_floor]
        broken = np.zeros(0, dtype=np.int64)
        if candidates.size:
            probability = np.minimum(compression[candidates], 1.0) ** config.fragility
            if periods > 1:
                probability = 1.0 - (1.0 - probability) ** periods
            draw = self.rng.random(candidates.size)
            broken = candidates[draw < probability]
            # most compressed first; a stable order keeps the run reproducible
            broken = broken[np.argsort(-compression[broken], kind='stable')]
        bend = np.flatnonzero(sheet.spring_kind == BEND)
        bend_ratio = spring_lengths(sheet.positions, sheet.spring_vertices[bend]) \
            / sheet.spring_rest_length[bend]
        folding = bend[bend_ratio < config.fold_threshold]
        if broken.size == 0 and folding.size == 0:
            return False
        editor = MeshEditor(sheet, self.aux_stiffness)
        for spring in broken.tolist():
            if self._at_cap(editor.vertex_count):
                break
            # the length the spring was pushed to: 1 − c of its rest (the compression
            # Eq. 7 saw, which in a projected sheet is more than its length now shows)
            if not editor.can_break(spring, config.min_breakable_length):
                continue
            ratio = max(1.0 - float(compression[spring]), config.min_crease_ratio)
            crease = ratio * float(sheet.spring_rest_length[spring])
            editor.break_spring(spring, crease, self.rng, config.area_conservation)
            self.breaks += 1
        for spring in folding.tolist():
            if self.capped:
                break
            # a break may have moved this BEND spring's end: test it again
            threshold = config.fold_threshold * editor.rest_length.data[spring]
            if editor.kind.data[spring] == BEND and editor.length(spring) < threshold \
                    and editor.folds_by_bending(spring, FOLD_MIN_AREA):
                editor.fold(spring)
                self.folds += 1
        if editor.changed:
            editor.commit()
            self.creases += editor.creases
        return editor.changed

    def _at_cap(self, vertex_count: int) -> bool:
        if vertex_count >= self.config.max_vertices:
            if not self.capped:
                log.warning('damage stopped: the sheet reached the vertex cap of %d '
                            '(DamageConfig.max_vertices)', self.config.max_vertices)
            self.capped = True
        return self.capped

    # ------------------------------------------------------------------- random damage
    def crumple(self, sheet: Sheet, count: int, seed: int) -> int:
        """Random damage (SPEC §4.3, paper Fig. 5, 7, 8): ``count`` events on randomly
        chosen springs through the same operations, drawn from their own generator
        seeded with ``seed``. A break compresses its spring to l_t = r·l0 with r drawn in
        [min_crease_ratio, 1); a fold gives the BEND spring of an edge an AUX spring of
        rest r·d0 with r in [min_crease_ratio, fold_threshold) and lifts the edge's ends
        to a random side (a flat sheet would otherwise have no side to fold to).
        Returns the number of events applied (fewer at the vertex cap)."""
        if count < 0:
            raise ValueError(f'crumple count must be >= 0, got {count}')
        config = self.config
        rng = np.random.default_rng([seed, 0xC3C3])
        editor = MeshEditor(sheet, self.aux_stiffness)
        applied = 0
        for _ in range(count):
            if self._at_cap(editor.vertex_count):
                break
            want_fold = rng.random() < config.crumple_fold_fraction
            count_now = editor.kind.count
            kinds = editor.kind.data[:count_now]
            bend = np.flatnonzero(kinds == BEND) if want_fold else np.zeros(0)
            if bend.size:
                spring = int(bend[rng.integers(bend.size)])
                upper = max(config.fold_threshold, config.min_crease_ratio)
                ratio = rng.uniform(config.min_crease_ratio, upper)
                rest = ratio * float(editor.rest_length.data[spring])
                self._lift_hinge(editor, spring, ratio, rng)
                editor.fold(spring, rest)
                self.folds += 1
            else:
                breakable = breakable_springs(kinds, editor.spring_vertices.data[:count_now],
                                              editor.rest_length.data[:count_now],
                                              editor.pinned.data, config.min_breakable_length)
                if breakable.size == 0:
                    continue
                spring = int(breakable[rng.integers(breakable.size)])
                if not editor.can_break(spring, config.min_breakable_length):
                    continue
                ratio = rng.uniform(config.min_crease_ratio, 1.0)
                l0 = float(editor.rest_length.data[spring])
                editor.break_spring(spring, ratio * l0, rng, config.area_conservation)
                self.breaks += 1
            applied += 1
        editor.commit()
        self.creases += editor.creases
        return applied

    @staticmethod
    def _lift_hinge(editor: MeshEditor, bend_spring: int, ratio: float,
                    rng: np.random.Generator) -> None:
        """Seed a random fold: lift the hinge edge under a BEND spring (r, l) by half the
        height a clean fold to |x_r − x_l| = ratio·d0 would give it, to a random side."""
        r, left = (int(x) for x in editor.spring_vertices.data[bend_spring])
        hinge = _hinge_between(editor, r, left)
        if hinge is None:
            return
        d0 = float(editor.rest_length.data[bend_spring])
        lift = 0.25 * d0 * math.sqrt(max(1.0 - ratio * ratio, 0.0))
        side = 1.0 if rng.random() < 0.5 else -1.0
        for v in hinge:
            if not editor.pinned.data[v]:
                editor.positions.data[v] += side * lift * editor.normals.data[v]


def _hinge_between(editor: MeshEditor, r: int, left: int) -> tuple[int, int] | None:
    """The edge (a, b) with triangles (a, b, r) and (b, a, l) on its two sides."""
    triangles = editor.triangles.data[:editor.triangles.count]

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


# ----------------------------------------------------------------------- measurement
def mesh_problems(sheet: Sheet) -> list[str]:
    """Every SPEC §4.4 invariant that fails on ``sheet`` (empty: valid)."""
    return check_mesh(sheet.triangles, sheet.vertex_count, sheet.positions,
                      sheet.spring_vertices, spring_kind=sheet.spring_kind)


def ridge_heights(positions: np.ndarray, creases: list[tuple[int, int, int]]) -> np.ndarray:
    """Height of every crease's ridge vertex m over the midpoint of its ends i, j [m]."""
    if not creases:
        return np.zeros(0)
    i, m, j = np.asarray(creases, dtype=np.int64).T
    return np.linalg.norm(positions[m] - 0.5 * (positions[i] + positions[j]), axis=1)


def plane_deviation(positions: np.ndarray) -> float:
    """RMS distance of the points from their least-squares plane [m]."""
    centred = positions - positions.mean(axis=0)
    _, singular, _ = np.linalg.svd(centred, full_matrices=False)
    return float(singular[-1] / math.sqrt(len(positions)))


def relax(simulator, seconds: float = 3.0, air_damping: float = 3.0,
          jitter: float = 1e-9):
    """A free, damped copy of ``simulator`` after ``seconds`` of relaxation: gravity,
    table, probes and pins off, damage off (the damage already done stays in the mesh),
    velocities zeroed, air drag ``air_damping`` [1/s]. The original is untouched.

    The vertices start displaced by a seeded random ``jitter`` [m] out of their plane: a
    creased sheet pressed exactly flat (by the table) sits in an unstable equilibrium
    that only in-plane forces can never leave; any real disturbance lets it pop up. An
    undamaged sheet is stable when flat and the jitter dies away."""
    from dataclasses import replace
    from .simulator import Simulator
    config = simulator.config
    relaxed_config = replace(
        config,
        solver=replace(config.solver, gravity=(0.0, 0.0, 0.0), air_damping=air_damping),
        contact=replace(config.contact, ground_enabled=False),
        damage=replace(config.damage, enabled=False))
    sheet = simulator.sheet.copy()
    sheet.velocities[:] = 0.0
    sheet.pinned[:] = False
    noise = np.random.default_rng([config.seed, 0x5E7]).uniform(-1.0, 1.0, sheet.vertex_count)
    sheet.positions += jitter * noise[:, None] * vertex_normals(sheet.positions, sheet.triangles)
    relaxed = Simulator(relaxed_config, initial_sheet=sheet)
    for _ in range(int(round(seconds / config.solver.dt))):
        relaxed.step_frame()
    return relaxed


def relaxed_deviation(simulator, seconds: float = 3.0) -> float:
    """RMS distance from the best-fit plane after ``relax`` [m]: ~0 for a sheet that
    springs back flat, millimetres for one that kept its creases."""
    return plane_deviation(relax(simulator, seconds).sheet.positions)


def damage_metrics(simulator, relax_seconds: float = 3.0) -> dict:
    """Metrics of the headless runner for damage: breaks, folds, mesh validity, the
    relaxed deviation."""
    problems = mesh_problems(simulator.sheet)
    damage = getattr(simulator, 'damage', None)
    return {
        'breaks': int(damage.breaks) if damage is not None else 0,
        'folds': int(damage.folds) if damage is not None else 0,
        'mesh_valid': not problems,
        'mesh_problems': problems,
        'relaxed_deviation_m': relaxed_deviation(simulator, relax_seconds),
    }
