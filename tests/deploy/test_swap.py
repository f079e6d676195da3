"""Swapping a scenario service in the fleet (docs/SWAP.md), checked without a Docker engine.

- deploy/docker-compose.swap.yml: valid against the Compose Specification's schema, alone
  and merged over deploy/docker-compose.yml; it replaces the controller's command with
  ``python -m examples.sql_controller`` and changes nothing else.
- The image carries examples/ in its working directory, where ``python -m`` finds it.
- The example imports nothing of the project (``common``, ``services``, ``pnav``): the
  contract is all it uses.
- A process started as the swapped compose file starts it passes the controller's own
  health check while it runs, exits 0 on SIGTERM, and fails the check once it has stopped.
- ``docker compose config`` accepts both files together, when a docker client is here.
"""

from __future__ import annotations

import ast
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.deploy.test_compose import (
    COMPOSE_FILE,
    DEPLOY,
    ROOT,
    as_role,
    base_env,
    compose,
    dockerfile_instructions,
    environment,
    interpolated,
    run_health_check,
    schema_errors,
)

SWAP_FILE = DEPLOY / "docker-compose.swap.yml"
EXAMPLE = ROOT / "examples" / "sql_controller"
SWAPPED_COMMAND = ["python", "-m", "examples.sql_controller"]


def swap() -> dict[str, Any]:
    doc = yaml.safe_load(SWAP_FILE.read_text())
    assert isinstance(doc, dict)
    return doc


def merged(base: Any, override: Any) -> Any:
    """Compose's merge, for what the swap file holds: mappings merge key by key, and a
    ``command`` (like any scalar) is replaced, not appended to."""
    if isinstance(base, dict) and isinstance(override, dict):
        out = dict(base)
        for key, value in override.items():
            out[key] = merged(base[key], value) if key in base else value
        return out
    return override


def swapped() -> dict[str, Any]:
    doc: dict[str, Any] = merged(compose(), swap())
    return doc


def test_the_swap_file_follows_the_compose_specification_schema() -> None:
    assert schema_errors(swap()) == []
    assert schema_errors(swapped()) == []
    assert schema_errors(interpolated(swapped())) == []


def test_the_swap_replaces_the_controllers_command_and_nothing_else() -> None:
    assert swap() == {"services": {"controller": {"command": SWAPPED_COMMAND}}}
    before, after = compose(), swapped()
    assert after["services"]["controller"]["command"] == SWAPPED_COMMAND
    after["services"]["controller"]["command"] = before["services"]["controller"]["command"]
    assert after == before
    assert (EXAMPLE / "__main__.py").is_file()


def test_the_image_carries_the_examples_in_its_working_directory() -> None:
    instructions = dockerfile_instructions()
    copy = ("COPY", "examples/ examples/")
    assert copy in instructions
    # after the last WORKDIR (/app, where the command runs), and after the RUN that deletes
    # the build sources: so `python -m examples.sql_controller` finds it in the container
    position = instructions.index(copy)
    workdirs = [i for i, (keyword, _) in enumerate(instructions) if keyword == "WORKDIR"]
    assert instructions[workdirs[-1]] == ("WORKDIR", "/app") and workdirs[-1] < position
    assert not any(keyword == "RUN" for keyword, _ in instructions[position:])


def imports(path: Path) -> list[str]:
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


def test_the_example_uses_the_contract_only() -> None:
    project = {"common", "services", "pnav", "tests"}
    offenders = [
        f"{path.relative_to(ROOT)} imports {module}"
        for path in sorted((ROOT / "examples").rglob("*.py"))
        for module in imports(path)
        if module.split(".")[0] in project
    ]
    assert offenders == []
    assert "examples.sql_controller.policy" in imports(EXAMPLE / "controller.py")  # it reads


@pytest.mark.slow
def test_the_swapped_controller_started_as_compose_starts_it_turns_healthy_then_not(
    db_url: str, acl_router_endpoint: str
) -> None:
    """As the controller's role in Postgres and its user on a router with the compose access
    control: a replacement gets the credentials of the service it replaces."""
    service = swapped()["services"]["controller"]
    env = {**base_env(), **environment(interpolated(service))}
    assert env["PNAV_ZENOH_USER"] == "controller"
    env["PNAV_DATABASE_URL"] = as_role(db_url, "controller")
    env["PNAV_ZENOH_CONNECT"] = acl_router_endpoint
    command = [sys.executable if w == "python" else w for w in service["command"]]
    # cwd: the repository root holds examples/, as the image's working directory /app does
    process = subprocess.Popen(
        command, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + 60
        while True:
            result = run_health_check("controller", env)
            if result.returncode == 0:
                break
            assert process.poll() is None, f"it died: {process.communicate()[1][-2000:]}"
            assert time.monotonic() < deadline, f"never healthy: {result.stderr}"
            time.sleep(0.3)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=30) == 0, process.communicate()[1][-2000:]
        assert run_health_check("controller", env).returncode == 1
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_docker_compose_config_accepts_the_swap() -> None:
    docker = shutil.which("docker")
    if docker is None:
        pytest.skip("no docker client on this machine")
    version = subprocess.run(
        [docker, "compose", "version"], capture_output=True, text=True, timeout=60
    )
    if version.returncode != 0:
        pytest.skip("the docker client has no compose plugin")
    result = subprocess.run(
        [docker, "compose", "-f", str(COMPOSE_FILE), "-f", str(SWAP_FILE), "config"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr
    assert "examples.sql_controller" in result.stdout
