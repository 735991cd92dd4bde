#!/usr/bin/env bash
# tools/bootstrap.sh: make the repository's environment ready, idempotently.
#
#   1. .venv/ (python3 -m venv) with the pinned requirements (requirements/ros.txt,
#      requirements/python.txt, constrained by requirements/lock.txt). Re-run only when the
#      hash of requirements/*.txt (and the python version) changed: no pip call otherwise.
#   2. The cmake include-path fix of the ROS message wheels:
#      their exported cmake files name the wheel-build container's Python/numpy include
#      directories; they are rewritten to this interpreter's. Idempotent.
#   3. colcon build of src/ into build/ install/ log/ at the repository root. Re-run only when
#      the packaging sources changed (package.xml, setup.*, CMakeLists.txt, msg/srv, resource,
#      launch, config/, the set of Python module files) or the venv changed. Python module
#      contents are not part of it: tools/env.sh puts src/tmgwr_common, src/maze_sim and src/tmgwr_agent first
#      on PYTHONPATH, so editing core code never needs a rebuild.
#   4. The numba kernels (src/tmgwr_agent/tmgwr_agent/core/kernels.py) compiled into their
#      on-disk cache (python -m tmgwr_agent.warmup: "compiling the numba kernels (once,
#      about N s)"), so that a node's first start loads them instead of compiling. Re-run
#      when kernels.py changed (numba's own key: its mtime and size), the cache is gone, or
#      the venv changed; a run that finds them cached takes about a second.
#
# Usage: tools/bootstrap.sh [--force] [--rebuild] [--status]
#   --force    reinstall the requirements and rebuild
#   --rebuild  rebuild the workspace only
#   --status   print what would be done and exit (0 when nothing is to be done)
# Environment: TMGWR_PYTHON (interpreter for the venv, default python3),
#              TMGWR_VERBOSE=1 (show pip and colcon output).
# Quiet when nothing is to be done; one progress line per heavy step; on failure the tail of
# the step's log and its path on stderr, exit status 1.

set -eo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
REQ_DIR="$ROOT/requirements"
REQ_STAMP="$VENV/.tmgwr-requirements.sha256"
ROOT_STAMP="$VENV/.tmgwr-root"
BUILD_STAMP="$ROOT/build/.tmgwr-build.sha256"
LOG_DIR="$ROOT/log/bootstrap"
PYTHON="${TMGWR_PYTHON:-python3}"

FORCE=0
REBUILD=0
STATUS=0
for arg in "$@"; do
    case "$arg" in
        --force) FORCE=1; REBUILD=1 ;;
        --rebuild) REBUILD=1 ;;
        --status) STATUS=1 ;;
        -h|--help) sed -n '2,29p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "tmgwr bootstrap: unknown option: $arg" >&2; exit 2 ;;
    esac
done

die() { echo "tmgwr bootstrap: error: $*" >&2; exit 1; }
say() { echo "tmgwr bootstrap: $*" >&2; }

# Run a step with its output in a log file (or on the terminal with TMGWR_VERBOSE=1).
run_step() {
    local name="$1"; shift
    mkdir -p "$LOG_DIR"
    local log="$LOG_DIR/$name.log"
    if [ -n "${TMGWR_VERBOSE:-}" ]; then
        if ! "$@" 2>&1 | tee "$log" >&2; then
            die "step '$name' failed (log: $log)"
        fi
    elif ! "$@" >"$log" 2>&1; then
        echo "---- last lines of $log ----" >&2
        tail -n 40 "$log" >&2
        echo "----" >&2
        die "step '$name' failed; full log: $log"
    fi
}

