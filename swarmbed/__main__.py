"""``python -m swarmbed ...`` is the ``swarmbed`` command."""

import sys

from swarmbed.experiments.cli import main

sys.exit(main())
