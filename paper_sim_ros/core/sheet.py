"""The sheet: vertices, triangles and springs as flat structure-of-arrays (SPEC §1).

The arrays are sized to the live mesh; damage (SPEC §4) replaces them with grown
copies between steps, which is cheap next to a step because breaks are rare events.
"""
from __future__ import annotations

from dataclasses import dataclass
import hashlib

import numpy as np

from .config import SheetConfig
from .topology import NO_VERTEX, mesh_edges

HINGE = 0
"""A triangle edge: stretch spring, breakable (§4.1), a fold hinge (§4.2)."""
BEND = 1
"""Across an interior edge, between the two vertices opposite it (paper Fig. 6)."""
AUX = 2
"""Created by damage; rest length frozen at creation; never breaks."""

UNDAMAGED = 0
"""Damage label of a vertex that no damage has touched."""
CREASED = 1
"""Damage label of a vertex at an end of an AUX spring (crease or fold memory)."""
INSERTED = 2
"""Damage label of a vertex inserted by a break (index >= the initial vertex count)."""

REFERENCE_CELL = 0.297 / 64
"""Cell size [m] at which ``SheetConfig.bend_stiffness`` applies unscaled."""


@dataclass
class Sheet:
    """Mesh and physical state of one sheet. All lengths in m, masses in kg."""

    positions: np.ndarray
    """(V, 3) float64 [m]."""
    velocities: np.ndarray
    """(V, 3) float64 [m/s]."""
    vertex_mass: np.ndarray
    """(V,) float64 [kg], a third of the rest area of each adjacent triangle × grammage."""
    pinned: np.ndarray
    """(V,) bool; pinned vertices never move (their Δv is filtered to zero)."""
    material: np.ndarray
    """(V, 2) float64 [m]: where the vertex sits on the flat sheet, origin at its centre.
    Texture coordinates follow from it, so they follow the material through damage."""
    triangles: np.ndarray
    """(T, 3) int32, counter-clockwise seen from +z on the flat sheet."""
    spring_vertices: np.ndarray
    """(S, 2) int32."""
    spring_rest_length: np.ndarray
    """(S,) float64 [m]."""
    spring_stiffness: np.ndarray
    """(S,) float64 [N/m]."""
    spring_damping: np.ndarray
    """(S,) float64 [N·s/m]."""
    spring_kind: np.ndarray
    """(S,) int8: HINGE, BEND or AUX."""
    width: float
    height: float

    @property
    def vertex_count(self) -> int:
        return int(self.positions.shape[0])

    @property
    def spring_count(self) -> int:
        return int(self.spring_vertices.shape[0])

    @property
    def total_mass(self) -> float:
        return float(self.vertex_mass.sum())

    def texture_coordinates(self) -> np.ndarray:
        """(V, 2) float32 in [0, 1]: u along x, v along y (v = 0 at the top edge)."""
        uv = np.empty((self.vertex_count, 2), dtype=np.float32)
        uv[:, 0] = self.material[:, 0] / self.width + 0.5
        uv[:, 1] = 0.5 - self.material[:, 1] / self.height
        return uv

    def strain(self, kind: int = HINGE) -> np.ndarray:
        """l / l0 - 1 of every spring of ``kind``."""
        mask = self.spring_kind == kind
        ends = self.spring_vertices[mask]
        length = np.linalg.norm(self.positions[ends[:, 1]] - self.positions[ends[:, 0]], axis=1)
        return length / self.spring_rest_length[mask] - 1.0

    def positions_sha256(self) -> str:
        return hashlib.sha256(np.ascontiguousarray(self.positions, dtype=np.float64)
                              .tobytes()).hexdigest()

    def copy(self) -> 'Sheet':
        return Sheet(**{name: (value.copy() if isinstance(value, np.ndarray) else value)
                        for name, value in self.__dict__.items()})


def grid_triangles(nx: int, ny: int) -> np.ndarray:
    """Two triangles per cell, the diagonal alternating like a checkerboard so that the
    mesh has no directional bias. Vertex (ix, iy) has index iy * nx + ix."""
    ix, iy = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    ix, iy = ix.ravel(), iy.ravel()
    v00 = iy * nx + ix
    v10 = v00 + 1
    v01 = v00 + nx
    v11 = v01 + 1
    even = (ix + iy) % 2 == 0
    # even cells split along v00-v11, odd ones along v10-v01; both counter-clockwise
    first = np.where(even[:, None], np.stack([v00, v10, v11], 1), np.stack([v00, v10, v01], 1))
    second = np.where(even[:, None], np.stack([v00, v11, v01], 1), np.stack([v10, v11, v01], 1))
    return np.concatenate([first, second]).astype(np.int32)


