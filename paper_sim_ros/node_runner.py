"""The `main` of every executable of this package, after the Jazzy demo_nodes_py skeleton."""
from __future__ import annotations

import signal
from typing import Callable

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def run_node(factory: Callable[[], Node], args=None, name: str = 'paper_sim',
             startup_errors: tuple[type[BaseException], ...] = ()) -> int:
    """Init rclpy, build the node and spin it until Ctrl-C / SIGTERM / shutdown; always
    destroy the node and shut down. A ``startup_errors`` exception raised while building the
    node is logged as one fatal line (no traceback) and gives exit status 1."""
    # Ctrl-C stops the node through rclpy's handler, which shuts the context down (spin then
    # ends with ExternalShutdownException) and then calls Python's own handler: left as the
    # default, that raises KeyboardInterrupt wherever the interpreter is, even inside a
    # finaliser, where it is printed as an ignored exception with a traceback
    signal.signal(signal.SIGINT, lambda signal_number, frame: None)
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except ExternalShutdownException:
        pass
    except startup_errors as error:
        rclpy.logging.get_logger(name).fatal(f'cannot start: {error}')
        return 1
    except RCLError:
        # SIGINT/SIGTERM shut the context down from rclpy's signal handler; if that lands
        # while the executor builds its wait set, rcl reports the invalid context instead of
        # ExternalShutdownException (a race inside rclpy.spin). Still an orderly stop.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
