import sys

from swarmbed.netem.proxy import main

sys.exit(main())
