#!/usr/bin/env bash
# `make setup`: build the development environment in .venv, in stages, each redone
# only when its inputs changed (content hashes in .venv/.hopper-stamps/):
#   deps  - create .venv, pip install the pinned ROS 2 wheels and Python deps
#           (inputs: requirements/*.txt)
#   msgs  - generate and compile msg/*.msg with rosidl through CMake and install them into
#           the venv prefix (inputs: deps, msg/*.msg, CMakeLists.txt, package.xml)
#   pkg   - pip install -e . (console scripts; inputs: deps, setup.py, package.xml,
#           hopper_ros/nodes/registry.py)
#   foxglove - npm ci of Foxglove's MCAP / ROS 2 libraries into .venv/foxglove, for
#           test/test_foxglove.py (inputs: test/foxglove/package*.json); skipped, and said so,
#           where Node.js or npm is absent
#   kernels - the numba kernels compiled into their disk cache (tools/warm_kernels.py; inputs: pkg,
#           the kernels' sources and their times)
# The no-op path runs no Python at all (every venv Python is re-executed once by
# ros-wheels-bootstrapper), only sha256sum over the inputs.
#
# Environment: HOPPER_PYTHON (interpreter for the venv, default python3; the ROS 2 Kilted
# wheels are cp311 builds, so it must be a Python 3.11), HOPPER_SETUP_JOBS (build jobs).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
STAMPS="$VENV/.hopper-stamps"
BUILD="$VENV/.hopper-build"           # CMake build tree of the messages
PYTHON="${HOPPER_PYTHON:-python3}"
JOBS="${HOPPER_SETUP_JOBS:-$(nproc 2>/dev/null || echo 2)}"
# Bump when the steps below change in a way that needs a rebuild.
SETUP_VERSION=1

cd "$ROOT"

say() { printf 'setup: %s\n' "$*"; }

# sha256 over names and contents of the given files (missing ones count as empty).
hash_files() {
  local f
  for f in "$@"; do
    printf '%s\n' "$f"
    if [[ -f "$f" ]]; then sha256sum < "$f"; fi
  done | sha256sum | cut -d' ' -f1
}

# stage_current NAME KEY: true when stage NAME was completed with KEY.
stage_current() {
  [[ -f "$STAMPS/$1" ]] && [[ "$(<"$STAMPS/$1")" == "$2" ]]
}
stage_done() {
  mkdir -p "$STAMPS"
  printf '%s\n' "$2" > "$STAMPS/$1.tmp"
  mv "$STAMPS/$1.tmp" "$STAMPS/$1"
}

# Copy SRC to DST only when the content differs.
install_if_changed() {
  if ! cmp -s "$1" "$2"; then
    cp "$1" "$2"
    say "installed $2"
  fi
}

