"""Pure functions that turn simulation state (numpy arrays) into ROS 2 messages.

Installed as ``paper_sim_ros.msg_adapters``; no Node lives here.
"""
