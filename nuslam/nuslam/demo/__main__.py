"""``python -m nuslam.demo``: the simulation + SLAM demo (see nuslam.demo.cli)."""

import sys

from .cli import main

sys.exit(main())
