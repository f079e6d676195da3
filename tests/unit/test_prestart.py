"""A process started ahead of its environment (pnav.run.prestart,
pnav.run.process_supervisor.Prestart) runs its module with the environment sent to it, as
``python -m`` would have; closed empty, or not taken, it ends without running it."""

from __future__ import annotations

import json
import os
import sys

import pytest

from pnav.run.prestart import Prestart

pytestmark = pytest.mark.timeout(60)

PROBE = [sys.executable, "-m", "tests.unit.prestart_probe", "--flag", "value"]


async def test_a_taken_process_runs_its_module_with_the_environment_sent() -> None:
    prestart = Prestart()
    await prestart.start([("probe", PROBE)])
    try:
        env = {**os.environ, "PROBE": "sent later"}
        warm = prestart.take("probe", PROBE, env)
        assert warm is not None
        out, _ = await warm.process.communicate()
        assert warm.process.returncode == 3  # the module's own exit code
        assert json.loads(out.decode().strip().splitlines()[-1]) == {
            "probe": "sent later",
            "argv": ["--flag", "value"],
        }
    finally:
        await prestart.close()


async def test_a_process_not_taken_ends_without_running_its_module() -> None:
    prestart = Prestart()
    await prestart.start([("probe", PROBE), ("other", PROBE)])
    warm = prestart.warm["probe"].process
    other = prestart.warm["other"].process
    # another command than the one started: let go, a new process must be started
    assert prestart.take("other", [*PROBE, "--more"], dict(os.environ)) is None
    await prestart.close()  # the rest: let go
    assert warm.returncode == 0 and other.returncode == 0
    assert not prestart.warm


async def test_a_command_not_a_module_is_not_started_ahead(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    prestart = Prestart()
    await prestart.start([("swapped", ["/bin/true"])])
    assert not prestart.warm
    monkeypatch.setenv("PNAV_PRESTART", "0")
    await prestart.start([("probe", PROBE)])
    assert not prestart.warm


async def test_an_interpreter_setting_that_changed_is_not_taken() -> None:
    prestart = Prestart()
    await prestart.start([("probe", PROBE)])
    try:
        env = {**os.environ, "PYTHONHASHSEED": "7"}  # read only when an interpreter starts
        assert prestart.take("probe", PROBE, env) is None
    finally:
        await prestart.close()


def _imports_node(code: str) -> bool:
    import subprocess

    probe = f"{code}; import sys; print('services.sim.node' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1] == "True"


def test_warming_a_module_runs_its_prestart_hook() -> None:
    """The sim imports its node only once it runs; started ahead, it imports it while it
    waits (services/sim/__main__.py, prestart)."""
    assert not _imports_node("import services.sim.__main__")
    assert _imports_node("from pnav.run.prestart import warm; warm('services.sim', [])")
