"""Launch the paper simulation with RViz, optionally with the scripted demo probe.

    ros2 launch paper_sim_ros paper_sim.launch.py                  # node + RViz
    ros2 launch paper_sim_ros paper_sim.launch.py scripted_probe:=true rviz:=false
    ros2 launch paper_sim_ros paper_sim.launch.py params_file:=/path/to/my.yaml use_sim_time:=true
    ros2 launch paper_sim_ros paper_sim.launch.py publish_clock:=true scripted_probe:=true

With ``publish_clock:=true`` the simulation is the clock (it publishes /clock, at most
``max_real_time_factor`` of real time) and the probe and RViz run on it (``use_sim_time``).

Needs a ROS 2 install with ``launch`` and ``launch_ros`` (they are not on PyPI; without them,
run ``python -m paper_sim_ros.demo`` or the executables directly).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('paper_sim_ros')
    params_file = LaunchConfiguration('params_file')
    use_sim_time = LaunchConfiguration('use_sim_time')
    publish_clock = LaunchConfiguration('publish_clock')
    # the nodes beside the simulation follow /clock when it comes from elsewhere or from it
    others_on_clock = PythonExpression(["'", use_sim_time, "' == 'true' or '", publish_clock,
                                        "' == 'true'"])
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file', default_value=os.path.join(share, 'config', 'paper_sim.yaml'),
            description='Node-keyed parameter file of the paper_sim node'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='Follow /clock instead of the wall clock'),
        DeclareLaunchArgument('publish_clock', default_value='false',
                              description='The simulation publishes /clock; the probe and '
                                          'RViz follow it'),
        DeclareLaunchArgument('max_real_time_factor', default_value='1.0',
                              description='With publish_clock: at most this fast (0: no cap)'),
        DeclareLaunchArgument('rviz', default_value='true',
                              description='Start RViz with config/paper_sim.rviz'),
        DeclareLaunchArgument('scripted_probe', default_value='false',
                              description='Start the scripted probe that presses and drags'),
        Node(package='paper_sim_ros', executable='paper_sim_node', name='paper_sim',
             output='screen', emulate_tty=True,
             parameters=[params_file, {
                 'use_sim_time': use_sim_time, 'publish_clock': publish_clock,
                 'max_real_time_factor': LaunchConfiguration('max_real_time_factor')}]),
        Node(package='paper_sim_ros', executable='paper_sim_probe',
             name='scripted_probe', output='screen',
             parameters=[{'use_sim_time': others_on_clock}],
             condition=IfCondition(LaunchConfiguration('scripted_probe'))),
        Node(package='rviz2', executable='rviz2', name='rviz2', output='log',
             arguments=['-d', os.path.join(share, 'config', 'paper_sim.rviz')],
             parameters=[{'use_sim_time': others_on_clock}],
             condition=IfCondition(LaunchConfiguration('rviz'))),
    ])
