#!/usr/bin/env bash
# `make test`: the suite as two pytest sessions side by side on this 2-core machine.
# - The node tests (real rclpy nodes, sockets, subprocesses: about one core, much of it waiting) in the
#   foreground, at normal priority, so their timing is what it was when they ran alone.
# - The CPU-bound diagnosis tests (`pytestmark = pytest.mark.compute`; numba kernels on both cores) beside
#   them at nice 19: they take what the node tests leave idle, then both cores once those are done.
# Both report; the exit status fails if either session failed. `pytest test` alone still runs everything.
set -u
cd "$(dirname "${BASH_SOURCE[0]}")/.." || exit 1
PYTHON=.venv/bin/python
ARGS=(-q -p no:cacheprovider --durations=15)
log=$(mktemp "${TMPDIR:-/tmp}/hopper_ros-compute-tests.XXXXXX")
nice -n 19 "$PYTHON" -m pytest "${ARGS[@]}" -m compute test >"$log" 2>&1 &
compute=$!
trap 'kill "$compute" 2>/dev/null; rm -f "$log"' EXIT
trap 'exit 130' INT TERM
echo "== node and unit tests (the compute-bound ones run beside them at nice 19; their report follows)"
"$PYTHON" -m pytest "${ARGS[@]}" -m "not compute" test
nodes=$?
wait "$compute"
computed=$?
echo "== compute-bound tests (diagnosis)"
cat "$log"
echo "== make test: node and unit tests exit $nodes, compute-bound tests exit $computed"
[ "$nodes" -eq 0 ] && [ "$computed" -eq 0 ]
