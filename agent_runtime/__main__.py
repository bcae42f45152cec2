import sys

from swarmbed.agent_runtime.process import main

sys.exit(main())
