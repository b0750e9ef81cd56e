#!/usr/bin/env bash
# One entry point for a fresh machine (only Python 3.11 + pip needed):
#   ./dev.sh run  [demo options]   set up .venv if needed, then run the simulation + SLAM demo
#   ./dev.sh test                  set up if needed, then everything CI checks: ruff (format and lint),
#                                  turtlelib's tests in a venv without ROS (.venv-core) beside the rest of
#                                  the suite in .venv (tests/turtlelib runs once; its output comes after
#                                  the suite's); each pytest run prints its 20 slowest tests
#   ./dev.sh test [pytest options] set up if needed, then only pytest with these options
#   ./dev.sh lint                  ruff format --check and ruff check
#   ./dev.sh datasets ARGS         set up if needed, then EKF SLAM on a real dataset (docs/real_data.md)
#   ./dev.sh replay BAG ARGS       set up if needed, then replay a rosbag2 recording into slam (docs/replay.md)
# Set-up is idempotent: an install is redone only when pyproject.toml changes.
set -euo pipefail
cd "$(dirname "$0")"
root=$PWD

# setup VENV EXTRAS: create VENV if missing and install the project with EXTRAS, unless already done
setup_venv() {
  local venv=$1 extras=$2
  local py=$venv/bin/python stamp=$venv/.installed-pyproject.sha256
  if [ ! -x "$py" ]; then
    echo "[dev.sh] creating $venv"
    "${PYTHON:-python3.11}" -m venv "$venv" 2>/dev/null || python3 -m venv "$venv"
  fi
  local want
  want=$(sha256sum pyproject.toml | cut -d' ' -f1)
  if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    return 0
  fi
  echo "[dev.sh] installing the project [$extras] into $venv"
  "$py" -m pip install --quiet --disable-pip-version-check -e ".[$extras]"
  echo "$want" > "$stamp"
}

venv=$root/.venv
py=$venv/bin/python
setup() { setup_venv "$venv" "ros,demo,test"; }

lint() {
  echo "[dev.sh] ruff format --check and ruff check"
  "$venv/bin/ruff" format --check --quiet .
  "$venv/bin/ruff" check --quiet .
}

# turtlelib's tests where ROS is not installed: numpy, scipy, pytest and hypothesis only
core_tests() {
  setup_venv "$root/.venv-core" "core-test"
  echo "[dev.sh] tests/turtlelib in .venv-core (no ROS)"
  for module in rclpy yaml; do
    if "$root/.venv-core/bin/python" -c "import $module" 2>/dev/null; then
      echo "[dev.sh] .venv-core must hold numpy, scipy, pytest and hypothesis only, but has $module" >&2
      exit 1
    fi
  done
  "$root/.venv-core/bin/python" -P -m pytest -q -p no:cacheprovider --durations=20 tests/turtlelib
}

# Shared-machine hygiene: one BLAS thread (2-core machines stall on small matrices otherwise),
# ROS logs under .venv rather than ~/.ros.
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
export ROS_HOME=${ROS_HOME:-$venv/ros_home} ROS_LOG_DIR=${ROS_LOG_DIR:-$venv/ros_home/log}
export RMW_IMPLEMENTATION=${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}

cmd=${1:-}
shift || true
# -P: the source folders must not shadow the installed packages
case "$cmd" in
  run) setup; exec "$py" -P -m nuturtle_demo "$@" ;;
  test)
    if [ $# -gt 0 ]; then setup; exec "$py" -P -m pytest "$@"; fi
    # the ROS-free venv installs while the main one does (two pip processes on two cores)
    setup_venv "$root/.venv-core" "core-test" &
    core_setup=$!
    setup
    wait "$core_setup"
    lint
    # two cores: turtlelib's tests (CPU-bound, one BLAS thread) run beside the suite (mostly waiting on
    # DDS and processes); their output is printed once both have ended
    core_log=$(mktemp)
    core_tests > "$core_log" 2>&1 &
    core_pid=$!
    echo "[dev.sh] the suite in .venv, tests/turtlelib left out (it runs in .venv-core beside it)"
    suite_status=0
    "$py" -P -m pytest --ignore=tests/turtlelib --durations=20 || suite_status=$?
    core_status=0
    wait "$core_pid" || core_status=$?
    cat "$core_log"
    rm -f "$core_log"
    if [ "$core_status" -ne 0 ]; then echo "[dev.sh] tests/turtlelib failed (.venv-core)" >&2; fi
    if [ "$suite_status" -ne 0 ]; then echo "[dev.sh] the suite failed (.venv)" >&2; fi
    [ "$core_status" -eq 0 ] && exit "$suite_status"
    exit "$core_status"
    ;;
  lint) setup; lint ;;
  setup) setup ;;
  datasets) setup; exec "$py" -P -m nuturtle_eval.datasets "$@" ;;
  replay) setup; exec "$py" -P -m nuturtle_tools.replay "$@" ;;
  *) echo "usage: ./dev.sh run|test|lint|setup|datasets|replay [args]" >&2; exit 2 ;;
esac
