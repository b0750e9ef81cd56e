"""``python -m nuturtle_demo``: the simulation + SLAM demo (see nuturtle_demo.cli)."""

import os
import sys

# One BLAS thread unless the caller says otherwise, set before numpy loads OpenBLAS (which reads it once):
# slam's small matrices gain nothing from threads that contend for the cores the nodes run on.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from .cli import main

sys.exit(main())
