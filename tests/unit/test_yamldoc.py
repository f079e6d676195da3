"""common.yamldoc reads the same documents as ``yaml.safe_load`` (faster, with libyaml where
PyYAML has it), and refuses what it refuses, but for one thing: a number in exponent
notation that YAML 1.1 reads as text (``1.0e308``, ``1e308``) is a number."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from common import yamldoc

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted(p for folder in ("worlds", "models") for p in (ROOT / folder).rglob("*.yaml"))


def test_every_shipped_yaml_file_reads_as_safe_load_reads_it() -> None:
    assert len(SHIPPED) > 50  # worlds, maps, benchmark suites, robot models
    for path in SHIPPED:
        text = path.read_text()
        assert yamldoc.load(text) == yaml.safe_load(text), path


@pytest.mark.parametrize(
    "text",
    [
        "a: yes\nb: No\nc: on\nd: OFF\ne: ~\nf: null\n",  # YAML 1.1 booleans and nulls
        "i: 010\nj: 0x1f\nk: 1_000\nm: 1.5e-3\nn: .inf\no: -.Inf\np: 12:30\nq: 6.02e+23\n",
        "t: 2026-11-27\nu: 2026-11-27T20:13:00Z\nv: '2026-11-27'\n",
        "base: &b {x: 1, y: [1, 2]}\nderived:\n  <<: *b\n  y: [3]\n",  # anchors, merge keys
        "- [1, 2.5, 'three']\n- {a: [], b: {}}\n- !!str 42\n- !!float 1\n",
        "resolution: 0.05\norigin: [-10.0, -10.0, 0.0]\nimage: map.pgm\n",
        "",  # an empty document
    ],
)
def test_tricky_documents_read_the_same(text: str) -> None:
    assert yamldoc.load(text) == yaml.safe_load(text)


@pytest.mark.parametrize("text", ["a: [1, 2\n", "a: b: c\n", "!!python/object:os.system x\n"])
def test_what_safe_load_refuses_is_refused(text: str) -> None:
    with pytest.raises(yaml.YAMLError):
        yaml.safe_load(text)
    with pytest.raises(yaml.YAMLError):
        yamldoc.load(text)


@pytest.mark.parametrize(
    ("text", "number"),
    [
        ("1.0e308", 1.0e308),  # YAML 1.1 wants a signed exponent
        ("1e308", 1.0e308),  # and a dot
        ("2e-3", 0.002),
        ("-1E+3", -1000.0),
        (".5e3", 500.0),
        ("1_0e2", 1000.0),
    ],
)
def test_exponent_notation_is_read_as_the_number_it_is(text: str, number: float) -> None:
    assert isinstance(yaml.safe_load(f"v: {text}")["v"], str)  # what YAML 1.1 would read
    assert yamldoc.load(f"v: {text}") == {"v": number}
    assert yamldoc.load(f"- {text}\n- [{text}]\n") == [number, [number]]


@pytest.mark.parametrize("text", ["'1e3'", '"1e3"', "!!str 1e3", "e3", "1e", "1e3x", "1.0.0e3"])
def test_what_is_not_a_plain_number_in_exponent_notation_stays_text(text: str) -> None:
    assert isinstance(yamldoc.load(f"v: {text}")["v"], str)


def test_the_safe_loader_itself_is_left_as_it_was() -> None:
    yamldoc.load("v: 1e3")
    assert yaml.safe_load("v: 1e3") == {"v": "1e3"}
