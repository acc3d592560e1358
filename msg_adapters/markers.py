"""The sheet as ``visualization_msgs/MarkerArray`` for RViz.

Namespaces and ids are stable, so RViz replaces markers in place frame after frame:

    ns                    id   type             what
    paper/surface         0    TRIANGLE_LIST    the shaded surface, one colour per point
    paper/springs/hinge   0    LINE_LIST        HINGE springs (triangle edges)
    paper/springs/aux     0    LINE_LIST        AUX springs (creases, folds: damage memory)
    paper/springs/bend    0    LINE_LIST        BEND springs (off by default)
    paper/probes          i    SPHERE           probe i (DELETE while it is inactive)

A spring kind with no springs is sent as DELETE: RViz warns about an empty LINE_LIST.

Two outputs of the same markers (``sheet_marker_parts`` describes them once):
- ``sheet_markers``: the MarkerArray message object. Every point is one Python
  ``geometry_msgs/Point`` and every colour one ``std_msgs/ColorRGBA``; we build one of each per
  *vertex* and let the triangle and line lists share them, but ``publish`` still serialises
  every entry (about 1 µs each): slow (bench/bench_adapters.py).
- ``sheet_markers_cdr``: the same message as serialised bytes, the large arrays written by
  numpy (``marker_cdr``); ``Publisher.publish`` takes bytes. What the node publishes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from paper_sim_ros.core.sheet import AUX, BEND, HINGE

from .marker_cdr import CdrWriter, serialize_marker_array

SURFACE_NS = 'paper/surface'
SPRING_NS = {HINGE: 'paper/springs/hinge', AUX: 'paper/springs/aux', BEND: 'paper/springs/bend'}
PROBE_NS = 'paper/probes'
IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)


@dataclass(frozen=True)
class MarkerStyle:
    """What to draw and how. Colours are RGBA in [0, 1]; widths in m."""

    hinge_springs: bool = True
    aux_springs: bool = True
    bend_springs: bool = False
    hinge_width: float = 0.0004
    aux_width: float = 0.0012
    bend_width: float = 0.0003
    hinge_color: tuple = (0.30, 0.40, 0.85, 0.6)
    aux_color: tuple = (0.90, 0.15, 0.10, 1.0)
    bend_color: tuple = (0.20, 0.70, 0.30, 0.4)
    probe_color: tuple = (0.95, 0.60, 0.10, 0.7)

    def __post_init__(self) -> None:
        for name in ('hinge_width', 'aux_width', 'bend_width'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f'{name} must be finite and > 0, got {value!r}')
        for name in ('hinge_color', 'aux_color', 'bend_color', 'probe_color'):
            value = getattr(self, name)
            if len(value) != 4 or not all(0.0 <= c <= 1.0 for c in value):
                raise ValueError(f'{name} must be four numbers in [0, 1], got {value!r}')

    def spring_settings(self, kind: int) -> tuple[bool, float, tuple]:
        name = {HINGE: 'hinge', AUX: 'aux', BEND: 'bend'}[kind]
        return (getattr(self, f'{name}_springs'), getattr(self, f'{name}_width'),
                getattr(self, f'{name}_color'))


def _checked_finite(name: str, array: np.ndarray) -> np.ndarray:
    if not np.isfinite(array).all():
        raise ValueError(f'{name} must be finite')
    return array


def points_from_array(positions: np.ndarray) -> list[Point]:
    """One ``Point`` per row of a (N, 3) array.

    The fastest legal construction measured (bench/bench_adapters.py): ``tolist()`` once,
    then the generated class's keyword constructor in a comprehension. (Writing the private
    ``_x`` slots directly is faster but relies on generated internals; a numpy record
    array is accepted by the serialiser through duck typing but is slower.)
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f'positions must be (N, 3), got {positions.shape}')
    _checked_finite('positions', positions)
    return [Point(x=x, y=y, z=z) for x, y, z in positions.tolist()]


def color_array(colors: np.ndarray, alpha: float = 1.0) -> np.ndarray:
    """(N, 4) float32 RGBA in [0, 1] of a (N, 3) uint8 array (0-255) or float array (0-1).
    float32, like ColorRGBA's fields, so that a message survives serialisation unchanged."""
    colors = np.asarray(colors)
    if colors.ndim != 2 or colors.shape[1] != 3:
        raise ValueError(f'colors must be (N, 3), got {colors.shape}')
    if colors.dtype == np.uint8:
        unit = colors.astype(np.float64) / 255.0
    else:
        unit = np.clip(np.nan_to_num(colors.astype(np.float64), nan=0.0), 0.0, 1.0)
    rows = np.empty((colors.shape[0], 4), dtype=np.float32)
    rows[:, :3] = unit
    rows[:, 3] = alpha
    return rows


