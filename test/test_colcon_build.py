"""`colcon build` of the package into a temporary directory, and the installed executable."""
from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys

import pytest
from sensor_msgs.msg import PointCloud2

from ros_harness import REPO, RosClient, new_domain_id, ros_env, start_node, stop_cleanly

COLCON = Path(sys.executable).parent / 'colcon'


@pytest.mark.slow
def test_colcon_build_installs_a_runnable_node(tmp_path):
    assert COLCON.exists(), f'colcon is not installed next to {sys.executable} (make setup)'
    leftovers = [REPO / name for name in ('build', 'install', 'log')]
    existed = {path: path.exists() for path in leftovers}
    result = subprocess.run(
        [str(COLCON), '--log-base', str(tmp_path / 'log'), 'build',
         '--base-paths', str(REPO), '--packages-select', 'paper_sim_ros',
         '--build-base', str(tmp_path / 'build'), '--install-base', str(tmp_path / 'install'),
         '--event-handlers', 'console_direct-'],
        cwd=str(tmp_path), capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    for path in leftovers:
        assert path.exists() == existed[path], f'the build wrote {path} into the repository'

    prefix = tmp_path / 'install' / 'paper_sim_ros'
    share = prefix / 'share' / 'paper_sim_ros'
    for relative in ('lib/paper_sim_ros/paper_sim_node',
                     'lib/paper_sim_ros/paper_sim_probe',
                     'share/ament_index/resource_index/packages/paper_sim_ros',
                     'share/paper_sim_ros/package.xml',
                     'share/paper_sim_ros/config/paper_sim.yaml',
                     'share/paper_sim_ros/config/paper_sim.rviz',
                     'share/paper_sim_ros/launch/paper_sim.launch.py'):
        assert (prefix / relative).exists(), f'{relative} not installed'
    site = next(prefix.glob('lib/python3*/site-packages'))
    assert (site / 'paper_sim_ros' / 'msg_adapters' / 'markers.py').exists()
    assert not (site / 'msg_adapters').exists(), 'msg_adapters installed as a global package'

    env_extra = {'PYTHONPATH': os.pathsep.join([str(site), os.environ.get('PYTHONPATH', '')]),
                 'AMENT_PREFIX_PATH': str(prefix)}
    where = subprocess.run([sys.executable, '-c', 'import paper_sim_ros.node as n; '
                            'print(n.__file__)'], env=ros_env(0, env_extra), cwd=str(tmp_path),
                           capture_output=True, text=True, timeout=60)
    assert where.stdout.strip().startswith(str(site)), where.stdout + where.stderr

    domain = new_domain_id()
    process = start_node(tmp_path, {'sheet.nx': 9, 'sheet.ny': 9},
                         domain_id=domain, params_file=share / 'config' / 'paper_sim.yaml',
                         executable=[str(prefix / 'lib' / 'paper_sim_ros' / 'paper_sim_node')],
                         env_extra=env_extra, name='installed')
    client = RosClient(domain)
    try:
        client.subscribe(PointCloud2, 'paper/points')
        client.spin_until(lambda: client.latest('paper/points') is not None, 60,
                          'a cloud from the installed node', process)
        assert client.latest('paper/points').width == 81
    finally:
        client.close()
        stop_cleanly(process)


def test_launch_file_and_rviz_config_match_the_package():
    """No launch_ros here: the launch file is compiled and checked for the executables it
    starts; the RViz config for the topics and frame the node uses."""
    import yaml
    launch = (REPO / 'launch' / 'paper_sim.launch.py').read_text()
    compile(launch, 'paper_sim.launch.py', 'exec')
    setup = (REPO / 'setup.py').read_text()
    for executable in ('paper_sim_node', 'paper_sim_probe'):
        assert f"executable='{executable}'" in launch
        assert f"'{executable} = " in setup, f'{executable} is not a console script'
    rviz = yaml.safe_load((REPO / 'config' / 'paper_sim.rviz').read_text())
    manager = rviz['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == 'world'
    topics = {display['Topic']['Value']: display['Class'] for display in manager['Displays']
              if 'Topic' in display}
    assert topics == {'/paper/markers': 'rviz_default_plugins/MarkerArray',
                      '/paper/points': 'rviz_default_plugins/PointCloud2'}
