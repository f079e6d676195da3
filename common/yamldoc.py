"""YAML documents as every part of the project reads them (worlds, maps, robot models,
benchmark suites): ``yaml.safe_load``'s documents, parsed by libyaml where PyYAML was built
with it, with one difference: a number in exponent notation is a number.

PyYAML follows YAML 1.1, where a float needs a dot and a signed exponent: ``1.0e+308`` is a
number, but ``1.0e308``, ``1e308`` and ``2e-3`` are strings, so a file saying
``max_linear_mps: 1e308`` got "must be a number, got '1e308'" for what is obviously a
number. Here they are read as the numbers they are (YAML 1.2's core schema reads them so),
and checked as numbers: the field's bound then refuses ``1e308`` and names the bound. A
plain scalar only: ``'1e3'`` in quotes, or ``!!str 1e3``, stays a string. Everything else
is ``yaml.safe_load``'s: the YAML 1.1 rules for booleans (``yes``, ``off``) and the other
numbers, tags, anchors and merge keys.

PyYAML's own parser is pure Python: the BARN-protocol suite of 45 world files took 7.6 s to
load with it (1.1 s with libyaml's), before ``pnav bench nav`` could start a run. libyaml's
parser feeds the same safe constructor and resolver, so the documents are the same; only the
wording of a syntax error differs. Both raise ``yaml.YAMLError``.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Collection, Mapping
from typing import Any

import yaml

# libyaml's parser with PyYAML's safe constructor, or PyYAML's own where it has no libyaml
_BASE: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

# A number with an exponent that YAML 1.1 leaves a string: no dot (1e308), or an unsigned
# exponent (1.0e308). Those YAML 1.1 reads as floats already match too; harmless.
EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$")


class _Loader(_BASE):  # type: ignore[misc]
    """The safe loader, with exponent notation read as a float."""


# add_implicit_resolver copies the base's table first: yaml.SafeLoader itself is unchanged
_Loader.add_implicit_resolver("tag:yaml.org,2002:float", EXPONENT_FLOAT, list("-+0123456789."))


def load(text: str) -> Any:
    """The YAML document in ``text``; raises yaml.YAMLError."""
    return yaml.load(text, Loader=_Loader)


def unknown_key(doc: Mapping[Any, Any], known: Collection[str]) -> Any | None:
    """The first key of the mapping ``doc``, in the file's order, that is not in ``known``
    (None: every key is known): a typo must be refused, never silently ignored."""
    return next((key for key in doc if key not in known), None)


def unknown_key_problem(key: Any, known: Collection[str], what: str = "key") -> str:
    """``unknown key 'battry' (did you mean 'battery'? known: battery, id, x, y)``: what
    to say of ``key``, with difflib's closest known name when there is one."""
    close = difflib.get_close_matches(str(key), sorted(known), n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"unknown {what} {str(key)!r} ({hint}known: {', '.join(sorted(known))})"
