#!/usr/bin/env bash
# The full suite on one Blender (make test-full): two pytest runs side by side, the render tests
# (Cycles renders on both cores) and the rest (numpy reference tests, mostly one core). On 2
# cores this takes about 5 minutes less than one run after the other; the two share no files
# (no pytest cache, separate temporary folders). The render run's output streams; the other's
# is printed when both are done. Fails if either fails.
#
#     scripts/test_full.sh PYTHON [PYTEST ARGS...]
set -uo pipefail
py="${1:?usage: test_full.sh PYTHON [PYTEST ARGS...]}"
shift
log=$(mktemp)
trap 'rm -f "$log"' EXIT
"$py" -m pytest -q -ra -p no:cacheprovider -m "not render" "$@" tests >"$log" 2>&1 &
other=$!
"$py" -m pytest -q -ra -p no:cacheprovider --durations=15 -m render "$@" tests
render_rc=$?
wait "$other"
other_rc=$?
echo "== the tests that do not render (run beside the render tests)"
cat "$log"
# pytest's 5 (no test selected) is not a failure of one half when arguments narrow the run.
ok() { [ "$1" -eq 0 ] || { [ "$#" -gt 1 ] && [ "$1" -eq 5 ]; }; }
ok "$render_rc" ${1:+narrowed} && ok "$other_rc" ${1:+narrowed}
