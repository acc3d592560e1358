"""Cost per published frame of the message adapters (a script, not a test).

    .venv/bin/python bench/bench_adapters.py [--grids 65 129] [--repeat 5]

For each grid it steps a sheet under a pressing probe for a few frames, then times (best of
``--repeat``) what the node does per published frame: normals and damage labels, the vertex
colours, building the PointCloud2 and the MarkerArray, and serialising each the way
``publish`` does (rclpy.serialization.serialize_message, the same C conversion). Markers two
ways: as message objects (one Python object per point, then serialised), and as CDR bytes
written by numpy (``sheet_markers_cdr``, what the node publishes; serialising is building).
It also compares ways of building the ``geometry_msgs/Point`` list of ``Marker.points``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from geometry_msgs.msg import Point
from rclpy.serialization import serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from paper_sim_ros.core.appearance import AppearanceConfig, PaperAppearance
from paper_sim_ros.core.config import SheetConfig, SimulationConfig
from paper_sim_ros.core.simulator import Simulator
from paper_sim_ros.core.topology import vertex_normals
from paper_sim_ros.msg_adapters.markers import MarkerStyle, sheet_markers, sheet_markers_cdr
from paper_sim_ros.msg_adapters.point_cloud import create_cloud, sheet_points


def best_of(repeat: int, function) -> tuple[float, object]:
    best, result = float('inf'), None
    for _ in range(repeat):
        started = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - started)
    return best, result


def pressed_simulator(grid: int) -> Simulator:
    simulator = Simulator(SimulationConfig(sheet=SheetConfig(nx=grid, ny=grid)))
    for frame in range(10):
        depth = 0.002 * frame
        simulator.set_probes(np.array([[0.0, 0.0, 0.02 - depth]]), np.array([0.02]),
                             np.array([True]))
        simulator.step_frame()
    return simulator


def point_list_variants(positions: np.ndarray, repeat: int) -> dict[str, float]:
    """Ways to make one Point per vertex; all give equal messages."""
    rows = positions.tolist()

    def keyword():
        return [Point(x=x, y=y, z=z) for x, y, z in rows]

    def slots():  # writes the generated class's private slots: fast, relies on internals
        new = Point.__new__
        points = []
        for x, y, z in rows:
            point = new(Point)
            point._check_fields = False
            point._x, point._y, point._z = x, y, z
            points.append(point)
        return points

    def record_array():  # duck typing: the C converter reads .x/.y/.z of any object
        return np.rec.fromarrays(positions.T, names='x,y,z')

    results = {}
    for name, build in (('Point(x=, y=, z=) over tolist()', keyword),
                        ('Point via private slots', slots),
                        ('numpy record array (duck typed)', record_array)):
        build_seconds, points = best_of(repeat, build)
        marker = Marker(points=points)
        serialize_seconds, _ = best_of(repeat, lambda: serialize_message(marker))
        results[name] = (build_seconds, serialize_seconds)
    return results


def bench_grid(grid: int, repeat: int) -> None:
    simulator = pressed_simulator(grid)
    sheet = simulator.sheet
    header = Header(frame_id='world')
    appearance = PaperAppearance(AppearanceConfig(), simulator.initial_sheet)  # as the node
    step_seconds, _ = best_of(repeat, simulator.step_frame)
    sheet = simulator.sheet
    normals_seconds, normals = best_of(repeat, lambda: vertex_normals(sheet.positions,
                                                                      sheet.triangles))
    labels_seconds, labels = best_of(repeat, simulator.damage_labels)
    colors_seconds, colors = best_of(repeat, lambda: appearance.vertex_colors(sheet))
    cloud_seconds, cloud = best_of(repeat, lambda: create_cloud(
        header, sheet_points(sheet.positions, normals, labels, sheet.material)))
    cloud_serialize, cloud_bytes = best_of(repeat, lambda: serialize_message(cloud))
    probes = simulator.probes

    def arguments(style):
        return (header, sheet.positions, sheet.triangles, colors, sheet.spring_vertices,
                sheet.spring_kind, probes.end, probes.radius, probes.active, style)
    rows = []
    for label, style in (('surface + hinge + aux', MarkerStyle()),
                         ('surface + aux (no hinge)', MarkerStyle(hinge_springs=False))):
        build_seconds, array = best_of(repeat, lambda: sheet_markers(*arguments(style)))
        serialize_seconds, data = best_of(repeat, lambda: serialize_message(array))
        points = sum(len(marker.points) for marker in array.markers)
        rows.append((f'objects, {label}', build_seconds, serialize_seconds, points,
                     len(data)))
        cdr_seconds, data = best_of(repeat, lambda: sheet_markers_cdr(*arguments(style)))
        rows.append((f'numpy CDR, {label}', cdr_seconds, 0.0, points, len(data)))

    print(f'\n== grid {grid}x{grid}: {sheet.vertex_count} vertices, {len(sheet.triangles)} '
          f'triangles, {sheet.spring_count} springs (best of {repeat}) ==')
    print(f'  physics step_frame                     {1e3 * step_seconds:8.2f} ms')
    print(f'  vertex normals                         {1e3 * normals_seconds:8.2f} ms')
    print(f'  damage labels                          {1e3 * labels_seconds:8.2f} ms')
    print(f'  colours: appearance.vertex_colors      {1e3 * colors_seconds:8.2f} ms')
    print(f'  PointCloud2 build                      {1e3 * cloud_seconds:8.2f} ms')
    print(f'  PointCloud2 serialise                  {1e3 * cloud_serialize:8.2f} ms '
          f'({len(cloud_bytes) / 1e6:.2f} MB)')
    cloud_total = normals_seconds + labels_seconds + cloud_seconds + cloud_serialize
    print(f'  => point cloud per published frame     {1e3 * cloud_total:8.2f} ms')
    for label, build_seconds, serialize_seconds, points, size in rows:
        total = normals_seconds + colors_seconds + build_seconds + serialize_seconds
        print(f'  MarkerArray {label:37s} build {1e3 * build_seconds:7.2f} ms, serialise '
              f'{1e3 * serialize_seconds:7.2f} ms ({points} points, {size / 1e6:.2f} MB)')
        print(f'  => markers per published frame {1e3 * total:8.2f} ms (with normals and colours)')
    print('  Point list for Marker.points, one per vertex: build / serialise')
    for name, (build_seconds, serialize_seconds) in point_list_variants(
            sheet.positions, repeat).items():
        print(f'    {name:34s} {1e3 * build_seconds:7.2f} ms / {1e3 * serialize_seconds:7.2f} ms')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[65, 129])
    parser.add_argument('--repeat', type=int, default=5)
    arguments = parser.parse_args()
    for grid in arguments.grids:
        bench_grid(grid, arguments.repeat)


if __name__ == '__main__':
    main()
