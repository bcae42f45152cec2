"""swarmbed: a Zenoh-networked emulation testbed for decentralized multi-robot task allocation.

The project's folders (``wire/``, ``coordinator/``, ``agent_runtime/``, ``netem/``, ``plugins/``,
``experiments/``) stay at the top of the repository and install as subpackages of this one
namespace (``swarmbed.wire``, ``swarmbed.coordinator``, ...): see ``pyproject.toml``.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("swarmbed")
except PackageNotFoundError:  # running from a checkout that was never installed
    __version__ = "0+unknown"
