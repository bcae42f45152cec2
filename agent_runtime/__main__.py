import sys

from agent_runtime.process import main

sys.exit(main())
