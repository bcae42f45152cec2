"""``python -m swarmbed ...`` is the ``swarmbed`` command."""

import sys

from swarmbed.cli.main import main

sys.exit(main())
