"""Runs the Python tests of the `warp_sim` example module: every `test_*` function of
test_ops_numpy.py, test_ops_torch.py, test_ops_jax.py and test_ocean.py (or of the files named on the command line).

    python3 examples/python/tests/run.py                      # CI: torch and GPU parts SKIPPED
    python3 examples/python/tests/run.py --require torch,jax,cuda  # the GPU machine: none may skip

`warp_sim` is imported from PYTHONPATH first, then from examples/python (where the build
copies warp_sim.abi3.so). A test whose framework or GPU is missing prints SKIPPED (a failure
when that requirement is named by --require). The last line is `N passed, N failed`; the exit
status is 1 when any failed.
"""

import argparse
import importlib.util
import os
import sys
import time
import traceback

# PyTorch and JAX share the GPU in this process: JAX would otherwise take most of its memory
# at its first use.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
HERE = os.path.dirname(os.path.abspath(__file__))
# After PYTHONPATH's entries: a module given there wins over a stale copy in the checkout.
sys.path.append(os.path.dirname(HERE))
sys.path.insert(0, HERE)

from _harness import Skip  # noqa: E402

FILES = ["test_ops_numpy.py", "test_ops_torch.py", "test_ops_jax.py", "test_ocean.py", "test_bounce.py"]


def run_file(path, require, counts):
    name = os.path.basename(path)
    spec = importlib.util.spec_from_file_location(name[:-3], path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception:
        traceback.print_exc()
        print("FAILED %s: the file did not import" % name)
        counts["failed"] += 1
        return
    tests = [(n, f) for n, f in vars(module).items() if n.startswith("test_") and callable(f)]
    tests.sort(key=lambda t: t[1].__code__.co_firstlineno)
    for test_name, fn in tests:
        label = "%s::%s" % (name, test_name)
        start = time.perf_counter()
        try:
            fn()
        except Skip as s:
            if s.requirement in require:
                print("FAILED %s: required %s is missing: %s" % (label, s.requirement, s.why))
                counts["failed"] += 1
            else:
                print("SKIPPED %s: %s" % (label, s.why))
                counts["skipped"] += 1
            continue
        except Exception:
            traceback.print_exc()
            print("FAILED %s" % label)
            counts["failed"] += 1
            continue
        print("ok   %s (%.2f s)" % (label, time.perf_counter() - start))
        counts["passed"] += 1


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="*", help="test files (default: %s)" % ", ".join(FILES))
    parser.add_argument(
        "--require",
        default="",
        help="comma-separated requirements (torch, jax, cuda) whose absence fails instead of skipping",
    )
    args = parser.parse_args(argv)
    require = {r for r in args.require.split(",") if r}
    unknown = require - {"torch", "jax", "cuda"}
    if unknown:
        parser.error("unknown requirement(s): %s (known: torch, jax, cuda)" % ", ".join(sorted(unknown)))
    counts = {"passed": 0, "failed": 0, "skipped": 0}
    for f in args.files or [os.path.join(HERE, f) for f in FILES]:
        run_file(f, require, counts)
    if counts["skipped"]:
        print("%d skipped" % counts["skipped"])
    print("%d passed, %d failed" % (counts["passed"], counts["failed"]))
    return 1 if counts["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