def colors_from_array(colors: np.ndarray, alpha: float = 1.0) -> list[ColorRGBA]:
    """One ``ColorRGBA`` per row of a (N, 3) uint8 array (0-255) or float array (0-1)."""
    return [ColorRGBA(r=r, g=g, b=b, a=a) for r, g, b, a in color_array(colors, alpha).tolist()]


def rgba(color: tuple) -> ColorRGBA:
    """A ColorRGBA of four numbers in [0, 1], rounded to float32 like its fields."""
    r, g, b, a = np.asarray(color, dtype=np.float32).tolist()
    return ColorRGBA(r=r, g=g, b=b, a=a)


def _base_marker(header: Header, ns: str, marker_id: int, marker_type: int) -> Marker:
    return Marker(header=header, ns=ns, id=marker_id, type=marker_type, action=Marker.ADD,
                  pose=Pose(orientation=IDENTITY), lifetime=Duration(sec=0, nanosec=0),
                  frame_locked=False)


def delete_marker(header: Header, ns: str, marker_id: int) -> Marker:
    return Marker(header=header, ns=ns, id=marker_id, action=Marker.DELETE,
                  pose=Pose(orientation=IDENTITY), scale=Vector3(x=1.0, y=1.0, z=1.0))


def delete_all_marker(header: Header) -> Marker:
    """Clears every marker of this publisher in RViz (sent first after a reset)."""
    return Marker(header=header, action=Marker.DELETEALL, pose=Pose(orientation=IDENTITY),
                  scale=Vector3(x=1.0, y=1.0, z=1.0))


@dataclass
class MarkerPart:
    """A marker whose points (and colours) are still vertex indices: ``points`` of the
    message are ``positions[indices]``; with ``per_point_colors`` its colours are the vertex
    colours at the same indices. Both outputs, objects and CDR bytes, are made from these."""

    marker: Marker
    indices: np.ndarray | None = None
    per_point_colors: bool = False


def _check_indices(name: str, indices: np.ndarray, columns: int, vertex_count: int) -> None:
    if indices.ndim != 2 or indices.shape[1] != columns:
        raise ValueError(f'{name} must be (N, {columns}), got {indices.shape}')
    if indices.size and (indices.min() < 0 or indices.max() >= vertex_count):
        raise ValueError(f'{name}: vertex index out of range')


def surface_part(header: Header, triangles: np.ndarray, vertex_count: int) -> MarkerPart:
    """TRIANGLE_LIST with three points (and three colours) per triangle."""
    triangles = np.asarray(triangles)
    _check_indices('triangles', triangles, 3, vertex_count)
    marker = _base_marker(header, SURFACE_NS, 0, Marker.TRIANGLE_LIST)
    marker.scale = Vector3(x=1.0, y=1.0, z=1.0)
    marker.color = rgba((1.0, 1.0, 1.0, 1.0))
    return MarkerPart(marker, triangles.ravel(), per_point_colors=True)


def spring_part(header: Header, spring_vertices: np.ndarray, vertex_count: int, kind: int,
                width: float, color: tuple) -> MarkerPart:
    """LINE_LIST of the given springs (two points per spring), or DELETE when there are none."""
    spring_vertices = np.asarray(spring_vertices)
    ns = SPRING_NS[kind]
    if spring_vertices.shape[0] == 0:
        return MarkerPart(delete_marker(header, ns, 0))
    _check_indices('spring_vertices', spring_vertices, 2, vertex_count)
    marker = _base_marker(header, ns, 0, Marker.LINE_LIST)
    marker.scale = Vector3(x=float(width), y=0.0, z=0.0)
    marker.color = rgba(color)
    return MarkerPart(marker, spring_vertices.ravel())


def probe_markers(header: Header, centers: np.ndarray, radii: np.ndarray, active: np.ndarray,
                  color: tuple) -> list[Marker]:
    """A SPHERE per active probe (diameter 2 r), DELETE for each inactive one."""
    centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    active = np.asarray(active, dtype=bool).reshape(-1)
    if not (len(centers) == len(radii) == len(active)):
        raise ValueError('centers, radii and active must have the same length')
    markers = []
    rows = zip(centers.tolist(), radii.tolist(), active.tolist())
    for index, (center, radius, on) in enumerate(rows):
        usable = on and np.isfinite(center).all() and np.isfinite(radius) and radius > 0
        if not usable:
            markers.append(delete_marker(header, PROBE_NS, index))
            continue
        marker = _base_marker(header, PROBE_NS, index, Marker.SPHERE)
        marker.pose = Pose(position=Point(x=center[0], y=center[1], z=center[2]),
                           orientation=IDENTITY)
        marker.scale = Vector3(x=2.0 * radius, y=2.0 * radius, z=2.0 * radius)
        marker.color = rgba(color)
        markers.append(marker)
    return markers


