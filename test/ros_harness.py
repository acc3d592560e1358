"""Helpers for tests that run the node as its own process and talk to it over real DDS.

Isolation: every node process and test context uses a fresh ROS domain id, drawn at random
from a generator seeded by the pid; discovery is limited to this machine. Importing this
module fails (it never skips) when rclpy is missing.
"""
from __future__ import annotations

import os
import random
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Callable

import numpy as np
import rclpy
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / 'config' / 'paper_sim.yaml'
PYTHON = sys.executable

_domain_random = random.Random(os.getpid() * 1_000_003 + time.time_ns())
_PROCESS_DOMAIN = _domain_random.randint(1, 232)
"""This test process's ROS domain; nodes it starts get fresh ones (1..232: Fast DDS ports)."""
_used_domains = {_PROCESS_DOMAIN}

ISOLATION = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_LOCALHOST_ONLY': '1'}
os.environ.update(ISOLATION)
os.environ['ROS_DOMAIN_ID'] = str(_PROCESS_DOMAIN)


def new_domain_id() -> int:
    """A domain id this test process has not used yet, drawn at random (seeded by the pid and
    the time), so that concurrent test processes practically never meet; ``RosClient``
    checks that the node it talks to is alone on it."""
    while True:
        domain = _domain_random.randint(1, 232)
        if domain not in _used_domains:
            _used_domains.add(domain)
            return domain


def ros_env(domain_id: int, extra: dict | None = None) -> dict:
    env = dict(os.environ)
    env.update(ISOLATION)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['PYTHONUNBUFFERED'] = '1'
    env['RCUTILS_LOGGING_BUFFERED_STREAM'] = '0'
    env.update(extra or {})
    return env


def overrides(values: dict) -> list[str]:
    arguments = []
    for name, value in values.items():
        if isinstance(value, bool):
            text = 'true' if value else 'false'
        elif isinstance(value, (list, tuple)):
            text = '[' + ','.join(repr(v) if isinstance(v, str) else str(v) for v in value) + ']'
        else:
            text = str(value)
        arguments += ['-p', f'{name}:={text}']
    return arguments


class NodeProcess:
    """The node in a subprocess; stdout and stderr go to files so they never block it."""

    def __init__(self, command: list[str], log_dir: Path, domain_id: int,
                 env_extra: dict | None = None, name: str = 'node') -> None:
        self.domain_id = domain_id
        self.stdout_path = log_dir / f'{name}.out'
        self.stderr_path = log_dir / f'{name}.err'
        self._stdout = open(self.stdout_path, 'wb')
        self._stderr = open(self.stderr_path, 'wb')
        self.process = subprocess.Popen(command, stdout=self._stdout, stderr=self._stderr,
                                        env=ros_env(domain_id, env_extra), cwd=str(log_dir))

    def alive(self) -> bool:
        return self.process.poll() is None

    def output(self) -> str:
        """Everything the node logged so far (rcutils logs to stderr, prints to stdout)."""
        return (self.stdout_path.read_text(errors='replace')
                + self.stderr_path.read_text(errors='replace'))

    def stop(self, signal_number: int = signal.SIGINT, timeout: float = 20.0) -> int:
        if self.alive():
            self.process.send_signal(signal_number)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)
                raise AssertionError(f'node did not stop within {timeout} s of signal '
                                     f'{signal_number}; log:\n{self.output()[-3000:]}')
        self._stdout.close()
        self._stderr.close()
        return self.process.returncode


def stop_cleanly(process: NodeProcess, signal_number: int = signal.SIGINT) -> str:
    """Stop the node with a signal; it must exit with status 0 and no traceback. Returns
    its log."""
    code = process.stop(signal_number)
    output = process.output()
    assert code == 0, f'exit status {code}:\n{output[-3000:]}'
    assert 'Traceback' not in output, output[-3000:]
    return output


def start_node(log_dir: Path, parameters: dict | None = None, domain_id: int | None = None,
               params_file: Path = CONFIG, executable: list[str] | None = None,
               env_extra: dict | None = None, name: str = 'node') -> NodeProcess:
    command = (executable or [PYTHON, '-m', 'paper_sim_ros.node']) + \
        ['--ros-args', '--params-file', str(params_file)] + overrides(parameters or {})
    return NodeProcess(command, log_dir, domain_id if domain_id is not None
                       else new_domain_id(), env_extra, name)


