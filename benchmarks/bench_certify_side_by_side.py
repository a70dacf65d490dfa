"""`crosscert certify` side by side: several installs (or options), interleaved, wall and CPU time each.

Prints numbers, asserts nothing.  Usage::

    python benchmarks/bench_certify_side_by_side.py --repeat 2 \\
        base=/work/venv-base/bin/python "base-om40=/work/venv-base/bin/python --one-motion 40" \\
        branch=/work/venv-branch/bin/python

Each ``label=python [certify options]`` runs ``python -m crosscert certify --no-progress`` in a fresh process
(cwd: a temporary directory, so that each python imports its own install), one round of every variant after
another (``--repeat`` rounds: the machine's load hits them alike).  Per variant: v_min, the refutation bound
and their ratio, the Monte Carlo count, the printed phases, wall time (the child's, with the worker process)
and CPU time (user + system of the child and the worker it waited for), the load average before each run,
then the min and median over the rounds.  Run each install once before (numba's cache) or read the first
round as cold.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shlex
import statistics
import subprocess
import tempfile
import time


def _run(python: str, options: list) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        done = subprocess.run([python, "-m", "crosscert", "certify", "--no-progress", "--out", tmp, *options],
                              cwd=tmp, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = done.stdout
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1:] or ["exit %d" % done.returncode]}
    grab = lambda pattern: (re.search(pattern, out) or [None, None])[1]  # noqa: E731
    return {"wall": wall, "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "load": load, "v_min": grab(r"minimal certified v_sing: (\S+)"),
            "bound": grab(r"refutation bound \(no sound tracker certifies at or below\): (\S+)"),
            "ratio": grab(r"ratio v_min / refutation bound = (\S+)"),
            "mc": grab(r"Monte Carlo at v_min: (\S+)"), "elapsed": grab(r"elapsed (.*)\n"),
            "robot": grab(r"at the robot's a_max .*?: minimal certified v_sing (\S+ m/s)")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("variants", nargs="+", help="label=python [certify options]")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    variants = []
    for v in a.variants:
        label, _, rest = v.partition("=")
        words = shlex.split(rest)
        variants.append((label, words[0], words[1:]))
    rows = {label: [] for label, _, _ in variants}
    for r in range(a.repeat):
        for label, python, options in variants:
            m = _run(python, options)
            rows[label].append(m)
            if "error" in m:
                print(f"round {r + 1} {label}: failed: {m['error']}", flush=True)
                continue
            print(f"round {r + 1} {label:12s} load {m['load']:.2f}  wall {m['wall']:6.1f} s  CPU {m['cpu']:6.1f} s  "
                  f"v_min {m['v_min']} bound {m['bound']} ratio {m['ratio']} MC {m['mc']} robot a_max {m['robot']}"
                  f"\n    elapsed {m['elapsed']}", flush=True)
    print("\nvariant        wall min / median (s)   CPU min / median (s)")
    for label, ms in rows.items():
        ok = [m for m in ms if "error" not in m]
        if ok:
            w, c = [m["wall"] for m in ok], [m["cpu"] for m in ok]
            print(f"{label:14s} {min(w):7.1f} / {statistics.median(w):7.1f}      {min(c):7.1f} / {statistics.median(c):7.1f}")


if __name__ == "__main__":
    main()
