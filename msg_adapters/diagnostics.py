"""Simulation statistics as ``diagnostic_msgs/DiagnosticArray`` (for ``/diagnostics``)."""
from __future__ import annotations

import math
from typing import Mapping

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

LEVEL_NAMES = {DiagnosticStatus.OK: 'OK', DiagnosticStatus.WARN: 'WARN',
               DiagnosticStatus.ERROR: 'ERROR', DiagnosticStatus.STALE: 'STALE'}


def format_value(value) -> str:
    """A diagnostic value as text: floats to 6 significant digits, the rest with str()."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        if math.isnan(value):
            return 'nan'
        return f'{value:.6g}'
    return str(value)


def diagnostic_status(name: str, hardware_id: str, level: bytes, message: str,
                      values: Mapping[str, object]) -> DiagnosticStatus:
    """One status with its key/value pairs, in the order given."""
    if level not in LEVEL_NAMES:
        raise ValueError(f'unknown diagnostic level {level!r}')
    return DiagnosticStatus(
        level=level, name=name, hardware_id=hardware_id, message=message,
        values=[KeyValue(key=str(key), value=format_value(value))
                for key, value in values.items()])


def diagnostic_array(stamp: Time, statuses: list[DiagnosticStatus]) -> DiagnosticArray:
    return DiagnosticArray(header=Header(stamp=stamp), status=list(statuses))


def values_of(status: DiagnosticStatus) -> dict[str, str]:
    """The key/value pairs of a status as a dict (for tests and tools)."""
    return {pair.key: pair.value for pair in status.values}