class RosClient:
    """A test node in its own rclpy context on the node's domain, with recorders of what
    arrives on the topics it subscribes to."""

    def __init__(self, domain_id: int, name: str = 'paper_sim_test') -> None:
        self.domain_id = domain_id
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list[tuple[float, object]]] = {}

    def subscribe(self, message_type, topic: str, qos=10, keep: int = 10000) -> None:
        store = self.received.setdefault(topic, [])

        def on_message(msg) -> None:
            store.append((time.monotonic(), msg))
            if len(store) > keep:
                del store[:len(store) - keep]
        self.node.create_subscription(message_type, topic, on_message, qos)

    def messages(self, topic: str, since: float = 0.0) -> list:
        return [msg for stamp, msg in self.received.get(topic, []) if stamp >= since]

    def latest(self, topic: str):
        store = self.received.get(topic)
        return store[-1][1] if store else None

    def spin_for(self, seconds: float, every: Callable[[], None] | None = None) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)
            if every is not None:
                every()

    def assert_alone(self, topic: str = 'paper/points') -> None:
        """Exactly one publisher of ``topic`` on this domain: no stray node from elsewhere."""
        count = self.node.count_publishers(topic)
        assert count == 1, f'{count} publishers of {topic} on domain {self.domain_id}: ' \
            'another process shares this ROS domain'

    def spin_until(self, predicate: Callable[[], bool], timeout: float,
                   what: str = 'condition', process: NodeProcess | None = None) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return
            if process is not None and not process.alive():
                raise AssertionError(f'node exited ({process.process.returncode}) while '
                                     f'waiting for {what}; log:\n{process.output()[-3000:]}')
            self.executor.spin_once(timeout_sec=0.02)
        log = process.output()[-3000:] if process is not None else ''
        raise AssertionError(f'timed out after {timeout} s waiting for {what}\n{log}')

    def call(self, service_type, name: str, request, timeout: float = 10.0):
        client = self.node.create_client(service_type, name)
        try:
            self.spin_until(client.service_is_ready, timeout, f'service {name}')
            future = client.call_async(request)
            self.spin_until(future.done, timeout, f'response of {name}')
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def parse_cloud(cloud) -> np.ndarray:
    """The PointCloud2 bytes as a numpy structured array, decoded here from the message's
    own field table (independently of the adapter's reader)."""
    numpy_types = {7: '<f4', 8: '<f8', 2: '<u1', 4: '<u2', 6: '<u4', 1: '<i1', 3: '<i2',
                   5: '<i4'}
    assert not cloud.is_bigendian
    dtype = np.dtype({'names': [f.name for f in cloud.fields],
                      'formats': [numpy_types[f.datatype] for f in cloud.fields],
                      'offsets': [f.offset for f in cloud.fields],
                      'itemsize': cloud.point_step})
    assert len(cloud.data) == cloud.width * cloud.height * cloud.point_step
    return np.frombuffer(bytes(cloud.data), dtype=dtype)


def cloud_positions(cloud) -> np.ndarray:
    points = parse_cloud(cloud)
    return np.stack([points['x'], points['y'], points['z']], axis=1).astype(np.float64)


def set_parameters(client, **values) -> list:
    types = {bool: (ParameterType.PARAMETER_BOOL, 'bool_value'),
             int: (ParameterType.PARAMETER_INTEGER, 'integer_value'),
             float: (ParameterType.PARAMETER_DOUBLE, 'double_value'),
             str: (ParameterType.PARAMETER_STRING, 'string_value')}
    parameters = []
    for name, value in values.items():
        if isinstance(value, list):
            value_msg = ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                                       double_array_value=value)
        else:
            kind, field = types[type(value)]
            value_msg = ParameterValue(type=kind, **{field: value})
        parameters.append(Parameter(name=name.replace('__', '.'), value=value_msg))
    response = client.call(SetParameters, '/paper_sim/set_parameters',
                           SetParameters.Request(parameters=parameters))
    return response.results
