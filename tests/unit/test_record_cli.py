"""``--record FILE`` is checked before anything starts: a recording is never overwritten."""

from __future__ import annotations

from pathlib import Path

import pytest

from pnav.cli import program as cli


@pytest.mark.parametrize("command", ["up", "demo"])
def test_an_existing_file_is_refused_in_one_line(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    existing = tmp_path / "run.mcap"
    existing.write_bytes(b"earlier")
    assert cli.main([command, "--record", str(existing)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the file exists" in err[0] and str(existing) in err[0]
    assert existing.read_bytes() == b"earlier"


def test_a_missing_folder_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["demo", "--record", str(tmp_path / "nowhere" / "run.mcap")]) == 2
    assert "no folder" in capsys.readouterr().err
