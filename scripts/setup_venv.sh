#!/usr/bin/env bash
# Create .venv with the pinned dependency set, repair the ROS wheels' CMake paths,
# build the pneumatic_unload_msgs interface package into the venv and install
# pneumatic_unload in editable mode. Idempotent: every step skips work already done.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${VENV:-.venv}"
PYTHON="${PYTHON:-python3}"

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] first run: creating $VENV (seconds), then the steps below; later runs skip"
  echo "[setup]   what is done"
  "$PYTHON" -m venv "$VENV"
fi
VPY="$VENV/bin/python"
VENV_ABS="$(cd "$VENV" && pwd)"

if ! cmp -s requirements.lock "$VENV/.requirements.lock"; then
  NPKG="$(grep -c '==' requirements.lock)"
  echo "[setup] installing the pinned set (requirements.lock, $NPKG packages, ~1 GB with"
  echo "[setup]   the ROS 2 wheels): 5-20 min on a first run, depending on the network;"
  echo "[setup]   under a minute from pip's cache. Each package is listed as it is fetched."
  # a line a minute while pip unpacks or downloads without a word; stopped on any exit
  ( trap 'kill $! 2>/dev/null; exit 0' TERM; t=0
    while :; do sleep 60 & wait $!; t=$((t + 1)); echo "[setup]   ... pip still working ($t min)"; done ) &
  HEARTBEAT=$!
  trap 'kill "$HEARTBEAT" 2>/dev/null || true' EXIT
  # pip's "Collecting" lines numbered; its "Location ... is ignored" lines come from this
  # machine's pip config: noise. pip's whole output is kept in $VENV/pip-install.log.
  "$VPY" -m pip install --disable-pip-version-check --progress-bar off -r requirements.lock 2>&1 \
    | tee "$VENV/pip-install.log" | { k=0; while IFS= read -r line; do case "$line" in
        *"is ignored: it is neither a file nor a directory"*) ;;
        "Collecting "*) k=$((k + 1)); read -r _ name _ <<<"$line"; echo "[setup]   $k/$NPKG $name" ;;
        "Installing collected packages"*) echo "[setup]   unpacking the packages into the venv (1-3 min)" ;;
        "Successfully installed"*) echo "[setup]   done: $(wc -w <<<"${line#Successfully installed}") package(s) installed" ;;
        ERROR*|WARNING*) echo "$line" ;;
      esac; done; } \
    || { echo "[setup] pip failed; its whole output: $VENV/pip-install.log" >&2; exit 1; }
  kill "$HEARTBEAT" 2>/dev/null || true
  cp requirements.lock "$VENV/.requirements.lock"
  rm -f "$VENV/.msgs-built"
fi

# The wheels' exported CMake files hard-code the wheel-build host's include dirs.
PYINC="$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
NPINC="$("$VPY" -c 'import numpy; print(numpy.get_include())')"
grep -rlZ --include='*.cmake' '/opt/python/cp3' "$VENV_ABS/share" 2>/dev/null | xargs -0 -r sed -i -E \
  -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#$PYINC#g" \
  -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#$NPINC#g" \
  || true

# Build the interface package when its sources changed since the last build.
MSG_HASH="$(cat pneumatic_unload_msgs/package.xml pneumatic_unload_msgs/CMakeLists.txt pneumatic_unload_msgs/msg/* pneumatic_unload_msgs/action/* | sha256sum | cut -d' ' -f1)"
if [ "$(cat "$VENV/.msgs-built" 2>/dev/null)" != "$MSG_HASH" ]; then
  echo "[setup] building pneumatic_unload_msgs into $VENV (1-3 min)"
  rm -rf build/msg_defs && mkdir -p build
  AMENT_PREFIX_PATH="$VENV_ABS" cmake -S pneumatic_unload_msgs -B build/msg_defs \
    -DCMAKE_PREFIX_PATH="$VENV_ABS" -DCMAKE_INSTALL_PREFIX="$VENV_ABS" \
    -DPython3_EXECUTABLE="$VENV_ABS/bin/python" -DBUILD_TESTING=OFF >build/msg_defs.log 2>&1 \
    || { cat build/msg_defs.log; exit 1; }
  AMENT_PREFIX_PATH="$VENV_ABS" cmake --build build/msg_defs -j 2 >>build/msg_defs.log 2>&1 \
    || { tail -50 build/msg_defs.log; exit 1; }
  cmake --install build/msg_defs >>build/msg_defs.log 2>&1 || { tail -50 build/msg_defs.log; exit 1; }
  echo "$MSG_HASH" > "$VENV/.msgs-built"
fi

PKG_HASH="$(cat pneumatic_unload/setup.py pneumatic_unload/setup.cfg pneumatic_unload/package.xml | sha256sum | cut -d' ' -f1)"
if [ "$(cat "$VENV/.pkg-installed" 2>/dev/null)" != "$PKG_HASH" ]; then
  echo "[setup] installing pneumatic_unload (editable, its C kernel compiled: a few seconds)"
  "$VPY" -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation \
    --config-settings editable_mode=compat -e ./pneumatic_unload 2>&1 \
    | { grep -v "is ignored: it is neither a file nor a directory" || true; }
  echo "$PKG_HASH" > "$VENV/.pkg-installed"
fi
# The model's C kernel (pneumatic_unload/pneumatic_unload/model/kernel.c) and the estimator's crossing fit
# (estimation/regression.c), compiled once with cc: importing them does it too, but ahead
# of time no test process races to build them.
"$VPY" -c "from pneumatic_unload.model import kernel; kernel.build(); import pneumatic_unload.estimation.regression" \
  || { echo "[setup] building the model kernel failed (is gcc installed?)" >&2; exit 1; }
"$VPY" -c "import rclpy, pneumatic_unload, pneumatic_unload_msgs.msg" \
  || { echo "[setup] import check failed" >&2; exit 1; }
