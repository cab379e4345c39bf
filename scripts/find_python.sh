#!/usr/bin/env bash
# Print the path of a working Python X.Y interpreter, or say which one to install and fail.
#
#     scripts/find_python.sh 3.13
#
# Tries, in order: pythonX.Y on PATH (it must really run: a pyenv shim for a version that is
# installed but not selected fails), then pyenv's installed versions, then the usual install
# prefixes. The pip bpy wheels need an exact minor version: Blender 5.1 and later Python 3.13,
# Blender 4.2 to 5.0 Python 3.11.
set -u
want="${1:?usage: find_python.sh X.Y}"

works() {
  [ -x "$1" ] && [ "$("$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null)" = "$want" ]
}

candidates=()
if found=$(command -v "python$want" 2>/dev/null); then candidates+=("$found"); fi
root="${PYENV_ROOT:-$HOME/.pyenv}"
for dir in "$root"/versions/"$want"*; do
  [ -d "$dir" ] && candidates+=("$dir/bin/python$want")
done
candidates+=("/usr/local/bin/python$want" "/usr/bin/python$want" "/opt/homebrew/bin/python$want")

for python in "${candidates[@]}"; do
  if works "$python"; then
    echo "$python"
    exit 0
  fi
done
echo "error: no working Python $want found (tried: ${candidates[*]})." >&2
echo "Install Python $want (e.g. 'pyenv install $want', or your system's python$want package)," >&2
echo "or point the Makefile at one: make PYTHON_$want=/path/to/python$want ..." >&2
exit 1
