#!/usr/bin/env bash
# Runs GPU test binaries under NVIDIA compute-sanitizer (memcheck, racecheck, initcheck) and
# prints one summary line per binary and tool; exits 1 when a tool reports an error.
#
#   tests/gpu_sanitize.sh BIN_DIR [FILTER] [TOOLS]
#
# BIN_DIR holds release test binaries (`../shared/tools/gpu-bundle` puts them in .gpu/bin, with
# .gpu/tests.txt naming each one's package directory); each binary whose name starts with
# suite-, fault_identity-, soak- or concurrent_grad- runs from its package directory with the
# libtest FILTER (default `cuda_backend` for the suite, none for the others), one test at a time
# (the sanitizers serialise kernels anyway). TOOLS defaults to "memcheck racecheck initcheck".
# Logs go to $OUT (or /tmp) as san-<tool>-<binary>.log. A shard of the suite is one FILTER
# (`cuda_backend::primitives`), to keep each call within a time limit: the sanitizers slow
# kernels 10 to 100 times.
#
# What each tool checks: memcheck, out-of-bounds and misaligned device memory accesses and
# leaks of device allocations made through the runtime API; racecheck, shared-memory data
# hazards inside a block (the primitives' scans and sorts, tile kernels); initcheck, reads of
# device memory never written (arrays are zeroed at allocation, so a report here is a kernel
# reading scratch it did not fill).
set -uo pipefail
# Line tables in the kernels, so that a report names the generated code's source lines.
export WARP_LANG_LINEINFO=${WARP_LANG_LINEINFO:-1}
bins=${1:?usage: tests/gpu_sanitize.sh BIN_DIR [FILTER] [TOOLS]}
filter=${2:-}
tools=${3:-memcheck racecheck initcheck}
logs=${OUT:-/tmp}
root=$(cd "$bins/../.." 2>/dev/null && pwd)
list="$bins/../tests.txt"
status=0
for tool in $tools; do
  for bin in "$bins"/suite-* "$bins"/fault_identity-* "$bins"/soak-* "$bins"/concurrent_grad-*; do
    [ -x "$bin" ] || continue
    name=$(basename "$bin")
    pkg=$( [ -f "$list" ] && grep "^$name " "$list" | cut -d' ' -f2 )
    args=(--test-threads=1)
    case "$name" in
      suite-*) args+=("${filter:-cuda_backend}") ;;
      *) [ -n "$filter" ] && args+=("$filter") ;;
    esac
    extra=()
    # initcheck's report of memory allocated and never used stays off: `--track-unused-memory`
    # is a switch in CUDA 13 (`--track-unused-memory no` made it take "no" for the program).
    log="$logs/san-$tool-${name%%-*}.log"
    (cd "$root/${pkg:-.}" && compute-sanitizer --tool "$tool" "${extra[@]}" --print-limit 50 \
      --error-exitcode 99 "$bin" "${args[@]}") > "$log" 2>&1
    rc=$?
    summary=$(grep -E "ERROR SUMMARY|RACECHECK SUMMARY" "$log" | tail -1)
    tests=$(grep -E "^test result" "$log" | tail -1)
    echo "$tool ${name%%-*} ${args[*]}: rc=$rc; $tests; $summary"
    [ "$rc" = 0 ] || status=1
  done
done
exit $status
