#!/usr/bin/env bash
# Set up ./.venv with bpy_pipeline and Blender's bpy module (Debian 12, Python 3.11).
#   ./setup.sh        runtime: bpy 4.5 LTS, embreex, trimesh, pyyaml, numpy
#   ./setup.sh test   the same plus the test tools (pytest, plyfile, laspy), Ray (the distributed tests),
#                     numba (the compiled scan path), Patchwork++ / scipy (real-scan mixing) and LightGBM /
#                     scikit-learn (bpy-pipeline evaluate)
#   ./setup.sh [test] --missing   only print the Debian packages it would install (an empty line: none)
# On a bare Debian it installs, as root, what bpy's wheel and venv need from Debian:
# python3-venv, the X11/GL client libraries bpy links against (no display is used), Mesa's
# software OpenGL through EGL, which Blender's renderer needs (the KITTI camera's image_2), and with
# `test`, GCC's OpenMP runtime (libgomp1), which LightGBM loads.
set -euo pipefail
cd "$(dirname "$0")"
extras="blender"
missing_only=""
for arg in "$@"; do
  case "$arg" in
    test) extras="blender,test,distributed,fast,mixing,evaluate" ;;
    --missing) missing_only=1 ;;  # print the Debian packages it would install (one line, maybe empty), install nothing
    *) echo "setup.sh: unknown argument '$arg'; allowed: test, --missing" >&2; exit 2 ;;
  esac
done
venv="${VENV:-.venv}"
py="${PYTHON:-python3.11}"
"$py" -c "import sys; assert sys.version_info[:2] == (3, 11)" 2>/dev/null || py=python3
if ! "$py" -c "import sys; assert sys.version_info[:2] == (3, 11)" 2>/dev/null; then
  echo "setup.sh: needs Python 3.11 (the bpy 4.5 wheels are built for it); set PYTHON=/path/to/python3.11" >&2
  exit 1
fi

packages=()
"$py" -c "import ensurepip, venv" 2>/dev/null || packages+=(python3-venv)
declare -A lib_package=([libX11.so.6]=libx11-6 [libXrender.so.1]=libxrender1 [libXfixes.so.3]=libxfixes3 [libXi.so.6]=libxi6
  [libxkbcommon.so.0]=libxkbcommon0 [libXext.so.6]=libxext6 [libSM.so.6]=libsm6 [libGL.so.1]=libgl1
  [libEGL.so.1]=libegl1 [libEGL_mesa.so.0]=libegl-mesa0)
# LightGBM (the evaluate extra) loads GCC's OpenMP runtime, which a bare Debian does not have
[[ ",$extras," == *,evaluate,* ]] && lib_package[libgomp.so.1]=libgomp1
known_libs=$( (/sbin/ldconfig -p 2>/dev/null || ldconfig -p 2>/dev/null) || true)
for lib in "${!lib_package[@]}"; do
  grep -q "$lib" <<<"$known_libs" || packages+=("${lib_package[$lib]}")
done
compgen -G "/usr/lib/*/dri/swrast_dri.so" >/dev/null || compgen -G "/usr/lib*/dri/swrast_dri.so" >/dev/null || packages+=(libgl1-mesa-dri)
if [ -n "$missing_only" ]; then
  echo "${packages[*]}"
  exit 0
fi
if [ ${#packages[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup.sh: installing from Debian: ${packages[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${packages[@]}" >/dev/null
  else
    echo "setup.sh: please install these Debian packages first: ${packages[*]}" >&2
    exit 1
  fi
fi

[ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
"$venv/bin/python" -m pip install -q --disable-pip-version-check -e ".[$extras]"
echo "setup.sh: ready ($venv, extras: $extras)"
