"""The Python package's call beside the command, paired and interleaved in
one run (issue 55's goal: the call costs at most 5 % more).

    python bench/python/paired.py [-n PAIRS] [--frame] -- ROBCAL_CALIBRATE_ARGS...

e.g. `-- --setup data/kr270/setup-naive.toml --data /tmp/kr-15.csv`. Each
pair runs, in turn, the command (`$ROBCAL`, default target/release/robcal,
`calibrate ARGS --json`, a whole process timed from outside) and the
package's call in this process (`robcal.calibrate(setup, data,
**settings).json()`, timed around the call: reading the files, the
calibration and the JSON, as the command does). Both must print the same
JSON. With `--frame` the call is given the data as a pandas DataFrame
(read before the pairs; the call converts it, as a notebook's call does).
One warm-up of each; the order within a pair alternates. Printed:
the median [min, max] of each side's wall time and of the ratio
call / command taken pair by pair.
"""

import argparse
import os
import statistics
import subprocess
import sys
import time

import robcal


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("-n", type=int, default=11)
    p.add_argument("--frame", action="store_true")
    p.add_argument("args", nargs=argparse.REMAINDER)
    a = p.parse_args()
    args = [x for x in a.args if x != "--"]
    cli = os.environ.get("ROBCAL", "target/release/robcal")
    k = argparse.ArgumentParser()
    k.add_argument("--setup")
    k.add_argument("--data")
    k.add_argument("--method", default="irls")
    k.add_argument("--no-diagnose", action="store_true")
    o = k.parse_args(args)
    settings = {"method": o.method, "diagnose": not o.no_diagnose}
    data = o.data
    if a.frame:
        import pandas as pd

        data = pd.read_csv(o.data)

    def command() -> tuple[float, str]:
        t = time.perf_counter()
        r = subprocess.run([cli, "calibrate", "-q", *args, "--json"], capture_output=True, text=True, check=True)
        return time.perf_counter() - t, r.stdout

    def call() -> tuple[float, str]:
        t = time.perf_counter()
        out = robcal.calibrate(o.setup, data, **settings).json()
        return time.perf_counter() - t, out

    (_, want), (_, got) = command(), call()
    if want != got:
        sys.exit("the call's JSON is not the command's")
    cmd, py, ratio = [], [], []
    for i in range(a.n):
        if i % 2 == 0:
            c, q = command()[0], call()[0]
        else:
            q, c = call()[0], command()[0]
        cmd.append(c)
        py.append(q)
        ratio.append(q / c)

    def show(v: list[float], unit: str = " s") -> str:
        return f"{statistics.median(v):.4g}{unit} [{min(v):.4g}, {max(v):.4g}]"

    print(f"command {show(cmd)}   call {show(py)}   call/command {show(ratio, '×')}   ({a.n} pairs)")


if __name__ == "__main__":
    main()