shopt -s nullglob
msg_files=(msg/*.msg)
shopt -u nullglob

# ---------------------------------------------------------------- deps
deps_key="v$SETUP_VERSION $ROOT $(hash_files requirements/ros.txt requirements/python.txt requirements/test.txt)"
if [[ -x "$VENV/bin/python" ]] && stage_current deps "$deps_key"; then
  say "deps up to date"
else
  if [[ ! -x "$VENV/bin/python" ]]; then
    if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      echo "setup: $PYTHON is not Python 3.11 (the ROS 2 Kilted wheels are cp311 builds);" \
        "set HOPPER_PYTHON=/path/to/python3.11" >&2
      exit 1
    fi
    say "creating $VENV with $PYTHON"
    "$PYTHON" -m venv "$VENV"
  fi
  say "installing pinned ROS 2 wheels, Python dependencies and test tools (requirements/*.txt)"
  "$VENV/bin/python" -m pip install --progress-bar off \
    -r requirements/ros.txt -r requirements/python.txt -r requirements/test.txt
  stage_done deps "$deps_key"
fi
# colcon must not mistake the ROS wheels' share/*/package.xml in .venv for packages.
[[ -f "$VENV/COLCON_IGNORE" ]] || : > "$VENV/COLCON_IGNORE"

site_packages=("$VENV"/lib/python3*/site-packages)
if [[ ${#site_packages[@]} -ne 1 || ! -d "${site_packages[0]}" ]]; then
  echo "setup: cannot find the site-packages of $VENV" >&2
  exit 1
fi
site_packages="${site_packages[0]}"

# Start-up hook: AMENT_PREFIX_PATH includes the venv, DDS stays on loopback (the Fast DDS
# profile it installs is a copy of hopper_ros/dds/fastdds_loopback.xml in the venv).
mkdir -p "$VENV/share/hopper_ros/dds"
install_if_changed hopper_ros/dds/fastdds_loopback.xml "$VENV/share/hopper_ros/dds/fastdds_loopback.xml"
install_if_changed tools/hopper_ros_env.pth "$site_packages/hopper_ros_env.pth"

# ---------------------------------------------------------------- msgs
# Generated Python of the messages: its own directory, merged into the hopper_ros package
# by hopper_ros/__init__.py (pkgutil.extend_path reads site-packages/hopper_ros.pkg).
interfaces_rel="lib/hopper_ros_interfaces"
msgs_key="$deps_key $(hash_files CMakeLists.txt package.xml "${msg_files[@]}")"
if stage_current msgs "$msgs_key" && [[ -d "$VENV/$interfaces_rel/hopper_ros/msg" ]]; then
  say "msgs up to date"
else
  say "generating and compiling ${#msg_files[@]} messages (rosidl + CMake), log: $BUILD/build.log"
  # A removed or renamed message leaves stale generated files in the build tree: start over
  # when the set of messages changed.
  msg_list="${msg_files[*]}"
  if [[ -f "$STAMPS/msg-list" && "$(<"$STAMPS/msg-list")" != "$msg_list" ]]; then
    # what the previous build installed goes first (its manifest goes with the build tree)
    if [[ -f "$BUILD/install_manifest.txt" ]]; then
      xargs -d '\n' rm -f < "$BUILD/install_manifest.txt"
    fi
    rm -rf "$BUILD"
  fi
  mkdir -p "$BUILD"
  log="$BUILD/build.log"
  : > "$log"
  run() {
    if ! "$@" >> "$log" 2>&1; then
      tail -n 80 "$log" >&2
      echo "setup: FAILED: $*" >&2
      exit 1
    fi
  }
  # The prerequisites of the message build (README.md, "Prerequisites"), said before anything runs.
  command -v cmake > /dev/null || { echo "setup: cmake is missing (the messages of msg/ are built with it):" \
    "install cmake 3.20 or later, e.g. apt install cmake" >&2; exit 1; }
  command -v c++ > /dev/null || command -v g++ > /dev/null || command -v clang++ > /dev/null || {
    echo "setup: no C++ compiler (c++, g++ or clang++) for the messages of msg/: e.g. apt install g++" >&2; exit 1; }
  # Only the venv is the ROS prefix; a sourced ROS install must not leak into this build.
  (
    unset PYTHONPATH
    export CMAKE_PREFIX_PATH="$VENV" AMENT_PREFIX_PATH="$VENV"
    run cmake -S "$ROOT" -B "$BUILD" \
      -DHOPPER_VENV_BUILD=ON \
      -DHOPPER_VENV_PYTHON_INSTALL_DIR="$interfaces_rel" \
      -DCMAKE_INSTALL_PREFIX="$VENV" \
      -DPython3_EXECUTABLE="$VENV/bin/python" \
      -DCMAKE_BUILD_TYPE=Release \
      -DBUILD_TESTING=OFF
    run cmake --build "$BUILD" -j "$JOBS"
    # Uninstall what the previous install put into the venv, then install.
    if [[ -f "$BUILD/install_manifest.txt" ]]; then
      xargs -d '\n' rm -f < "$BUILD/install_manifest.txt"
    fi
    run cmake --install "$BUILD"
  )
  printf '%s\n' "$msg_list" > "$STAMPS/msg-list"
  stage_done msgs "$msgs_key"
fi
pkg_file="$(mktemp)"
printf '%s\n' "$VENV/$interfaces_rel/hopper_ros" > "$pkg_file"
install_if_changed "$pkg_file" "$site_packages/hopper_ros.pkg"
rm -f "$pkg_file"

# ---------------------------------------------------------------- pkg
pkg_key="$deps_key $(hash_files setup.py package.xml hopper_ros/nodes/registry.py)"
if stage_current pkg "$pkg_key"; then
  say "pkg up to date"
else
  say "pip install -e . (console scripts: hopper + one per node of hopper_ros/nodes/registry.py)"
  "$VENV/bin/python" -m pip install --progress-bar off --no-deps --no-build-isolation -e "$ROOT"
  stage_done pkg "$pkg_key"
fi

# ---------------------------------------------------------------- foxglove
# Foxglove's own libraries (@mcap/core, @foxglove/rosmsg, @foxglove/rosmsg2-serialization),
# pinned with their closure in test/foxglove/package-lock.json, installed with this machine's
# npm into an ignored folder; test/test_foxglove.py opens our bags with them.
FOXGLOVE="$VENV/foxglove"
foxglove_key="v$SETUP_VERSION $(hash_files test/foxglove/package.json test/foxglove/package-lock.json)"
if ! command -v node > /dev/null 2>&1 || ! command -v npm > /dev/null 2>&1; then
  say "foxglove skipped: no Node.js/npm on this machine (test/test_foxglove.py is skipped)"
elif stage_current foxglove "$foxglove_key" && [[ -d "$FOXGLOVE/node_modules" ]]; then
  say "foxglove up to date"
else
  say "installing Foxglove's MCAP and ROS 2 libraries with npm (test/foxglove/package-lock.json)"
  rm -rf "$FOXGLOVE"
  mkdir -p "$FOXGLOVE"
  cp test/foxglove/package.json test/foxglove/package-lock.json "$FOXGLOVE/"
  if ! (cd "$FOXGLOVE" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error); then
    echo "setup: FAILED: npm ci in $FOXGLOVE (is the npm registry reachable?)" >&2
    exit 1
  fi
  stage_done foxglove "$foxglove_key"
fi
# ---------------------------------------------------------------- kernels
# Every numba kernel compiled into the disk cache once here (tools/warm_kernels.py), not by each process that first
# needs it (make test's sessions and simulated robots side by side). numba also checks its sources' times, so
# those are in the key with their contents.
kernel_sources=(hopper_ros/physics/*.py hopper_ros/diagnosis/compiled.py hopper_ros/sim/plant.py tools/warm_kernels.py)
kernels_key="$pkg_key ${NUMBA_CACHE_DIR:-} $(hash_files "${kernel_sources[@]}") $(stat -c %Y "${kernel_sources[@]}" | sha256sum | cut -c1-16)"
if stage_current kernels "$kernels_key"; then
  say "kernels up to date"
else
  "$VENV/bin/python" tools/warm_kernels.py
  stage_done kernels "$kernels_key"
fi
say "ready: $VENV"
