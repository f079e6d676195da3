"""Scenarios found, not listed: Python entry points name the scenarios a service can run.

A scenario is a class in any installed package, named in the package's metadata under the
service's entry-point group (docs/ENGINE.md, "Adding a scenario"), e.g. in pyproject.toml::

    [project.entry-points."pnav.controller.scenarios"]
    avoid_left = "services.controller.avoid_left:AvoidLeft"

The entry point's name is the scenario's name, the one a strategy row uses; it must equal
the class's ``scenario`` attribute. A service calls :func:`load_scenarios` once at start:
a new scenario package needs ``pip install`` and a restart of the service, no edit of any
file of the service's.

An entry point that cannot be loaded (an import error, not a subclass of the service's
base, a name that disagrees with the class) is logged and skipped: one broken plug-in does
not take the service, and with it every robot, down. Two entry points claiming one name
are refused the same way: a scenario shipped with proactive-nav keeps its name whatever the
order of sys.path (a plug-in must never replace ``safety_stop`` by claiming its name), and
between two plug-ins the first in distribution order is kept.
"""

from __future__ import annotations

import logging
from importlib.metadata import EntryPoint, entry_points
from typing import TypeVar

from common import log

logger = logging.getLogger("pnav.plugins")

T = TypeVar("T")

# the distribution whose scenarios no plug-in can displace
SHIPPED = "proactive-nav"


def load_scenarios(group: str, base: type[T]) -> dict[str, type[T]]:
    """Scenario name -> class, for every loadable entry point of ``group``."""
    found: dict[str, type[T]] = {}
    # sorted() is stable: within the shipped and the foreign points, distribution order holds
    points = sorted(entry_points(group=group), key=lambda p: (p.name, not _shipped(p)))
    for point in points:
        cls = _load(point, base)
        if cls is None:
            continue
        if point.name in found and found[point.name] is not cls:
            log.event(
                logger,
                logging.ERROR,
                "scenario name claimed twice; the second is ignored",
                group=group,
                scenario=point.name,
                kept=_qualname(found[point.name]),
                ignored=point.value,
            )
            continue
        found[point.name] = cls
    return found


def _shipped(point: EntryPoint) -> bool:
    dist = point.dist
    return dist is not None and dist.name.replace("_", "-").lower() == SHIPPED


def _load(point: EntryPoint, base: type[T]) -> type[T] | None:
    try:
        cls = point.load()
    except Exception as exc:
        _ignored(
            point,
            "scenario plug-in cannot be loaded; ignored",
            error=f"{type(exc).__name__}: {exc}",
        )
        return None
    if not (isinstance(cls, type) and issubclass(cls, base)):
        why = f"not a subclass of {_qualname(base)}"
    elif getattr(cls, "scenario", point.name) != point.name:
        why = f"its class says scenario = {getattr(cls, 'scenario', None)!r}"
    else:
        return cls
    _ignored(point, "scenario plug-in refused; ignored", why=why)
    return None


def _ignored(point: EntryPoint, message: str, **detail: str) -> None:
    """Log ``point`` as ignored, naming it the same way whatever the reason."""
    log.event(
        logger,
        logging.ERROR,
        message,
        group=point.group,
        scenario=point.name,
        target=point.value,
        **detail,
    )


def _qualname(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"
