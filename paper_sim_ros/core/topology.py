"""Triangle-mesh topology: edges, their opposite vertices, and validity checks (SPEC §4.4).

numpy, and one numba kernel (vertex normals, needed every frame by damage and display);
used when a sheet is built and whenever damage changes the mesh.
"""
from __future__ import annotations

import numpy as np
from numba import njit

NO_VERTEX = -1
"""Marks the missing opposite vertex of a border edge (topology tables only, never kernels)."""


def edge_key(first: np.ndarray, second: np.ndarray, vertex_count: int) -> np.ndarray:
    """An order-independent integer key per undirected edge."""
    low = np.minimum(first, second).astype(np.int64)
    high = np.maximum(first, second).astype(np.int64)
    return low * vertex_count + high


def find_sorted(keys: np.ndarray, sorted_reference: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(at, found): where each of ``keys`` is in ``sorted_reference`` (ascending; ``at`` is
    clamped into it) and whether it is there. The one look-up of keys (edges, triangles)
    a mesh change makes: also np.isin without sorting the keys (2.4 against 0.9 ms for
    8 000 of them)."""
    at = np.minimum(np.searchsorted(sorted_reference, keys), max(sorted_reference.size - 1, 0))
    if sorted_reference.size == 0:
        return at, np.zeros(np.shape(keys), dtype=bool)
    return at, sorted_reference[at] == keys


def two_edge_path_lengths(pairs: np.ndarray, edges: np.ndarray, lengths: np.ndarray,
                          vertex_count: int) -> np.ndarray:
    """(P,) for each vertex pair (a, b) of ``pairs``: the shortest length of a path a–k–b
    over two of ``edges`` (E, 2) of ``lengths`` (E,); inf where none exists."""
    source = np.concatenate([edges[:, 0], edges[:, 1]]).astype(np.int64)
    target = np.concatenate([edges[:, 1], edges[:, 0]]).astype(np.int64)
    weight = np.concatenate([lengths, lengths])
    order = np.argsort(source, kind='stable')
    target, weight = target[order], weight[order]
    start = np.concatenate([[0], np.cumsum(np.bincount(source, minlength=vertex_count))])
    first = pairs[:, 0].astype(np.int64)
    degree = start[first + 1] - start[first]
    pair = np.repeat(np.arange(pairs.shape[0]), degree)
    slot = np.repeat(start[first] - np.cumsum(degree) + degree, degree) + np.arange(pair.size)
    middle, first_leg = target[slot], weight[slot]
    keys = edge_key(edges[:, 0], edges[:, 1], vertex_count)
    key_order = np.argsort(keys)
    wanted = edge_key(middle, pairs[pair, 1], vertex_count)
    at, found = find_sorted(wanted, keys[key_order])
    shortest = np.full(pairs.shape[0], np.inf)
    np.minimum.at(shortest, pair[found], first_leg[found] + lengths[key_order][at][found])
    return shortest


def mesh_edges(triangles: np.ndarray, vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges of a triangle mesh and their opposite vertices.

    Returns ``edges`` (E, 2) int32 with ``edges[:, 0] < edges[:, 1]`` and ``opposite``
    (E, 2) int32: the vertex opposite the edge in its first and second triangle,
    ``NO_VERTEX`` in the second column for a border edge. Raises ``ValueError`` if an
    edge has more than two triangles (non-manifold).
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    first = np.concatenate([a, b, c])
    second = np.concatenate([b, c, a])
    across = np.concatenate([c, a, b])
    keys = edge_key(first, second, vertex_count)
    order = np.argsort(keys, kind='stable')
    keys_sorted = keys[order]
    unique_keys, starts, counts = np.unique(keys_sorted, return_index=True, return_counts=True)
    if counts.size and counts.max() > 2:
        raise ValueError('non-manifold mesh: an edge has more than two triangles')
    edges = np.empty((unique_keys.size, 2), dtype=np.int32)
    edges[:, 0] = unique_keys // vertex_count
    edges[:, 1] = unique_keys % vertex_count
    opposite = np.full((unique_keys.size, 2), NO_VERTEX, dtype=np.int32)
    opposite[:, 0] = across[order[starts]]
    interior = counts == 2
    opposite[interior, 1] = across[order[starts[interior] + 1]]
    return edges, opposite


def vertex_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(V, 3) area-weighted unit vertex normals (unit +z where a vertex has no area)."""
    normals = np.empty((positions.shape[0], 3))
    _unit_vertex_normals(np.ascontiguousarray(positions, dtype=np.float64),
                         np.ascontiguousarray(triangles), normals)
    return normals


@njit(cache=True)
def spring_end_points(positions, spring_vertices, spring_kind, kind):
    """The two ends of every spring of ``kind``, in the springs' order, as float32 points
    (2 S, 3): what a display draws as line segments, gathered in one pass (numpy's select,
    gather and cast: 0.8 ms for a 65² sheet's HINGE springs, a Rerun frame's largest part)."""
    count = 0
    for spring in range(spring_kind.shape[0]):
        if spring_kind[spring] == kind:
            count += 1
    points = np.empty((2 * count, 3), dtype=np.float32)
    row = 0
    for spring in range(spring_kind.shape[0]):
        if spring_kind[spring] != kind:
            continue
        for end in range(2):
            vertex = spring_vertices[spring, end]
            for axis in range(3):
                points[row, axis] = positions[vertex, axis]
            row += 1
    return points


@njit(cache=True)
def _unit_vertex_normals(positions, triangles, normals):
    """Area-weighted unit vertex normals into ``normals`` (+z where a vertex has no area)."""
    normals[:, :] = 0.0
    for t in range(triangles.shape[0]):
        a = triangles[t, 0]
        b = triangles[t, 1]
        c = triangles[t, 2]
        ux = positions[b, 0] - positions[a, 0]
        uy = positions[b, 1] - positions[a, 1]
        uz = positions[b, 2] - positions[a, 2]
        vx = positions[c, 0] - positions[a, 0]
        vy = positions[c, 1] - positions[a, 1]
        vz = positions[c, 2] - positions[a, 2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        for v in (a, b, c):
            normals[v, 0] += nx
            normals[v, 1] += ny
            normals[v, 2] += nz
    for v in range(normals.shape[0]):
        size = np.sqrt(normals[v, 0] ** 2 + normals[v, 1] ** 2 + normals[v, 2] ** 2)
        if size < 1e-30:
            normals[v, 0] = 0.0
            normals[v, 1] = 0.0
            normals[v, 2] = 1.0
        else:
            normals[v, 0] /= size
            normals[v, 1] /= size
            normals[v, 2] /= size


def check_mesh(triangles: np.ndarray, vertex_count: int, positions: np.ndarray,
               spring_vertices: np.ndarray, min_area: float = 1e-14,
               spring_kind: np.ndarray | None = None) -> list[str]:
    """Every SPEC §4.4 invariant that fails, as readable sentences (empty list: valid).

    Checks: indices in range, no repeated corner, every edge in at most two triangles
    (edge-manifold), the triangles around every vertex form one fan (vertex-manifold),
    consistent orientation (each interior edge traversed once in each direction), the two
    triangles of an interior edge have different opposite vertices, every triangle edge is
    a spring, no degenerate (near-zero-area) triangle, every vertex used by a triangle.
    With ``spring_kind`` (HINGE 0, BEND 1, AUX 2) also: the HINGE springs are exactly the
    triangle edges, once each, and every BEND spring joins the two opposite vertices of an
    interior edge (the adjacency it was built from).
    """
    problems: list[str] = []
    if triangles.size == 0:
        return ['mesh has no triangles']
    if triangles.min() < 0 or triangles.max() >= vertex_count:
        return ['triangle index out of range']
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    if np.any((a == b) | (b == c) | (c == a)):
        problems.append('a triangle repeats a vertex')
    directed = np.concatenate([a, b, c]).astype(np.int64) * vertex_count \
        + np.concatenate([b, c, a]).astype(np.int64)
    if np.unique(directed).size != directed.size:
        problems.append('inconsistent orientation: a directed edge appears twice')
    try:
        edges, opposite = mesh_edges(triangles, vertex_count)
    except ValueError as error:
        problems.append(str(error))
        edges = np.empty((0, 2), dtype=np.int32)
        opposite = np.empty((0, 2), dtype=np.int32)
    interior = opposite[:, 1] != NO_VERTEX
    if np.any(opposite[interior, 0] == opposite[interior, 1]):
        problems.append('an interior edge has the same opposite vertex on both sides')
    problems += _vertex_fan_problems(triangles, vertex_count, edges, interior)
    spring_keys = np.unique(edge_key(spring_vertices[:, 0], spring_vertices[:, 1], vertex_count))
    triangle_edge_keys = edge_key(edges[:, 0], edges[:, 1], vertex_count)
    missing = ~np.isin(triangle_edge_keys, spring_keys)
    if np.any(missing):
        problems.append(f'{int(missing.sum())} triangle edges have no spring')
    if spring_kind is not None:
        problems += _spring_adjacency_problems(spring_vertices, spring_kind, vertex_count,
                                               edges, opposite, triangle_edge_keys)
    corner = positions[triangles]
    area = 0.5 * np.linalg.norm(
        np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]), axis=1)
    if np.any(~np.isfinite(area)) or np.any(area < min_area):
        problems.append(f'{int(np.sum(~(area >= min_area)))} degenerate triangles')
    used = np.zeros(vertex_count, dtype=bool)
    used[triangles.ravel()] = True
    if not used.all():
        problems.append(f'{int((~used).sum())} vertices belong to no triangle')
    return problems


