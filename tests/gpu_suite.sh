#!/usr/bin/env bash
# Runs the suite's CUDA half from a release `suite` test binary in SHARDS concurrent processes,
# then the `errors` module alone, and prints each process's libtest summary; exits 1 when any
# test failed or skipped for want of a device.
#
#   tests/gpu_suite.sh SUITE_BIN [SHARDS]
#
# SUITE_BIN is a release build of tests/suite (`cargo test --release --no-run --test suite`;
# stripped it is over 100 MB, so a machine reached through a size-limited copy may take it
# xz-compressed: a SUITE_BIN ending in .xz is decompressed beside itself first). Run it from
# the repository root (some tests read files under tests/data). SHARDS defaults to 4.
#
# Why shards: each suite process runs its CUDA tests one at a time (the suite's GPU lock), and
# most of a test's time is NVRTC compiling its kernels on the host, so separate processes
# (each with its own lock, NVRTC and CUDA context) overlap that work: on an H200 machine with
# 16 cores, 638 tests took 274 s in four shards against about 640 s in one process. The
# shards are whole modules, balanced by test count (tile modules counted double: their
# kernels compile longest). The `errors` module runs alone, after the others: one of its tests
# exhausts GPU memory on purpose, which would fail tests running beside it.
#
# Logs go to $OUT (or /tmp) as gpu-suite-<shard>.log (uncaptured, so a test that finds no GPU
# shows its SKIPPED line there and here); the test lists as gpu-suite-<shard>.txt.
set -uo pipefail
bin=${1:?usage: tests/gpu_suite.sh SUITE_BIN [SHARDS]}
shards=${2:-4}
out=${OUT:-/tmp}
mkdir -p "$out"
if [[ "$bin" == *.xz ]]; then
  xz -d -k -f "$bin" || exit 1
  bin=${bin%.xz}
fi
chmod +x "$bin"
"$bin" --list 2>/dev/null | sed -n 's/^\(.*::cuda_backend::.*\): test$/\1/p' > "$out/gpu-suite-all.txt"
python3 - "$out" "$shards" <<'PY'
import collections, sys
out, shards = sys.argv[1], int(sys.argv[2])
mods = collections.OrderedDict()
for name in open(f"{out}/gpu-suite-all.txt").read().split():
    mods.setdefault(name.split("::cuda_backend")[0], []).append(name)
alone = mods.pop("errors", [])
lists, load = [[] for _ in range(shards)], [0] * shards
weight = lambda m: len(mods[m]) * (2 if "tile" in m else 1)
for m in sorted(mods, key=weight, reverse=True):
    i = load.index(min(load))
    lists[i] += mods[m]
    load[i] += weight(m)
for i, names in enumerate(lists):
    open(f"{out}/gpu-suite-{i}.txt", "w").write("\n".join(names) + "\n")
open(f"{out}/gpu-suite-errors.txt", "w").write("\n".join(alone) + "\n")
PY
status=0
for ((i = 0; i < shards; i++)); do
  [ -s "$out/gpu-suite-$i.txt" ] || continue
  # shellcheck disable=SC2046
  "$bin" --nocapture --exact $(cat "$out/gpu-suite-$i.txt") > "$out/gpu-suite-$i.log" 2>&1 &
done
wait || true
# shellcheck disable=SC2046
"$bin" --nocapture --exact $(cat "$out/gpu-suite-errors.txt") > "$out/gpu-suite-errors.log" 2>&1
for log in "$out"/gpu-suite-*.log; do
  summary=$(grep -E '^test result' "$log" | tail -1)
  echo "$(basename "$log"): ${summary:-no summary (crashed?)}"
  grep -E '^test .* FAILED$|SKIPPED' "$log" | head -20
  # The panics too: a caller that gets back only some of the logs still sees why.
  grep -qE '^test result: ok' "$log" || { grep -A6 'panicked at' "$log" | head -40; status=1; }
  # A CUDA test that found no device passes after printing SKIPPED: not a GPU run.
  ! grep -q '^SKIPPED' "$log" || status=1
done
exit $status
