"""swarmbed: a Zenoh-networked emulation testbed for decentralized multi-robot task allocation.

The project's folders stay at the top of the repository and install as subpackages of this one
namespace (``wire/`` is ``swarmbed.wire``, ``cli/`` is ``swarmbed.cli``, ...): pyproject.toml lists
them, docs/ARCHITECTURE.md says what each holds and what it may import.
"""

import os as _os
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("swarmbed")
except PackageNotFoundError:  # running from a checkout that was never installed
    __version__ = "0+unknown"

# In a checkout, this folder sits beside the subpackages' folders: Python started in the checkout's
# root (``python -m swarmbed ...``, and every process it spawns) finds this folder first, before any
# installed copy, and must then find the subpackages beside it.
_checkout = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))
if all(_os.path.isfile(_os.path.join(_checkout, name, "__init__.py")) for name in ("wire", "netem", "coordinator")):
    __path__.append(_checkout)