requirements_hash() {
    # The venv's python version (pyvenv.cfg) and the requirement files: cheap, no interpreter.
    { grep -E '^version' "$VENV/pyvenv.cfg" 2>/dev/null || true; cat "$REQ_DIR"/*.txt; } |
        sha256sum | cut -d' ' -f1
}

# Everything a colcon build depends on, except the Python modules (used from src/ directly).
build_hash() {
    (
        cd "$ROOT"
        {
            find src -type f \
                \( -name package.xml -o -name setup.py -o -name setup.cfg \
                   -o -name CMakeLists.txt -o -name '*.cmake' -o -name '*.msg' -o -name '*.srv' \
                   -o -name '*.action' -o -path '*/resource/*' -o -path '*/launch/*' \
                   -o -path '*/config/*' -o -path '*/mazes/*' \) \
                -not -path '*/__pycache__/*' -print0 2>/dev/null | sort -z | xargs -0 -r sha256sum
            # The set of Python modules (names, not contents): a new module or subpackage
            # reaches the installed copy that `ros2 run` and `colcon test` use.
            find src -name '*.py' -not -path '*/__pycache__/*' 2>/dev/null | sort
            cat "$REQ_STAMP" 2>/dev/null || true
        } | sha256sum | cut -d' ' -f1
    )
}

venv_ok() {
    # -e follows the bin/python symlink: fails when the base interpreter is gone.
    [ -x "$VENV/bin/python" ] && [ -e "$VENV/bin/python" ] && [ -f "$VENV/pyvenv.cfg" ] &&
        [ "$(cat "$ROOT_STAMP" 2>/dev/null)" = "$ROOT" ]
}

need_pip() {
    [ "$FORCE" = 1 ] && return 0
    venv_ok || return 0
    [ "$(cat "$REQ_STAMP" 2>/dev/null)" = "$(requirements_hash)" ] || return 0
    return 1
}

KERNELS_PY="$ROOT/src/tmgwr_agent/tmgwr_agent/core/kernels.py"
KERNELS_CACHE="${NUMBA_CACHE_DIR:-$(dirname "$KERNELS_PY")/__pycache__}"
# one stamp per cache location (NUMBA_CACHE_DIR may point elsewhere for a while)
KERNELS_STAMP="$ROOT/build/.tmgwr-kernels-$(echo "$KERNELS_CACHE" | sha256sum | cut -c1-12).stamp"

# What decides whether the numba cache is still valid: numba keys it on the source file's
# mtime and size; the venv (numba's version); the cache files.
kernels_key() {
    {
        stat -c '%Y %s' "$KERNELS_PY" 2>/dev/null || true
        cat "$REQ_STAMP" 2>/dev/null || true
        find "$KERNELS_CACHE" -name 'kernels.*.nbi' 2>/dev/null | sort || true
    } | sha256sum | cut -d' ' -f1
}

need_warm() {
    [ -f "$KERNELS_PY" ] || return 1
    [ "$(cat "$KERNELS_STAMP" 2>/dev/null)" = "$(kernels_key)" ] || return 0
    return 1
}

need_build() {
    [ "$REBUILD" = 1 ] && return 0
    [ -f "$ROOT/install/setup.bash" ] || return 0
    [ "$(cat "$BUILD_STAMP" 2>/dev/null)" = "$(build_hash)" ] || return 0
    return 1
}

# ---------------------------------------------------------------- fast path (no lock, no pip)
if ! need_pip && ! need_build && ! need_warm; then
    [ "$STATUS" = 1 ] && echo "tmgwr bootstrap: up to date" >&2
    exit 0
fi
if [ "$STATUS" = 1 ]; then
    need_pip && echo "tmgwr bootstrap: requirements to (re)install into $VENV" >&2
    need_build && echo "tmgwr bootstrap: workspace to (re)build" >&2
    need_warm && echo "tmgwr bootstrap: numba kernels to compile (or check) in their cache" >&2
    exit 1
fi

# ---------------------------------------------------------------- one bootstrap at a time
mkdir -p "$ROOT/build"
if command -v flock >/dev/null 2>&1; then
    exec 9>"$ROOT/build/.tmgwr-bootstrap.lock"
    if ! flock -n 9; then
        say "waiting for another bootstrap of this repository to finish..."
        flock 9
    fi
fi

# ---------------------------------------------------------------- checks of the machine
check_machine() {
    "$PYTHON" - <<'EOF' || die "Python 3.11 to 3.14 is needed for the ROS 2 Jazzy wheels (got '$PYTHON'; set TMGWR_PYTHON)"
import sys
sys.exit(0 if (3, 11) <= sys.version_info[:2] <= (3, 14) else 1)
EOF
    [ "$(uname -m)" = x86_64 ] || die "the ROS 2 Jazzy wheels exist for x86_64 (manylinux_2_28) only, not $(uname -m)"
    local tool
    for tool in cmake make gcc g++; do
        command -v "$tool" >/dev/null 2>&1 ||
            die "'$tool' not found: building tmgwr_interfaces needs it (Debian: apt-get install -y cmake build-essential)"
    done
}

# ---------------------------------------------------------------- 1. venv + requirements
DID_PIP=0
if need_pip; then
    DID_PIP=1
    check_machine
    if [ "$FORCE" = 1 ] || ! venv_ok; then
        if [ -e "$VENV" ]; then
            say "recreating $VENV (missing, broken, or the repository moved)"
            rm -rf "$VENV" "$ROOT/build" "$ROOT/install"
            mkdir -p "$ROOT/build"
        fi
        run_step venv "$PYTHON" -m venv "$VENV" ||
            die "python3 -m venv failed (Debian: apt-get install -y python3-venv)"
        echo "$ROOT" >"$ROOT_STAMP"
    fi
    say "installing pinned requirements into .venv (first run: about 1-2 minutes)..."
    rm -f "$REQ_STAMP"
    run_step pip env -u PYTHONPATH -u _ROS_WHEELS_BOOTSTRAP_COMPLETE \
        "$VENV/bin/python" -m pip install --disable-pip-version-check --no-input \
        -r "$REQ_DIR/ros.txt" -r "$REQ_DIR/python.txt" -c "$REQ_DIR/lock.txt"
fi

# ---------------------------------------------------------------- 2. cmake include-path fix
fix_cmake_paths() {
    env -u PYTHONPATH "$VENV/bin/python" - "$VENV" <<'EOF'
"""Rewrite the wheel-build container's include paths in the wheels' exported cmake files."""
import glob, os, re, sys, sysconfig
import numpy

venv = sys.argv[1]
py_inc = sysconfig.get_paths()['include']
np_inc = numpy.get_include()
if not os.path.isfile(os.path.join(py_inc, 'Python.h')):
    sys.exit(f'Python headers missing: {py_inc}/Python.h (Debian: apt-get install -y python3-dev)')
pat_np = re.compile(r'/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/(?:_core/|core/)?include')
pat_py = re.compile(r'/opt/python/cp3\d+-cp3\d+/include/python3\.\d+')
fixed = 0
for path in glob.glob(os.path.join(venv, 'share', '*', 'cmake', '*.cmake')):
    with open(path, encoding='utf-8', errors='surrogateescape') as f:
        text = f.read()
    if '/opt/python/' not in text:
        continue
    new = pat_py.sub(lambda m: py_inc, pat_np.sub(lambda m: np_inc, text))
    if '/opt/python/' in new:
        sys.exit(f'unexpected container path left in {path}')
    with open(path, 'w', encoding='utf-8', errors='surrogateescape') as f:
        f.write(new)
    fixed += 1
print(f'cmake include paths rewritten in {fixed} file(s)')
EOF
}

if [ "$DID_PIP" = 1 ]; then
    run_step cmake-fix fix_cmake_paths
    requirements_hash >"$REQ_STAMP"
fi

# ---------------------------------------------------------------- 3. colcon build
if need_build; then
    check_machine
    run_step cmake-fix fix_cmake_paths
    say "building the colcon workspace (src/ -> build/ install/)..."
    rm -f "$BUILD_STAMP"
    build_env=(
        env -u PYTHONPATH -u COLCON_PREFIX_PATH -u AMENT_CURRENT_PREFIX
        -u _ROS_WHEELS_BOOTSTRAP_COMPLETE
        "VIRTUAL_ENV=$VENV" "PATH=$VENV/bin:$PATH"
        "AMENT_PREFIX_PATH=$VENV" "CMAKE_PREFIX_PATH=$VENV"
        "PYTHONDONTWRITEBYTECODE=1"
        # colcon-cmake would pass "-jN -lN": the load limit serialises the rosidl build as
        # soon as anything else runs on a 2-core machine.
        "MAKEFLAGS=-j$(nproc 2>/dev/null || echo 2)"
    )
    ( cd "$ROOT" && run_step colcon "${build_env[@]}" "$VENV/bin/colcon" --log-base "$ROOT/log" \
        build --base-paths "$ROOT/src" --build-base "$ROOT/build" --install-base "$ROOT/install" \
        --event-handlers console_direct+ desktop_notification- terminal_title- \
        --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF )
    [ -f "$ROOT/install/setup.bash" ] || die "colcon build produced no install/setup.bash (log: $LOG_DIR/colcon.log)"
    build_hash >"$BUILD_STAMP"
fi

# ---------------------------------------------------------------- 4. numba kernels
# The nodes import the core from src/ (tools/env.sh): its cache is the one they read.
if need_warm; then
    rm -f "$KERNELS_STAMP"
    ( cd "$ROOT" && env -u _ROS_WHEELS_BOOTSTRAP_COMPLETE \
        "PYTHONPATH=$ROOT/src/tmgwr_common:$ROOT/src/maze_sim:$ROOT/src/tmgwr_agent" \
        "$VENV/bin/python" -m tmgwr_agent.warmup --quiet --prefix "tmgwr bootstrap: " \
        >&2 ) || die "compiling the numba kernels failed (python -m tmgwr_agent.warmup)"
    kernels_key >"$KERNELS_STAMP"
fi
exit 0
