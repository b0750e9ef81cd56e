"""``python -m nuturtle_demo``: the simulation + SLAM demo (see nuturtle_demo.cli)."""

import sys

from .cli import main

sys.exit(main())
