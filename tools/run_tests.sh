#!/usr/bin/env bash
# make test: the ROS-free tests and the ROS tests side by side, each in order.
#
# Two pytest processes on the two cores, not pytest-xdist: the ROS tests
# (node processes over DDS, pseudo-terminals, module-wide node fixtures that
# later tests build on) must run one after another in file order, and never
# two closed loops at once; the ROS-free tests (detector, survey, lint) are
# CPU-bound and fill the other core, with the VISCA tests (a pseudo-terminal,
# mostly waiting: 43 s of wall for 5 s of CPU), which balances the two.
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
ROS_DOMAIN_ID=$core_domain "$py" -m pytest -q "$@" test \
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
