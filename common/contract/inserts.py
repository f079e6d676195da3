"""A table's INSERT, its argument arrays and its row image, all from its declaration.

A writer names a declared :class:`~common.contract.columns.Table` and, where a record's
attribute is not the column's name, how the record gives that column; the statement, the
arguments and the image (CONTRACT.md "Row images") follow from the declaration, so a new
column is one edit there (and its migration), not one per writer.

A batch is ONE statement, all rows together:
``INSERT ... SELECT FROM unnest($1::text[], $2::float8[], ...) AS u(...) RETURNING ...``,
column arrays in, every new id out. An array column (a scan's ``ranges``, a command's
``considered_ids``) goes as one flat array with each row's first and last position, since
Postgres arrays cannot hold rows of arrays of different lengths: each row takes its slice.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from operator import attrgetter
from typing import Any

from common.contract.columns import FLOATS, INTS, Column, Table

Image = dict[str, Any]
Getter = Callable[[Any], Any]


def _is_array(column: Column) -> bool:
    return column.type in (FLOATS, INTS)


@dataclass(frozen=True)
class Insert:
    """How a writer's records become rows of ``table``.

    ``fields``: column -> how a record gives its value, where it is not the attribute of
    the column's name; ``images``: column -> its value in the image, where it is not what
    the INSERT sends (a ``real[]`` rounded to float32 as Postgres stores it).
    """

    table: Table
    fields: Mapping[str, Getter] = field(default_factory=dict)
    images: Mapping[str, Getter] = field(default_factory=dict)

    @property
    def columns(self) -> tuple[Column, ...]:
        return self.table.inserted

    @cached_property
    def _getters(self) -> list[tuple[Column, Getter]]:
        return [(c, self.fields.get(c.name) or attrgetter(c.name)) for c in self.columns]

    def batch_sql(self, *, returning: str = "id, robot_id", conflict: str = "") -> str:
        """The batched INSERT of :meth:`args`' arrays."""
        return self._batch(self.columns, returning, conflict, with_id=False)

    def replay_sql(self) -> str:
        """The same rows again with the ids they were given (the ids' array comes last):
        a row already there is kept, and RETURNING gives the ids written again."""
        return self._batch(self.columns, "id", "ON CONFLICT (id) DO NOTHING", with_id=True)

    def _batch(
        self, columns: Sequence[Column], returning: str, conflict: str, *, with_id: bool
    ) -> str:
        types: list[str] = []
        aliases: list[str] = []
        values: list[str] = []
        for column in columns:
            if _is_array(column):
                # the flat array is an argument of its own; unnest takes its slice bounds
                flat = len(types) + 1
                types += ["__flat__"]
                values.append(
                    f"(${flat}::{column.sql_type})[u.{column.name}_first:u.{column.name}_last]"
                )
                aliases += [f"{column.name}_first", f"{column.name}_last"]
                types += ["int4[]", "int4[]"]
            else:
                types.append(f"{column.sql_type}[]")
                aliases.append(column.name)
                values.append(f"u.{column.name}")
        names = [c.name for c in columns]
        if with_id:
            types.append("bigint[]")
            aliases.append("id")
            values.append("u.id")
            names.append("id")
        unnest = ", ".join(f"${i}::{t}" for i, t in enumerate(types, 1) if t != "__flat__")
        return (
            f"INSERT INTO {self.table.name} ({', '.join(names)})\n"
            f"SELECT {', '.join(values)}\n"
            f"FROM unnest({unnest}) AS u({', '.join(aliases)})\n"
            + (f"{conflict}\n" if conflict else "")
            + f"RETURNING {returning}"
        )

    def args(self, records: Sequence[Any]) -> list[Any]:
        """The argument arrays of :meth:`batch_sql` for ``records``, in its order."""
        out: list[Any] = []
        for column, get in self._getters:
            if _is_array(column):
                flat: list[Any] = []
                first: list[int] = []
                last: list[int] = []
                for record in records:
                    first.append(len(flat) + 1)  # Postgres arrays are 1-based, slices inclusive
                    flat.extend(get(record))
                    last.append(len(flat))
                out += [flat, first, last]
            else:
                out.append([get(record) for record in records])
        return out

    def values_sql(self, *, returning: str = "id") -> str:
        """The INSERT of one row (:meth:`values`' arguments)."""
        names = ", ".join(c.name for c in self.columns)
        params = ", ".join(f"${i}::{c.sql_type}" for i, c in enumerate(self.columns, 1))
        return f"INSERT INTO {self.table.name} ({names})\nVALUES ({params})\nRETURNING {returning}"

    def param(self, name: str) -> str:
        """``$n::type`` of column ``name`` in :meth:`values_sql`."""
        for i, column in enumerate(self.columns, 1):
            if column.name == name:
                return f"${i}::{column.sql_type}"
        raise KeyError(name)

    def values(self, record: Any) -> list[Any]:
        """The arguments of :meth:`values_sql` for one record."""
        return [
            list(get(record)) if _is_array(column) else get(record) for column, get in self._getters
        ]

    def image(self, record: Any) -> Image:
        """The row's image without its ``id``: every inserted column, as the table holds it."""
        out: Image = {}
        for column, get in self._getters:
            shown = self.images.get(column.name)
            if shown is not None:
                out[column.name] = shown(record)
            else:
                out[column.name] = list(get(record)) if _is_array(column) else get(record)
        return out
