"""Every exception proactive-nav raises on purpose.

    PnavError                      base of all of them
    ├── UsageError                 the caller misused something; the message says how to fix it
    │   ├── ConfigError            an environment variable or option has a bad value
    │   ├── ContractError          a row, payload or key does not follow CONTRACT.md
    │   ├── WorldError             a world or map file cannot be loaded (names file + problem)
    │   └── ModelError             a robot model file is wrong (names file + field)
    ├── ConnectionFailure          Postgres or Zenoh could not be reached or was lost
    ├── MigrationError             the contract schema could not be applied
    └── InternalError              a bug in proactive-nav itself; please report it

Rules never see these from the engine: an exception raised inside a rule is caught, logged
with the rule's name and counted (see ``common.engine``), never re-raised.
"""

from __future__ import annotations


class PnavError(Exception):
    """Base class of every error raised by proactive-nav on purpose."""


class UsageError(PnavError):
    """The caller misused an API, a command or a file; the message says how to fix it."""


class ConfigError(UsageError):
    """A configuration value (environment variable or command-line option) is invalid."""


class ContractError(UsageError):
    """Data that does not follow the shared-database contract (CONTRACT.md)."""


class WorldError(UsageError):
    """A world file or map cannot be loaded; the message names the file and the problem."""


class ModelError(UsageError):
    """A robot model (models/*.yaml, or overrides of one) is wrong; the message names the file
    and the field, e.g. ``models/jackal.yaml: lidar.beams: ...``."""


class ConnectionFailure(PnavError):
    """Postgres or Zenoh could not be reached, or the connection was lost."""


class MigrationError(PnavError):
    """The contract's migrations could not be applied to the database."""


class InternalError(PnavError):
    """An invariant of proactive-nav itself was broken: a bug, not a misuse."""
