"""The suite's own scheduling: under ``--dist loadgroup`` (the README's test command) each test of an
``xdist_group`` runs with its group, so a group's shared fixtures are built once (tests/conftest.py)."""
from __future__ import annotations

import os

import pytest

pytestmark = pytest.mark.xdist_group("suite_groups")


def test_a_grouped_test_carries_its_group_under_loadgroup(request):
    # a worker of ``--dist loadgroup`` has the option ``loadgroup`` set (pytest-xdist's remote.setup_config)
    if os.environ.get("PYTEST_XDIST_WORKER") is None or not getattr(request.config.option, "loadgroup", False):
        pytest.skip("only under pytest-xdist --dist loadgroup")
    # pytest-xdist names the group in the test's node id, and schedules by that name
    assert request.node.nodeid.endswith("@suite_groups"), (
        f"{request.node.nodeid!r}: pytest-xdist did not group this test (see the pytest pin in pyproject.toml)")