def lumped_mass(rest_positions: np.ndarray, triangles: np.ndarray, grammage: float) -> np.ndarray:
    """Each vertex carries a third of the rest area of its triangles × grammage."""
    corner = rest_positions[triangles]
    area = 0.5 * np.linalg.norm(
        np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]), axis=1)
    mass = np.zeros(rest_positions.shape[0])
    for k in range(3):
        np.add.at(mass, triangles[:, k], area * grammage / 3.0)
    return mass


def sheet_from_rest_shape(config: SheetConfig, rest_positions: np.ndarray,
                          material: np.ndarray, triangles: np.ndarray) -> Sheet:
    """A sheet at rest in ``rest_positions``: HINGE springs on every triangle edge and BEND
    springs across every interior edge, all rest lengths measured on that shape."""
    vertex_count = rest_positions.shape[0]
    edges, opposite = mesh_edges(triangles, vertex_count)
    interior = opposite[:, 1] != NO_VERTEX
    bend = opposite[interior]
    spring_vertices = np.concatenate([edges, bend]).astype(np.int32)
    kind = np.concatenate([np.full(len(edges), HINGE), np.full(len(bend), BEND)]).astype(np.int8)
    rest_length = np.linalg.norm(
        rest_positions[spring_vertices[:, 1]] - rest_positions[spring_vertices[:, 0]], axis=1)
    cell = min(config.width / (config.nx - 1), config.height / (config.ny - 1))
    # a BEND spring resists a fold of angle θ only to second order in θ, so its stiffness
    # must grow as the cell shrinks for the sheet to bend alike on any grid (∝ cell⁻⁴)
    bend_stiffness = config.bend_stiffness * (REFERENCE_CELL / cell) ** 4
    stiffness = np.where(kind == HINGE, config.stretch_stiffness, bend_stiffness)
    damping = np.where(kind == HINGE, config.stretch_damping, config.bend_damping)
    return Sheet(
        positions=rest_positions.astype(np.float64).copy(),
        velocities=np.zeros((vertex_count, 3)),
        vertex_mass=lumped_mass(rest_positions, triangles, config.grammage),
        pinned=np.zeros(vertex_count, dtype=bool),
        material=material.astype(np.float64).copy(),
        triangles=triangles.astype(np.int32),
        spring_vertices=spring_vertices,
        spring_rest_length=rest_length,
        spring_stiffness=stiffness.astype(np.float64),
        spring_damping=damping.astype(np.float64),
        spring_kind=kind,
        width=config.width,
        height=config.height,
    )


def grid_material(config: SheetConfig) -> np.ndarray:
    """(V, 2) flat-sheet coordinates of the grid, centred on the origin."""
    xs = np.linspace(-config.width / 2, config.width / 2, config.nx)
    ys = np.linspace(-config.height / 2, config.height / 2, config.ny)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def build_flat_sheet(config: SheetConfig) -> Sheet:
    """The flat rectangle of SPEC §1 in the plane z = ``config.elevation``."""
    material = grid_material(config)
    rest = np.column_stack([material, np.full(len(material), config.elevation)])
    return sheet_from_rest_shape(config, rest, material, grid_triangles(config.nx, config.ny))


def damage_labels(vertex_count: int, spring_vertices: np.ndarray, spring_kind: np.ndarray,
                  initial_vertex_count: int) -> np.ndarray:
    """(V,) uint16 label per vertex: INSERTED for vertices added by breaks (index at or past
    ``initial_vertex_count``: damage only appends vertices), else CREASED where an AUX
    spring ends, else UNDAMAGED."""
    if vertex_count < 0 or initial_vertex_count < 0:
        raise ValueError('vertex counts must be >= 0')
    spring_vertices = np.asarray(spring_vertices)
    spring_kind = np.asarray(spring_kind)
    if spring_vertices.shape != (spring_kind.shape[0], 2):
        raise ValueError(f'spring_vertices must be (S, 2) with S = {spring_kind.shape[0]}, '
                         f'got {spring_vertices.shape}')
    labels = np.full(vertex_count, UNDAMAGED, dtype=np.uint16)
    labels[spring_vertices[spring_kind == AUX].ravel()] = CREASED
    labels[initial_vertex_count:] = INSERTED
    return labels
