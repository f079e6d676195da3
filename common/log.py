"""Structured logging: one line per event, ``key=value`` pairs after a short message.

Every service calls :func:`setup` once; code logs with ``log.info("msg", extra=fields(...))``
or the :func:`event` shortcut so a line can be grepped by robot, rule or table.
"""

from __future__ import annotations

import contextvars
import json
import logging
import os
import sys
import time
from typing import Any

_RESERVED = set(vars(logging.makeLogRecord({})).keys()) | {"message", "asctime"}
# The service a line is written for, when one process hosts several (pnav.run.host): each
# service's task sets it (:func:`speak_as`) and the tasks it starts inherit it, so every line
# names its own service; unset, the process's service (:func:`setup`) is named.
_SERVICE: contextvars.ContextVar[str | None] = contextvars.ContextVar("pnav_service", default=None)


def speak_as(service: str) -> None:
    """Name ``service`` on the lines of this task and of the tasks and callbacks it starts."""
    _SERVICE.set(service)


class KeyValueFormatter(logging.Formatter):
    """``2026-11-21T05:01:02.123Z INFO planner msg key=value ...``"""

    def __init__(self, service: str) -> None:
        super().__init__()
        self.service = service

    def format(self, record: logging.LogRecord) -> str:
        ts = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created))
        ms = int(record.msecs)
        service = _SERVICE.get() or self.service
        parts = [f"{ts}.{ms:03d}Z", record.levelname, service, record.getMessage()]
        for key, value in record.__dict__.items():
            if key not in _RESERVED and not key.startswith("_"):
                parts.append(f"{key}={_render(value)}")
        line = " ".join(parts)
        if record.exc_info:
            line += "\n" + self.formatException(record.exc_info)
        return line


def _render(value: Any) -> str:
    if isinstance(value, str) and value and " " not in value and "=" not in value:
        return value
    return json.dumps(value, default=str)


def setup(service: str, level: str | None = None) -> None:
    """Send every log line of this process to stderr in the key=value format."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(KeyValueFormatter(service))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel((level or os.environ.get("PNAV_LOG_LEVEL", "INFO")).upper())


def event(logger: logging.Logger, level: int, msg: str, **fields: Any) -> None:
    """Log ``msg`` with ``fields`` as key=value pairs."""
    if logger.isEnabledFor(level):
        logger.log(level, msg, extra=fields)
