"""Fixtures of the deployment tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from pnav._testing import acl_router
from pnav.run.credentials import ZENOH_PASSWORDS
from tests.deploy.test_compose import ROUTER_CONFIG, SECRETS


@pytest.fixture
def acl_router_endpoint(tmp_path: Path) -> Iterator[str]:
    """A router from deploy/zenoh/router.json5 (access control, user/password), its
    dictionary the passwords of ``SECRETS``, on a free loopback port."""
    passwords = {user: SECRETS[var] for user, var in ZENOH_PASSWORDS.items()}
    with acl_router(ROUTER_CONFIG, passwords, tmp_path) as endpoint:
        yield endpoint
