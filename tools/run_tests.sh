#!/usr/bin/env bash
# make test: the ROS-free tests, the VISCA tests and the ROS tests side by side,
# each in order.
#
# Three pytest processes, not pytest-xdist: the ROS tests (node processes over
# DDS, module-wide node fixtures that later tests build on) must run one after
# another in file order, and never two closed loops at once; the VISCA tests
# (an emulated camera on pseudo-terminals, no DDS) likewise among themselves;
# the ROS-free tests (detector, survey, lint) are CPU-bound and fill the cores
# while the other two wait on real time. Each process gets its own ROS domain.
# Usage: tools/run_tests.sh PYTHON [PYTEST OPTIONS...]
set -uo pipefail
py=${1:?usage: tools/run_tests.sh PYTHON [PYTEST OPTIONS...]}
shift
base=${ROS_DOMAIN_ID:-$(( ($$ % 100) + 101 ))}
core_log=$(mktemp "${TMPDIR:-/tmp}/pattern_locator_core_tests.XXXXXX")
visca_log=$(mktemp "${TMPDIR:-/tmp}/pattern_locator_visca_tests.XXXXXX")
trap 'rm -f "$core_log" "$visca_log"' EXIT
ROS_DOMAIN_ID=$(( (base + 50) % 232 + 1 )) "$py" -m pytest -q "$@" test \
    --ignore=test/nodes --ignore=test/visca >"$core_log" 2>&1 &
core=$!
ROS_DOMAIN_ID=$(( (base + 100) % 232 + 1 )) "$py" -m pytest -q "$@" test/visca \
    >"$visca_log" 2>&1 &
visca=$!
echo "ROS tests (test/nodes):"
ROS_DOMAIN_ID=$base "$py" -m pytest -q "$@" test/nodes
ros_status=$?
wait "$visca"
visca_status=$?
wait "$core"
core_status=$?
echo
echo "VISCA tests (test/visca):"
cat "$visca_log"
echo
echo "ROS-free tests (the rest of test/):"
cat "$core_log"
if [ "$ros_status" -ne 0 ] || [ "$visca_status" -ne 0 ] || [ "$core_status" -ne 0 ]; then
    echo "make test: FAILED (ROS tests exit $ros_status, VISCA tests exit $visca_status," \
         "ROS-free tests exit $core_status)"
    exit 1
fi
echo "make test: all passed"
