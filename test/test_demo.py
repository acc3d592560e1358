"""The scripted probe's path, and `make demo` end to end (short and small)."""
from __future__ import annotations

import re
import subprocess

import numpy as np
import pytest

from paper_sim_ros.scripted_probe import ProbePath
from ros_harness import PYTHON, REPO, new_domain_id, ros_env


def test_probe_path_visits_its_waypoints_in_order():
    path = ProbePath(approach=(0.0, 0.0, 1.0), press_start=(0.0, 0.0, 0.0),
                     press_end=(1.0, 0.0, 0.0), retreat=(1.0, 0.0, 1.0), period=10.0,
                     start_delay=2.0)
    assert path.position(0.0) is None and path.position(1.99) is None
    np.testing.assert_allclose(path.position(2.0), [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(path.position(2.0 + 1.5), [0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(path.position(2.0 + 7.0), [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(path.position(2.0 + 8.5), [1.0, 0.0, 1.0], atol=1e-12)
    middle_of_drag = path.position(2.0 + 1.5 + 2.75)
    np.testing.assert_allclose(middle_of_drag, [0.5, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(path.position(2.0 + 13.5), path.position(2.0 + 3.5))
    samples = np.array([path.position(2.0 + t) for t in np.linspace(0, 10, 2001)])
    assert np.abs(np.diff(samples, axis=0)).max() < 0.01, 'the path jumps'


def test_probe_path_refuses_bad_values():
    with pytest.raises(ValueError):
        ProbePath(period=0.0)
    with pytest.raises(ValueError):
        ProbePath(approach=(0.0, float('nan'), 0.0))
    with pytest.raises(ValueError):
        ProbePath(start_delay=-1.0)


@pytest.mark.slow
def test_demo_runs_and_says_where_its_recording_is(tmp_path):
    result = subprocess.run(
        [PYTHON, '-m', 'paper_sim_ros.demo', '--duration', '8', '--grid', '9',
         '--out', str(tmp_path / 'out'), '--report-every', '3'],
        env=ros_env(new_domain_id()), cwd=str(REPO), capture_output=True, text=True,
        timeout=120)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    recording = tmp_path / 'out' / 'demo.rrd'
    assert f'Rerun recording: {recording}' in result.stdout
    assert recording.stat().st_size > 0
    assert 'all finite: True' in result.stdout
    strains = re.search(r'max strain ([0-9.]+)% over the last second, ([0-9.]+)% over the run',
                        result.stdout)
    assert strains, result.stdout[-2000:]
    last_second, run = (float(value) for value in strains.groups())
    assert 0.0 < last_second <= run, f'last second {last_second} %, run {run} %'
    # the scripted probe runs as a process of its own: its poses reached the node over DDS
    # (it is away for its first 2 s, then publishes at 60 Hz)
    poses = re.search(r'(\d+) probe poses', result.stdout)
    assert poses and int(poses.group(1)) > 0, result.stdout[-2000:]
    # --report-every: a line per interval, each with the factor, the vertices and the memory
    reports = re.findall(r'([0-9.]+)× real time over the last (\d+) s \(([0-9.]+) s simulated\),'
                         r' (\d+) vertices, breaks \d+, folds \d+, RSS (\d+) MB', result.stdout)
    assert len(reports) == 2, result.stdout[-2000:]
    for factor, interval, simulated, vertices, resident in reports:
        assert float(factor) > 0.0 and int(interval) >= 3 and int(vertices) == 81
        assert 50 < int(resident) < 4000
    assert float(reports[0][2]) < float(reports[1][2])
    assert 'Traceback' not in result.stderr
