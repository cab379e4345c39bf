#!/usr/bin/env bash
# Create (once) the cached virtual environment pinned by a requirements file; print its Python.
#
#     scripts/venv.sh requirements.txt                  # the pinned environment (current Blender)
#     scripts/venv.sh tests/compat/requirements-4.2.txt # a compatibility environment
#
# The venv lives outside the clone, in $MICROFACET_LAB_CACHE (default ~/.cache/microfacet-lab),
# named after the Python version and the hash of the requirements file, so fresh clones reuse it
# and a changed pin gets a new one. The file's "# python X.Y" line says which interpreter the
# pinned bpy wheel needs; scripts/find_python.sh finds it (or PYTHON_X_Y=/path overrides).
# Progress goes to stderr, the venv's python path to stdout.
set -euo pipefail
req="${1:?usage: venv.sh REQUIREMENTS_FILE}"
here="$(cd "$(dirname "$0")" && pwd)"
want=$(sed -n 's/^# python \([0-9][0-9.]*\).*/\1/p' "$req" | head -n 1)
[ -n "$want" ] || { echo "error: $req has no '# python X.Y' line" >&2; exit 1; }
hash=$(sha256sum "$req" | cut -c1-12)
cache="${MICROFACET_LAB_CACHE:-$HOME/.cache/microfacet-lab}"
venv="$cache/venv-py$want-$hash"
if [ ! -f "$venv/.installed" ]; then
  override="PYTHON_${want//./_}"
  python="${!override:-}"
  [ -n "$python" ] || python=$("$here/find_python.sh" "$want")
  echo "[venv] creating $venv with $python from $req (first time only; about 1.1 GB)" >&2
  mkdir -p "$cache"
  [ -x "$venv/bin/python" ] || "$python" -m venv "$venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$req" >&2
  touch "$venv/.installed"
fi
echo "$venv/bin/python"
