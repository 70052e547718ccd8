#!/usr/bin/env bash
# The real-Blender lane: Debian 13's Blender 4.3 and Debian unstable's Blender 5.x in cached chroots,
# headless runs against the bpy module and the sidebar panel driven in a window (Xvfb, xdotool).
#   tests/blender/run_lane.sh [--screenshots DIR] [--figures FILE] [pytest args...]
# Skips (exit 0, one line "SKIP: reason") where the chroots cannot be built: not root, no debootstrap,
# no network, not enough disk. Bounded in time: chroots 15 min at most (4 min measured), tests BPY_PIPELINE_LANE_TIMEOUT s (default 600).
set -euo pipefail
cd "$(dirname "$0")/../.."
PY="${PYTHON:-.venv/bin/python}"
while [ $# -gt 0 ]; do
  case "$1" in
    --screenshots) export BPY_PIPELINE_SCREENSHOTS="$(realpath -m "$2")"; shift 2 ;;
    --figures) export BPY_PIPELINE_REAL_BLENDER_FIGURES="$(realpath -m "$2")"; shift 2 ;;
    *) break ;;
  esac
done
if ! command -v debootstrap >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  apt-get install -y -q debootstrap >/dev/null 2>&1 || true
fi
status=0
timeout 900 tests/blender/chroots.sh trixie sid || status=$?
if [ $status = 3 ]; then exit 0; fi  # chroots.sh printed "SKIP: reason"
if [ $status != 0 ]; then echo "SKIP: building the Blender chroots failed or took over 15 min (exit $status)"; exit 0; fi
export BPY_PIPELINE_REAL_BLENDER=1
# outputs, logs and screenshots of the last lane stay in $BPY_PIPELINE_LANE_TMP (replaced by the next run)
exec timeout "${BPY_PIPELINE_LANE_TIMEOUT:-600}" "$PY" -m pytest -q -p no:cacheprovider \
  --basetemp "${BPY_PIPELINE_LANE_TMP:-/var/tmp/bpy_pipeline_lane}" tests/blender "$@"
