"""deploy/docker-compose.composed.yml, the composed alternative to one container per
scenario service: valid Compose over the main file, and the host it runs is the one
`pnav up --processes composed` runs (pnav.run.host), as the same identity and roles."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from common.contract import acl
from pnav.run.credentials import ZENOH_PASSWORDS
from tests.deploy.test_compose import compose, schema_errors
from tests.deploy.test_swap import merged

COMPOSED_FILE = Path(__file__).resolve().parents[2] / "deploy" / "docker-compose.composed.yml"
HOSTED = ("strategy", "planner", "controller", "decision")


def composed() -> dict[str, Any]:
    doc = yaml.safe_load(COMPOSED_FILE.read_text())
    assert isinstance(doc, dict)
    return doc


def test_the_composed_file_follows_the_compose_specification_schema() -> None:
    assert schema_errors(merged(compose(), composed())) == []


def test_the_host_replaces_the_four_containers_as_their_union() -> None:
    services = merged(compose(), composed())["services"]
    for name in HOSTED:  # not started unless the "separate" profile is asked for
        assert services[name]["profiles"] == ["separate"]
    host = services["host"]
    assert host["command"] == ["python", "-m", "pnav.run.host", *HOSTED]
    env = host["environment"]
    assert env["PNAV_ZENOH_USER"] == acl.host_identity(HOSTED) == acl.DEFAULT_HOSTS[0]
    assert env["PNAV_ZENOH_PASSWORD"] == (
        f"${{{ZENOH_PASSWORDS[acl.DEFAULT_HOSTS[0]]}:?set {ZENOH_PASSWORDS[acl.DEFAULT_HOSTS[0]]}}}"
    )
    for name in HOSTED:  # each service its own role: the URL the one-service container has
        assert (
            env[f"PNAV_DATABASE_URL_{name.upper()}"]
            == (services[name]["environment"]["PNAV_DATABASE_URL"])
        )
    assert "PNAV_DATABASE_URL" not in env
    # the router of the main file knows the host identity
    assert acl.DEFAULT_HOSTS[0] in {s["id"] for s in acl.access_control()["subjects"]}
