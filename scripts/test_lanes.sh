#!/usr/bin/env bash
# make test on 2 cores: two pytest lanes side by side, which share no files (no pytest cache,
# separate temporary folders).
#   lane 1: the render tests on the pinned release (Cycles renders on both cores), and the few
#           that do not render marked `render_lane` (tests/conftest.py: the lanes' balance);
#   lane 2: the other tests that do not render (numpy, mostly one core) on the pinned release, then
#           the compatibility suite (-m "compat and not release_only") on each older Blender
#           whose Python follows --compat, one after the other, the oldest first; on the others,
#           less the tests marked `oldest_only` (tests/conftest.py says which, and why).
# Lane 1's output streams; lane 2's is printed when both are done. Fails if any run fails.
#
#     scripts/test_lanes.sh PINNED_PYTHON [--compat OLDEST_PYTHON PYTHON ...] [-- PYTEST ARGS...]
#
# PYTEST ARGS narrow every run (e.g. -k back_face); a run left with no test is then no failure.
set -uo pipefail
# glibc returns every freed block above 128 KB-32 MB to the system (munmap, heap trim), so each
# of numpy's large temporaries is faulted in afresh, page by page; on these virtual machines a
# page fault is costly (a loop over 200 MB arrays: 2.5 s, 1.4 of it in the kernel; with the
# heap kept: 1.05 s). Keeping freed memory in the heap took the tests that do not render from
# 259 to 225 s (test_reference_split and _heitz2016_walk: 64 to 46 s, peak memory 4.28 GB
# both ways); renders are unchanged.
export GLIBC_TUNABLES="${GLIBC_TUNABLES:-glibc.malloc.mmap_threshold=4294967296:glibc.malloc.trim_threshold=8589934592}"
py="${1:?usage: test_lanes.sh PINNED_PYTHON [--compat PYTHON ...] [-- PYTEST ARGS...]}"
shift
compat=()
if [ "${1:-}" = "--compat" ]; then
  shift
  while [ "$#" -gt 0 ] && [ "$1" != "--" ]; do compat+=("$1"); shift; done
fi
[ "${1:-}" = "--" ] && shift
narrowed=$#
opts=(-q -ra -p no:cacheprovider)
log=$(mktemp)
trap 'rm -f "$log"' EXIT

ok() { [ "$1" -eq 0 ] || { [ "$narrowed" -gt 0 ] && [ "$1" -eq 5 ]; }; }
version() { "$1" -c 'import bpy; print(bpy.app.version_string)' 2>/dev/null; }

lane2() {
  local rc=0 p
  echo "== the tests that do not render, Blender $(version "$py") (beside the render tests)"
  "$py" -m pytest "${opts[@]}" -m "not render and not render_lane" "$@" tests
  ok $? || rc=1
  local marks="compat and not release_only"
  for p in "${compat[@]}"; do
    echo "== compatibility suite on Blender $(version "$p")"
    "$p" -m pytest "${opts[@]}" -m "$marks" "$@" tests
    ok $? || rc=1
    marks="compat and not release_only and not oldest_only"  # past the oldest
  done
  return "$rc"
}

start=$SECONDS
lane2 "$@" >"$log" 2>&1 &
other=$!
echo "== the render tests, Blender $(version "$py")"
"$py" -m pytest "${opts[@]}" --durations=15 -m "render or render_lane" "$@" tests
render_rc=$?
echo "== lane 1 (render tests) done after $((SECONDS - start)) s"
wait "$other"
other_rc=$?
cat "$log"
echo "== both lanes done after $((SECONDS - start)) s"
ok "$render_rc" && [ "$other_rc" -eq 0 ]
