"""Who may write what: the *Roles* table of CONTRACT.md, read into typed grants.

CONTRACT.md is the one place a writer is named; this module reads its *Roles: who may write
what* table so the Postgres GRANTs (common.contract.roles) and the Zenoh router's access
control (common.contract.acl) are both derived from it, never written twice.

A row is ``| object | role | may |``: a table (or a function, ``name()``), the short name of
a role (``bridge`` for ``pnav_bridge``), and a comma list of privileges, each optionally with
a column list: ``INSERT, UPDATE (status, reason)``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cache
from importlib import resources

from common.contract.keys import ROBOT_LEASE
from common.errors import InternalError

ROLE_PREFIX = "pnav_"
# Owns every table and function and applies migrations; cannot log in (common.contract.roles).
OWNER = "owner"
# People: the CLI and dashboards.
USER = "user"
# The services that connect to Postgres, each as its own role (the sim does not connect).
SERVICES = ("bridge", "strategy", "planner", "controller", "decision")
LOGIN_ROLES = (*SERVICES, USER)
# Every service on the bus (the Zenoh identities), the sim included.
BUS_IDENTITIES = ("sim", *SERVICES, USER)

TABLE_PRIVILEGES = frozenset(("INSERT", "UPDATE", "DELETE"))
FUNCTION_PRIVILEGES = frozenset(("EXECUTE",))

_SECTION = "## Roles: who may write what"
_PRIVILEGE = re.compile(r"\s*([A-Z]+)\s*(?:\(([^)]*)\))?\s*(?:,|$)")
_NAME = re.compile(r"^[a-z_][a-z0-9_]*$")


def role_name(short: str) -> str:
    """``planner`` -> ``pnav_planner``."""
    return f"{ROLE_PREFIX}{short}"


@dataclass(frozen=True)
class Grant:
    """One privilege of one role on one table or function."""

    object: str  # a table name, or a function's name followed by "()"
    role: str  # the short name: "bridge"
    privilege: str  # INSERT, UPDATE, DELETE or EXECUTE
    columns: tuple[str, ...] = ()  # a column grant; empty: the whole table

    @property
    def is_function(self) -> bool:
        return self.object.endswith("()")

    @property
    def name(self) -> str:
        """The table's or function's name, without the ``()``."""
        return self.object.removesuffix("()")

    def sql(self) -> str:
        """The GRANT statement (quoting is not needed: every name matched ``_NAME``)."""
        if self.is_function:
            return f"GRANT {self.privilege} ON FUNCTION {self.object} TO {role_name(self.role)}"
        cols = f" ({', '.join(self.columns)})" if self.columns else ""
        return f"GRANT {self.privilege}{cols} ON TABLE {self.object} TO {role_name(self.role)}"


def _privileges(cell: str, where: str) -> list[tuple[str, tuple[str, ...]]]:
    out: list[tuple[str, tuple[str, ...]]] = []
    pos = 0
    cell = cell.strip()
    while pos < len(cell):
        match = _PRIVILEGE.match(cell, pos)
        if match is None or match.end() == pos:
            raise InternalError(f"CONTRACT.md roles, {where}: cannot read {cell[pos:]!r}")
        columns = tuple(c.strip() for c in (match[2] or "").split(",") if c.strip())
        out.append((match[1], columns))
        pos = match.end()
    return out


def parse_grants(text: str) -> tuple[Grant, ...]:
    """The grants of the *Roles* table in CONTRACT.md ``text``."""
    lines = text.splitlines()
    try:
        start = lines.index(_SECTION)
    except ValueError:
        raise InternalError(f"CONTRACT.md has no section {_SECTION!r}") from None
    grants: list[Grant] = []
    for line in lines[start + 1 :]:
        if line.startswith("## "):
            break
        if not line.startswith("| ") or line.startswith("| object"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3:
            raise InternalError(f"CONTRACT.md roles: a row needs 3 cells: {line!r}")
        obj, role, may = cells
        where = f"row {obj!r} / {role!r}"
        if not _NAME.match(obj.removesuffix("()")) or role not in (OWNER, *LOGIN_ROLES):
            raise InternalError(f"CONTRACT.md roles, {where}: unknown object or role")
        allowed = FUNCTION_PRIVILEGES if obj.endswith("()") else TABLE_PRIVILEGES
        for privilege, columns in _privileges(may, where):
            bad = [c for c in columns if not _NAME.match(c)]
            if privilege not in allowed or bad or (columns and privilege != "UPDATE"):
                raise InternalError(f"CONTRACT.md roles, {where}: {privilege} {columns}")
            grants.append(Grant(obj, role, privilege, columns))
    if not grants:
        raise InternalError("CONTRACT.md roles: the table is empty")
    return tuple(grants)


@cache
def contract_grants() -> tuple[Grant, ...]:
    """The grants of the shipped CONTRACT.md."""
    text = resources.files("common.contract").joinpath("CONTRACT.md").read_text()
    return parse_grants(text)


def role_grants(role: str, grants: tuple[Grant, ...] | None = None) -> tuple[Grant, ...]:
    """The grants of one role (short name)."""
    return tuple(g for g in (grants or contract_grants()) if g.role == role)


def written_tables(role: str, grants: tuple[Grant, ...] | None = None) -> frozenset[str]:
    """The tables ``role`` may INSERT into or UPDATE: those it announces on the bus."""
    return frozenset(
        g.name
        for g in role_grants(role, grants)
        if not g.is_function and g.privilege in ("INSERT", "UPDATE")
    )


def lease_holders(grants: tuple[Grant, ...] | None = None) -> tuple[str, ...]:
    """The roles (short names) that may hold robot leases, and so take advisory locks at all:
    those that may INSERT into robot_lease (its history is written by the holders only).
    Every other login role is refused every advisory lock (common.contract.roles)."""
    return tuple(
        sorted(
            {
                g.role
                for g in (grants or contract_grants())
                if g.name == ROBOT_LEASE and g.privilege == "INSERT" and g.role != OWNER
            }
        )
    )
