#!/usr/bin/env bash
# One entry point for a fresh machine (only Python 3.11 + pip needed):
#   ./dev.sh run  [demo options]   set up .venv if needed, then run the simulation + SLAM demo
#   ./dev.sh test [pytest options] set up .venv if needed, then run the whole test suite
# Set-up is idempotent: the install is redone only when pyproject.toml changes.
set -euo pipefail
cd "$(dirname "$0")"
root=$PWD
venv=$root/.venv
py=$venv/bin/python
stamp=$venv/.installed-pyproject.sha256

setup() {
  if [ ! -x "$py" ]; then
    echo "[dev.sh] creating $venv"
    "${PYTHON:-python3.11}" -m venv "$venv" 2>/dev/null || python3 -m venv "$venv"
  fi
  want=$(sha256sum pyproject.toml | cut -d' ' -f1)
  if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    return 0
  fi
  echo "[dev.sh] installing the ROS 2 Jazzy wheels and the project into .venv"
  "$py" -m pip install --quiet --disable-pip-version-check -e ".[ros,demo,test]"
  echo "$want" > "$stamp"
}

# Shared-machine hygiene: one BLAS thread (2-core machines stall on small matrices otherwise),
# ROS logs under .venv rather than ~/.ros.
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
export ROS_HOME=${ROS_HOME:-$venv/ros_home} ROS_LOG_DIR=${ROS_LOG_DIR:-$venv/ros_home/log}
export RMW_IMPLEMENTATION=${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}

cmd=${1:-}
shift || true
case "$cmd" in
  run)  setup; exec "$py" -P -m nuturtle_demo "$@" ;;  # -P: the source folders must not shadow the installed packages
  test) setup; exec "$py" -P -m pytest "$@" ;;
  setup) setup ;;
  *) echo "usage: ./dev.sh run|test|setup [args]" >&2; exit 2 ;;
esac
