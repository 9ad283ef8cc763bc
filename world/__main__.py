"""``python -m world``: the world process of a distributed run (see `world.node`)."""

import sys

from world.node import main

sys.exit(main())
