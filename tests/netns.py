"""The ``lab`` fixture: stand-in hosts (network namespaces, one ``swarmbed host`` each) for a test."""

import pytest

from swarmbed.hosts.netns import LabError, make_lab


@pytest.fixture
def lab(tmp_path):
    """A bridge for stand-in hosts; ``lab.add_host(name)`` adds one. Skips, with the reason, where
    namespaces cannot be made (no root, no iproute2)."""
    try:
        the_lab = make_lab(tmp_path / "hosts")
    except LabError as exc:
        pytest.skip(str(exc))
    try:
        yield the_lab
    finally:
        the_lab.close()