def _vertex_fan_problems(triangles: np.ndarray, vertex_count: int, edges: np.ndarray,
                         interior: np.ndarray) -> list[str]:
    """A vertex is manifold when its triangles form one fan: a closed one (no border
    edges, as many triangles as edges) or an open one (two border edges, one triangle
    fewer than edges). Two fans meeting at a vertex (a bow tie) break the count."""
    triangle_count = np.bincount(triangles.ravel(), minlength=vertex_count)
    edge_count = np.bincount(edges.ravel(), minlength=vertex_count)
    border = edges[~interior]
    border_count = np.bincount(border.ravel(), minlength=vertex_count)
    closed = (border_count == 0) & (triangle_count == edge_count)
    open_fan = (border_count == 2) & (triangle_count == edge_count - 1)
    bad = triangle_count > 0
    bad &= ~(closed | open_fan)
    if np.any(bad):
        return [f'{int(bad.sum())} non-manifold vertices (not a single fan of triangles)']
    return []


def _spring_adjacency_problems(spring_vertices: np.ndarray, spring_kind: np.ndarray,
                               vertex_count: int, edges: np.ndarray, opposite: np.ndarray,
                               triangle_edge_keys: np.ndarray) -> list[str]:
    problems = []
    hinge = spring_vertices[spring_kind == 0]
    hinge_keys = edge_key(hinge[:, 0], hinge[:, 1], vertex_count)
    if np.unique(hinge_keys).size != hinge_keys.size:
        problems.append('two HINGE springs share an edge')
    if np.any(~np.isin(hinge_keys, triangle_edge_keys)):
        problems.append('a HINGE spring is not a triangle edge')
    if np.any(~np.isin(triangle_edge_keys, hinge_keys)):
        problems.append('a triangle edge has no HINGE spring')
    bend = spring_vertices[spring_kind == 1]
    interior = opposite[:, 1] != NO_VERTEX
    across_keys = edge_key(opposite[interior, 0], opposite[interior, 1], vertex_count)
    if np.any(~np.isin(edge_key(bend[:, 0], bend[:, 1], vertex_count), across_keys)):
        problems.append('a BEND spring does not span an interior edge')
    return problems
