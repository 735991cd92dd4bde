#!/usr/bin/env bash
# tools/freeze.sh: regenerate requirements/lock.txt (the full transitive pin set) from a fresh
# throw-away venv built from requirements/ros.txt + requirements/python.txt (unconstrained).
# Review the diff, then commit it; tools/bootstrap.sh reinstalls when the hash changes.
set -eo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PYTHON="${TMGWR_PYTHON:-python3}"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
"$PYTHON" -m venv "$TMP/venv"
"$TMP/venv/bin/python" -m pip install -q --disable-pip-version-check --no-input \
    -r "$ROOT/requirements/ros.txt" -r "$ROOT/requirements/python.txt"
{
    echo "# Full transitive lock of the .venv (generated with pip from a fresh python3.11 venv; pip itself excluded)."
    echo "# Used as a constraints file (-c) by tools/bootstrap.sh; regenerate with tools/freeze.sh."
    # Only distributions pip installed: the ROS wheels also carry egg-info metadata of their
    # inner python packages (rclpy, std_msgs...), which are not installable names on PyPI.
    _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 "$TMP/venv/bin/python" - <<'PY'
import importlib.metadata as md
rows = sorted({(d.metadata['Name'].lower(), d.version) for d in md.distributions()
               if (d.read_text('INSTALLER') or '').strip() == 'pip'
               and d.metadata['Name'].lower() != 'pip'})
print(''.join(f'{n}=={v}\n' for n, v in rows), end='')
PY
} >"$ROOT/requirements/lock.txt"
echo "wrote $ROOT/requirements/lock.txt ($(grep -vc '^#' "$ROOT/requirements/lock.txt") pins)"
