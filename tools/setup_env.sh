#!/usr/bin/env bash
# Create .venv with everything hmocap_ros needs, idempotently:
#   1. the pinned Python dependencies (ROS 2 Jazzy wheels, numpy, OpenCV, rosbags, ...);
#   2. the interface package msg_defs/ (hmocap_interfaces), built with CMake against the wheels;
#   3. tf2_msgs from msg_defs_tf2/ and hri_msgs from msg_defs_hri/, the same way, each only when
#      the environment has none of its own (the ROS 2 wheels on PyPI ship neither; a ROS install
#      keeps its own);
#   4. hmocap_ros itself in editable mode.
# Each step is skipped when its inputs have not changed since it last succeeded
# (stamp files in .venv/.hmocap/ hold a hash of the inputs).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=${HMOCAP_VENV:-.venv}
case $VENV in /*) ;; *) VENV=$ROOT/$VENV ;; esac
PY=${PYTHON:-python3}
STAMPS=$VENV/.hmocap

die() { echo "setup: ERROR: $*" >&2; exit 1; }
say() { echo "setup: $*"; }
hash_of() { cat "$@" | sha256sum | cut -c1-16; }
fresh() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
mark() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

command -v "$PY" >/dev/null || die "$PY not found: install CPython 3.11 (e.g. apt-get install python3 python3-venv)."
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11)' 2>/dev/null \
  || die "the ROS 2 Jazzy wheels need CPython 3.11; $PY is $("$PY" -V 2>&1). Set PYTHON=python3.11."

if [ ! -x "$VENV/bin/python" ]; then
  say "creating $VENV"
  "$PY" -m venv "$VENV" || die "could not create a venv (on Debian: apt-get install python3-venv)."
fi

# HMOCAP_PINS=FILE (make test-jazzy: requirements-jazzy.txt) replaces the pins of the packages it
# names, in requirements.txt and in the lock, by its own.
REQUIREMENTS=requirements.txt
LOCK=requirements-lock.txt
if [ -n "${HMOCAP_PINS:-}" ]; then
  [ -f "$HMOCAP_PINS" ] || die "HMOCAP_PINS names $HMOCAP_PINS, which does not exist."
  mkdir -p "$STAMPS"
  pinned() {  # $1 without the packages HMOCAP_PINS names or replaces ("# replaces NAME"), then HMOCAP_PINS
    "$PY" - "$1" "$HMOCAP_PINS" <<'PYEOF'
import re, sys
source, pins = sys.argv[1], open(sys.argv[2]).read().splitlines()
def name(line):
    m = re.match(r"\s*([A-Za-z0-9_.-]+)", line)
    return m.group(1).lower().replace("_", "-") if m and not line.lstrip().startswith("#") else None
names = {name(l) for l in pins} | {m.lower() for l in pins for m in re.findall(r"#\s*replaces\s+(\S+)", l)}
kept = [l for l in open(source).read().splitlines() if name(l) not in names]
print("\n".join(kept + pins))
PYEOF
  }
  pinned requirements.txt > "$STAMPS/requirements.txt"
  pinned requirements-lock.txt > "$STAMPS/requirements-lock.txt"
  REQUIREMENTS=$STAMPS/requirements.txt
  LOCK=$STAMPS/requirements-lock.txt
fi

deps=$(hash_of "$REQUIREMENTS" "$LOCK")
if ! fresh deps "$deps"; then
  say "installing pinned dependencies (about 30 s on a fresh machine)"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -r "$REQUIREMENTS" -c "$LOCK"
  mark deps "$deps"
fi

msgs=$(hash_of msg_defs/CMakeLists.txt msg_defs/package.xml msg_defs/pyproject.toml msg_defs/msg/*.msg msg_defs/srv/*.srv \
  requirements.txt)
if ! fresh interfaces "$msgs" || ! "$VENV/bin/python" -c 'import hmocap_interfaces.msg' 2>/dev/null; then
  for tool in cmake g++ make; do
    command -v $tool >/dev/null || die "'$tool' is needed to build msg_defs (hmocap_interfaces). On Debian: apt-get install cmake g++ make."
  done
  say "building the interface package hmocap_interfaces (msg_defs/, about 15 s)"
  rm -rf msg_defs/build
  CMAKE_PREFIX_PATH=$VENV AMENT_PREFIX_PATH=$VENV \
    "$VENV/bin/python" -m pip install -q --no-build-isolation --force-reinstall --no-deps \
      -C cmake.define.Python3_EXECUTABLE="$VENV/bin/python" ./msg_defs \
    || die "building msg_defs failed (see the CMake output above)."
  mark interfaces "$msgs"
fi

# tf2_msgs and hri_msgs: each built here unless another one imports (a ROS install's, a
# wheel's). The stamp marks one built here, which is rebuilt when its definitions change.
# fallback_interfaces NAME FOLDER WHAT
fallback_interfaces() {
  local name=$1 dir=$2 what=$3 inputs
  inputs=$(hash_of "$dir/CMakeLists.txt" "$dir/package.xml" "$dir/pyproject.toml" \
    $(find "$dir/msg" "$dir/srv" "$dir/action" -type f 2>/dev/null | sort) requirements.txt)
  if [ ! -f "$STAMPS/$name" ] && "$VENV/bin/python" -c "import $name.msg" 2>/dev/null; then
    say "using the installed $name ($("$VENV/bin/python" -c "import $name; print(list($name.__path__)[0])"))"
  elif ! fresh "$name" "$inputs" || ! "$VENV/bin/python" -c "import $name.msg" 2>/dev/null; then
    for tool in cmake g++ make; do
      command -v $tool >/dev/null || die "'$tool' is needed to build $dir ($name). On Debian: apt-get install cmake g++ make."
    done
    say "building $name ($dir/, none installed; $what)"
    rm -rf "$dir/build"
    CMAKE_PREFIX_PATH=$VENV AMENT_PREFIX_PATH=$VENV \
      "$VENV/bin/python" -m pip install -q --no-build-isolation --force-reinstall --no-deps \
        -C cmake.define.Python3_EXECUTABLE="$VENV/bin/python" "./$dir" \
      || die "building $dir failed (see the CMake output above)."
    mark "$name" "$inputs"
  fi
}
fallback_interfaces tf2_msgs msg_defs_tf2 "about 20 s"
fallback_interfaces hri_msgs msg_defs_hri "about 10 s"

pkg=$(hash_of setup.py setup.cfg package.xml)
# checked from / (not the checkout, which is on the path of `python -c`): an editable install
# finds only the packages that existed when it was made (hmocap_ros, hmocap_sim, hmocap_examples)
if ! fresh package "$pkg" || ! (cd / && "$VENV/bin/python" -c 'import hmocap_ros, hmocap_sim, hmocap_examples') 2>/dev/null; then
  say "installing hmocap_ros and hmocap_sim (editable)"
  # setuptools' notice that every editable install gets (folders named as the package shadow
  # it) is not a problem of this checkout: silenced, errors still show
  PYTHONWARNINGS=ignore::UserWarning "$VENV/bin/python" -m pip install -q --no-build-isolation --no-deps -e . \
    || die "pip install -e . failed."
  mark package "$pkg"
fi

"$VENV/bin/python" -c 'import rclpy, hmocap_interfaces.msg, tf2_msgs.msg, hri_msgs.msg, hmocap_ros' \
  || die "the environment is incomplete: rclpy, hmocap_interfaces, tf2_msgs, hri_msgs or hmocap_ros does not import."
say "ready ($VENV)"
