from glob import glob

from setuptools import setup

package_name = 'paper_sim_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=[package_name, f'{package_name}.core', f'{package_name}.dataset',
              f'{package_name}.msg_adapters'],
    # msg_adapters/ sits at the top level of the repository but installs inside our namespace
    package_dir={f'{package_name}.msg_adapters': 'msg_adapters'},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{package_name}']),
        (f'share/{package_name}', ['package.xml']),
        (f'share/{package_name}/config', glob('config/*.yaml') + glob('config/*.rviz')),
        (f'share/{package_name}/launch', glob('launch/*.py')),
    ],
    # what runs: the core (numpy, numba, scipy; pyyaml for scenario files; pillow for a
    # texture image file), Rerun recording (node, headless, replay; pyarrow, which rerun-sdk
    # brings, is imported directly) and rosbag2 writing (rosbags). package.xml names the
    # same as rosdep keys, but for numba, rerun-sdk, pyarrow and rosbags, which it leaves to
    # pip: without rerun-sdk the node runs and refuses only to record (README). Ray runs
    # datasets (paper_sim_dataset; not in package.xml either): [default] is what `ray start`
    # nodes and KubeRay images have, and it brings the Ray Client (ray://).
    # test/test_dependencies.py checks that every module imported at run time is declared.
    install_requires=['setuptools', 'numpy', 'numba', 'scipy', 'pyyaml', 'pillow',
                      'rerun-sdk==0.41.*', 'pyarrow', 'rosbags', 'ray[default]==2.60.*'],
    # what only the tests and the linters use (`make setup` installs '.[test]')
    extras_require={
        'test': ['pytest', 'import-linter', 'flake8', 'mcap', 'mcap-ros2-support',
                 'colcon-core', 'colcon-ros',
                 'colcon-python-setup-py', 'colcon-package-selection', 'colcon-output',
                 'colcon-library-path'],
    },
    zip_safe=True,
    maintainer='paper_sim_ros developers',
    maintainer_email='dev@paper-sim-ros.invalid',
    description='Interactive simulation of folded paper for ROS 2 robot stacks.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'paper_sim_headless = paper_sim_ros.headless:main',
            'paper_sim_node = paper_sim_ros.node:main',
            'paper_sim_probe = paper_sim_ros.scripted_probe:main',
            'paper_sim_dataset = paper_sim_ros.dataset.cli:main',
        ],
    },
)
