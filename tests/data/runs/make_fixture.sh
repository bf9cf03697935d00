#!/bin/sh
# Regenerates the run-directory fixture tests/data/runs/can_fault/ (used by
# tests/media/run_report_test.cpp) from tests/data/runs/can_fault.yaml with a built omnitwin.
# Usage (from the repository root): tests/data/runs/make_fixture.sh BUILD_DIR
set -eu
build=${1:?usage: make_fixture.sh BUILD_DIR}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
# Exit 1 is expected: the fixture fails one expectation on purpose.
"$build/twin/omnitwin" run tests/data/runs/can_fault.yaml --out "$out/run" --no-video --no-report --no-progress || [ $? -eq 1 ]
rm -rf tests/data/runs/can_fault
mkdir tests/data/runs/can_fault
cp "$out"/run/* tests/data/runs/can_fault/
ls -l tests/data/runs/can_fault
