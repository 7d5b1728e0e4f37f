#!/usr/bin/env bash
# make test: the ROS-free tests and the ROS tests side by side, each in order.
#
# The ROS tests in one pytest process, not pytest-xdist: they (node
# processes over DDS, pseudo-terminals, module-wide node fixtures that later
# tests build on) must run one after another in file order, and never two
# closed loops at once. The ROS-free tests (detector, survey, lint: CPU-bound;
# the VISCA tests, a pseudo-terminal, mostly waiting) beside them on two
# xdist workers at a lower priority, which fill what the ROS side leaves of
# the two cores.
# Each process gets its own ROS domain: ROS_DOMAIN_ID for the ROS tests and
# CORE_ROS_DOMAIN_ID (default 51 domains on) for the rest.
# Usage: tools/run_tests.sh PYTHON [PYTEST OPTIONS...]
set -uo pipefail
py=${1:?usage: tools/run_tests.sh PYTHON [PYTEST OPTIONS...]}
shift
base=${ROS_DOMAIN_ID:-$(( ($$ % 100) + 101 ))}
core_log=$(mktemp "${TMPDIR:-/tmp}/pattern_locator_core_tests.XXXXXX")
trap 'rm -f "$core_log"' EXIT
core_domain=${CORE_ROS_DOMAIN_ID:-$(( (base + 50) % 232 + 1 ))}
# The ROS-free side on two pytest-xdist workers (a test file at a time, so
# that a module fixture is made once), niced: the ROS tests' nodes run in
# real time and get a core when they need one; these fill the rest.
ROS_DOMAIN_ID=$core_domain nice -n 10 "$py" -m pytest -q -n 2 --dist loadfile "$@" test \
    --ignore=test/nodes >"$core_log" 2>&1 &
core=$!
echo "ROS tests (test/nodes):"
ROS_DOMAIN_ID=$base "$py" -m pytest -q "$@" test/nodes
ros_status=$?
wait "$core"
core_status=$?
echo
echo "ROS-free and VISCA tests (the rest of test/):"
cat "$core_log"
if [ "$ros_status" -ne 0 ] || [ "$core_status" -ne 0 ]; then
    echo "make test: FAILED (ROS tests exit $ros_status, ROS-free tests exit $core_status)"
    exit 1
fi
echo "make test: all passed"