def sheet_marker_parts(header: Header, positions: np.ndarray, triangles: np.ndarray,
                       vertex_colors: np.ndarray, spring_vertices: np.ndarray,
                       spring_kind: np.ndarray, probe_centers: np.ndarray,
                       probe_radii: np.ndarray, probe_active: np.ndarray,
                       style: MarkerStyle = MarkerStyle(),
                       delete_all: bool = False) -> list[MarkerPart]:
    """Everything of ``sheet_markers`` but the point lists; validates all input."""
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f'positions must be (V, 3), got {positions.shape}')
    _checked_finite('positions', positions)
    vertex_count = positions.shape[0]
    if len(vertex_colors) != vertex_count:
        raise ValueError(f'{len(vertex_colors)} colours for {vertex_count} vertices')
    spring_kind = np.asarray(spring_kind)
    spring_vertices = np.asarray(spring_vertices)
    parts = [MarkerPart(delete_all_marker(header))] if delete_all else []
    parts.append(surface_part(header, triangles, vertex_count))
    for kind in (HINGE, AUX, BEND):
        shown, width, color = style.spring_settings(kind)
        if shown:
            parts.append(spring_part(header, spring_vertices[spring_kind == kind],
                                     vertex_count, kind, width, color))
        else:
            parts.append(MarkerPart(delete_marker(header, SPRING_NS[kind], 0)))
    parts.extend(MarkerPart(marker) for marker in probe_markers(
        header, probe_centers, probe_radii, probe_active, style.probe_color))
    return parts


def sheet_markers(header: Header, positions: np.ndarray, triangles: np.ndarray,
                  vertex_colors: np.ndarray, spring_vertices: np.ndarray,
                  spring_kind: np.ndarray, probe_centers: np.ndarray, probe_radii: np.ndarray,
                  probe_active: np.ndarray, style: MarkerStyle = MarkerStyle(),
                  delete_all: bool = False) -> MarkerArray:
    """The whole sheet as one MarkerArray message; ``delete_all`` puts a DELETEALL first
    (after a reset). One ``Point`` and one ``ColorRGBA`` object per vertex, shared by every
    marker that refers to the vertex (slow: see ``sheet_markers_cdr``)."""
    parts = sheet_marker_parts(header, positions, triangles, vertex_colors, spring_vertices,
                               spring_kind, probe_centers, probe_radii, probe_active, style,
                               delete_all)
    vertex_points = points_from_array(positions)
    vertex_color_list = colors_from_array(vertex_colors)
    for part in parts:
        if part.indices is None:
            continue
        order = part.indices.tolist()
        part.marker.points = [vertex_points[i] for i in order]
        if part.per_point_colors:
            part.marker.colors = [vertex_color_list[i] for i in order]
    return MarkerArray(markers=[part.marker for part in parts])


def sheet_markers_cdr(header: Header, positions: np.ndarray, triangles: np.ndarray,
                      vertex_colors: np.ndarray, spring_vertices: np.ndarray,
                      spring_kind: np.ndarray, probe_centers: np.ndarray,
                      probe_radii: np.ndarray, probe_active: np.ndarray,
                      style: MarkerStyle = MarkerStyle(), delete_all: bool = False,
                      writer: CdrWriter | None = None) -> bytes:
    """``sheet_markers`` serialised (the bytes of ``serialize_message(sheet_markers(...))``
    but for padding, for ``Publisher.publish``), built from numpy without a Python object per
    point. ``writer``: a ``CdrWriter`` to write into (it records where the padding is)."""
    parts = sheet_marker_parts(header, positions, triangles, vertex_colors, spring_vertices,
                               spring_kind, probe_centers, probe_radii, probe_active, style,
                               delete_all)
    positions = np.asarray(positions, dtype=np.float64)
    rgba_rows = color_array(vertex_colors)
    return serialize_marker_array([
        (part.marker,
         positions[part.indices] if part.indices is not None else None,
         rgba_rows[part.indices] if part.per_point_colors else None)
        for part in parts], writer)
