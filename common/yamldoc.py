"""YAML documents as every part of the project reads them (worlds, maps, robot models,
benchmark suites): ``yaml.safe_load``'s documents, parsed by libyaml where PyYAML was built
with it.

PyYAML's own parser is pure Python: the BARN-protocol suite of 45 world files took 7.6 s to
load with it (1.1 s with libyaml's), before ``pnav bench nav`` could start a run. libyaml's
parser feeds the same safe constructor, so the documents (types, tags, the YAML 1.1 rules
for booleans and numbers) are the same; only the wording of a syntax error differs. Both
raise ``yaml.YAMLError``.
"""

from __future__ import annotations

from typing import Any

import yaml

# libyaml's parser with PyYAML's safe constructor, or PyYAML's own where it has no libyaml
_LOADER: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load(text: str) -> Any:
    """The YAML document in ``text`` (``yaml.safe_load``'s result); raises yaml.YAMLError."""
    return yaml.load(text, Loader=_LOADER)
