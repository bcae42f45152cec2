import sys

from netem.proxy import main

sys.exit(main())
