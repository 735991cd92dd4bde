# tools/env.sh: source from bash to get the project's ROS 2 environment in this shell:
#
#     tools/bootstrap.sh        # once (./tmgwr and make do it for you)
#     source tools/env.sh
#
# What it sets up (idempotent, safe to source again, silent unless something is wrong):
# - activates .venv (the ROS 2 Jazzy wheels, colcon, numpy, pytest...);
# - AMENT_PREFIX_PATH / CMAKE_PREFIX_PATH include the venv prefix (the wheels install
#   into it), then sources install/setup.bash (colcon workspace: tmgwr_interfaces,
#   maze_sim, tmgwr_agent) with `set -u` lifted while it runs;
# - LD_LIBRARY_PATH covers the venv's ROS libraries and _ROS_WHEELS_BOOTSTRAP_COMPLETE=1,
#   so python processes skip the wheels' self re-exec (children inherit a complete env);
# - PYTHONPATH starts with src/tmgwr_common, src/maze_sim and src/tmgwr_agent: `import maze_sim, tmgwr_agent`
#   resolves to the source trees, so editing core code never needs a rebuild;
# - ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (nothing leaves the machine),
#   RMW_IMPLEMENTATION=rmw_fastrtps_cpp, FASTRTPS_DEFAULT_PROFILES_FILE=tools/fastdds_localhost.xml
#   (fast discovery; UDP on 127.0.0.1 only, and shared memory). ROS_DOMAIN_ID is left as it
#   is. A graph over a LAN needs ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET and
#   FASTRTPS_DEFAULT_PROFILES_FILE=tools/fastdds_subnet.xml, exported after sourcing this.
# - TMGWR_ROOT = the repository root.

if [ -z "${BASH_VERSION:-}" ]; then
    echo "tools/env.sh: source this file from bash" >&2
    return 1 2>/dev/null || exit 1
fi

TMGWR_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export TMGWR_ROOT

if [ ! -x "$TMGWR_ROOT/.venv/bin/python" ] || [ ! -f "$TMGWR_ROOT/install/setup.bash" ]; then
    echo "tools/env.sh: the environment is not bootstrapped yet: run $TMGWR_ROOT/tools/bootstrap.sh" >&2
    return 1 2>/dev/null || exit 1
fi

# colcon's setup scripts reference unset variables: lift `set -u` while we work.
case $- in *u*) _tmgwr_nounset=1; set +u ;; *) _tmgwr_nounset=0 ;; esac

# _tmgwr_prepend VAR DIR...: put DIRs first in the colon list VAR, without duplicates.
_tmgwr_prepend() {
    local var="$1" dir rest out
    shift
    rest=":${!var:-}:"
    for dir in "$@"; do
        while [[ "$rest" == *":$dir:"* ]]; do rest="${rest//:$dir:/:}"; done
    done
    out="$(IFS=:; echo "$*")"
    rest="${rest#:}"; rest="${rest%:}"
    [ -n "$rest" ] && out="$out:$rest"
    export "$var=$out"
}

VIRTUAL_ENV_DISABLE_PROMPT="${VIRTUAL_ENV_DISABLE_PROMPT:-}"
# shellcheck disable=SC1091
. "$TMGWR_ROOT/.venv/bin/activate"

# The venv is the underlay: added when missing, never moved ahead of the workspace overlay.
[[ ":${AMENT_PREFIX_PATH:-}:" == *":$VIRTUAL_ENV:"* ]] || _tmgwr_prepend AMENT_PREFIX_PATH "$VIRTUAL_ENV"
[[ ":${CMAKE_PREFIX_PATH:-}:" == *":$VIRTUAL_ENV:"* ]] || _tmgwr_prepend CMAKE_PREFIX_PATH "$VIRTUAL_ENV"

# What the wheels' .pth bootstrapper would do by re-executing every python process.
_tmgwr_libs=("$VIRTUAL_ENV/lib")
for _tmgwr_d in "$VIRTUAL_ENV"/lib/python3.*/site-packages/ros_*.libs; do
    [ -d "$_tmgwr_d" ] && _tmgwr_libs+=("$_tmgwr_d")
done
_tmgwr_prepend LD_LIBRARY_PATH "${_tmgwr_libs[@]}"
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1

# shellcheck disable=SC1091
. "$TMGWR_ROOT/install/setup.bash"

_tmgwr_prepend PYTHONPATH "$TMGWR_ROOT/src/tmgwr_common" "$TMGWR_ROOT/src/maze_sim" "$TMGWR_ROOT/src/tmgwr_agent"

export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export FASTRTPS_DEFAULT_PROFILES_FILE="$TMGWR_ROOT/tools/fastdds_localhost.xml"

unset _tmgwr_d _tmgwr_libs
unset -f _tmgwr_prepend
[ "$_tmgwr_nounset" = 1 ] && set -u
unset _tmgwr_nounset
true
