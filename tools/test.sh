#!/usr/bin/env bash
# `make test`: the suite as three pytest sessions side by side on this 2-core machine.
# - The node tests (real rclpy nodes, sockets, subprocesses: about one core, 867 CPU-s in 749 s measured
#   alone on 2026-11-28 before the diagnosis tests among them moved out) in the foreground, at normal priority,
#   so their timing is what it was when they ran alone.
# - The CPU-bound diagnosis tests (`pytestmark = pytest.mark.compute`) beside them at nice 19, as two
#   sessions of one numba thread each, of about equal CPU (FIRST's modules; every other compute module).
#   They take what the node tests leave idle, then a core each once those are done. One session of two
#   threads stalled: a parallel kernel waits for its slowest thread, and a nice-19 thread on the core a
#   node test holds gets about 1/70 of it (a diagnosis beside one busy loop: 22.8 s with two threads,
#   16.1 s with one; 9.9 s with two on an idle machine).
# Tests marked `long` (a diagnosis of a minute or more, pytest.ini) are left to `make bench`
# (bench/bench_long_tests.py runs them). All report; the exit status fails if any session failed. `pytest test`
# alone runs everything.
set -u
cd "$(dirname "${BASH_SOURCE[0]}")/.." || exit 1
PYTHON=.venv/bin/python
ARGS=(-q -p no:cacheprovider --durations=15)
FIRST=(test/test_diagnosis_independent.py test/test_diagnosis.py test/test_diagnosis_angle.py test/test_diagnosis_progress.py
       test/test_import.py)
logs=()
pids=()
trap 'kill "${pids[@]}" 2>/dev/null; rm -f "${logs[@]}"' EXIT
trap 'exit 130' INT TERM
compute() {     # compute LABEL PYTEST-ARGS...: one niced single-threaded session in the background
    local log
    log=$(mktemp "${TMPDIR:-/tmp}/hopper_ros-compute-tests.XXXXXX")
    echo "$1" >"$log"
    shift
    NUMBA_NUM_THREADS=1 nice -n 19 "$PYTHON" -m pytest "${ARGS[@]}" -m "compute and not long" "$@" >>"$log" 2>&1 &
    pids+=($!)
    logs+=("$log")
}
compute "== compute-bound tests, first session" "${FIRST[@]}"
compute "== compute-bound tests, second session" "${FIRST[@]/#/--ignore=}" test
echo "== node and unit tests (the compute-bound ones run beside them at nice 19; their reports follow)"
"$PYTHON" -m pytest "${ARGS[@]}" -m "not compute and not long" test
nodes=$?
status=("node and unit tests exit $nodes")
failed=$((nodes != 0))
for k in "${!pids[@]}"; do
    wait "${pids[$k]}"
    code=$?
    cat "${logs[$k]}"
    status+=("compute-bound session $((k + 1)) exit $code")
    [ "$code" -eq 0 ] || failed=1
done
pids=()
echo "== make test: $(IFS=,; echo "${status[*]}" | sed 's/,/, /g')"
[ "$failed" -eq 0 ]
