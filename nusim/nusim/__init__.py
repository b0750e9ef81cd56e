"""nusim ROS 2 package."""

import os

# the nodes' BLAS on one thread, set before numpy loads OpenBLAS (docs/robot.md, "CPU and memory")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
