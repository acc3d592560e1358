"""Per-vertex quantities derived from the sheet arrays for publishing: damage labels and a
fallback shading. Pure numpy; no ROS types here.
"""
from __future__ import annotations

import numpy as np

from paper_sim_ros.core.sheet import AUX

UNDAMAGED = 0
"""Damage label of a vertex that no damage has touched."""
CREASED = 1
"""Damage label of a vertex at an end of an AUX spring (crease or fold memory)."""
INSERTED = 2
"""Damage label of a vertex inserted by a break (index >= the initial vertex count)."""
DAMAGE_LABEL_NAMES = {UNDAMAGED: 'undamaged', CREASED: 'creased', INSERTED: 'inserted'}

PAPER_WHITE = np.array([245.0, 243.0, 235.0])
"""Base colour of the fallback shading (0-255)."""
LIGHT_DIRECTION = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])
"""Unit direction towards the light of the fallback shading (from above, a little aside)."""
AMBIENT = 0.35
"""Share of the colour that does not depend on the light."""


def damage_labels(vertex_count: int, spring_vertices: np.ndarray, spring_kind: np.ndarray,
                  initial_vertex_count: int) -> np.ndarray:
    """(V,) uint16 label per vertex: INSERTED for vertices added by breaks (index at or past
    ``initial_vertex_count``), else CREASED where an AUX spring ends, else UNDAMAGED."""
    if vertex_count < 0 or initial_vertex_count < 0:
        raise ValueError('vertex counts must be >= 0')
    spring_vertices = np.asarray(spring_vertices)
    spring_kind = np.asarray(spring_kind)
    if spring_vertices.shape != (spring_kind.shape[0], 2):
        raise ValueError(f'spring_vertices must be (S, 2) with S = {spring_kind.shape[0]}, '
                         f'got {spring_vertices.shape}')
    labels = np.zeros(vertex_count, dtype=np.uint16)
    creased = spring_vertices[spring_kind == AUX].ravel()
    labels[creased] = CREASED
    labels[initial_vertex_count:] = INSERTED
    return labels


def lambert_colors(normals: np.ndarray, base: np.ndarray = PAPER_WHITE) -> np.ndarray:
    """(V, 3) uint8 two-sided Lambert shading of unit ``normals``: ambient plus diffuse light
    from LIGHT_DIRECTION. Used when ``paper_sim_ros.core.appearance`` is not available."""
    normals = np.asarray(normals, dtype=np.float64)
    if normals.ndim != 2 or normals.shape[1] != 3:
        raise ValueError(f'normals must be (V, 3), got {normals.shape}')
    diffuse = np.abs(normals @ LIGHT_DIRECTION)
    diffuse = np.nan_to_num(diffuse, nan=0.0, posinf=1.0, neginf=0.0)
    intensity = AMBIENT + (1.0 - AMBIENT) * np.clip(diffuse, 0.0, 1.0)
    return np.clip(intensity[:, None] * np.asarray(base)[None, :], 0, 255).astype(np.uint8)
