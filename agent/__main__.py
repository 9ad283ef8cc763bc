"""``python -m agent``: one robot process of a distributed run (see `agent.node`)."""

import sys

from agent.node import main

sys.exit(main())
