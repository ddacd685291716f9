"""Peer benchmark of issue 16: the paper's KR-270 iterative WLS in robcal,
numpy and statsmodels, on exactly the same 810 x 9 problem, interleaved in
one run. Started by bench/peers/run.sh (which builds robcal's timing
program and exports the problem); see BENCHMARKS.md, "Peers side by side
(issue 16)".

The job (robcal::estimate::irls, section 5 of the paper), identical in the
three:

1. OLS (all weights 1).
2. After every fit: residuals r = dp - B x; per configuration g and axis a
   (45 cells of 18 rows) the residual sum RSS and the leverage share
   h = sum w^2 b' inv(L) b over the cell's rows; dof = max(n - h, 1/2),
   sigma = sqrt(RSS / dof); cells with dof < 8 pooled per axis
   (pool_small_groups; none on this data, implemented anyway).
3. Sandwich covariance inv(L) M inv(L), M = sum w^4 sigma^2 c b b' with
   c = dof / max(dof - 4(1 - w), dof/2) when the weights were estimated from
   these data (every WLS step), c = 1 for OLS.
4. Weights of eq. 14, w = sigma0 / (sigma0 + lambda sigma), per cell; WLS
   refit; stop when no parameter moved by more than 1e-3 of its standard
   deviation (5 WLS steps here).

robcal solves it from grouped sufficient statistics (GroupedStats: 45 cells'
moments built from the rows inside the timing, then reweighted); numpy and
statsmodels work on the stored 810 rows as a user of those libraries would:

- numpy: the weighted normal equations (W B)'(W B), np.linalg.inv, x = L^-1 eta,
  leverage by einsum, cell sums by np.bincount, sandwich by matrix products;
  vectorised, no Python loop over rows.
- statsmodels: sm.WLS(dp, B, weights=w^2).fit() for every fit (its default
  pinv solver): params, resid, normalized_cov_params = inv(L), and the
  leverage from its whitened design and pseudo-inverse (model.wexog,
  model.pinv_wexog; OLSInfluence.hat_matrix_diag would use the unwhitened
  exog, which is the leverage of OLS only). The per-cell sigma, eq. 14 and
  the sandwich's middle term are numpy: statsmodels has no per-group
  variance model. Its RLM is not the same estimator (per-residual M-estimator
  weights with one global scale, not eq. 14 per configuration and axis), and
  its HC0..HC3 sandwiches use each row's own squared residual, not the
  cell's sigma^2.

Before timing, the three results are compared with robcal's (x and the
sandwich standard deviations, relative 1e-6, same number of iterations).

With --stream (run.sh --stream), the streaming update of issue 16 instead:
10^6 weighted blocks (3 rows x N, a ring of 1000 distinct blocks read 1000
times over) into robcal's core Accumulator<f64, Dyn> (scalar), into
robcal::estimate::wide::WideAccumulator (SIMD, dispatched at run time), and
numpy's normal equations on the same rows in chunks of one ring
(L += A.T @ (w2*A), eta += (w2*A).T @ dp, yy += dp @ (w2*dp)), with the
machine's FMA peak measured through robcal's dispatch (independent FMA
chains), interleaved core, wide, peak, numpy per round. The wide accumulator
runs through its three entry points, each on the same stream with the same
sums: `update` (one block a call, the main table), `update_many` (a slice
of blocks, one ring a call) and `update_rows` (the ring's rows row-major,
3000 a call). numpy's sums are checked against robcal's before timing. Flops are counted as the useful
work, 3 N(N+1)/2 * 2 per block for the upper triangle of Lambda plus 3 N * 2
for eta (numpy computes the full N x N product: about twice that).
"""

import argparse
import os
import statistics
import subprocess
import sys
import time

import numpy as np
import statsmodels
import statsmodels.api as sm

CELLS = 45  # 15 configurations x 3 axes


def load(data):
    rows = np.loadtxt(f"{data}/kr270_rows.csv", delimiter=",", skiprows=1)
    cell = (rows[:, 0] * 3 + rows[:, 1]).astype(np.intp)
    b = np.ascontiguousarray(rows[:, 2:11])
    dp = np.ascontiguousarray(rows[:, 11])
    ref = {}
    with open(f"{data}/kr270_reference.txt") as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            key, *vals = line.split()
            ref[key] = vals
    settings = {
        "sigma0": float(ref["sigma0_m"][0]),
        "lam": float(ref["lambda"][0]),
        "tol": float(ref["tolerance"][0]),
        "max_it": int(ref["max_iterations"][0]),
        "pool": float(ref["pool_below_dof"][0]),
    }
    expected = {
        "x": np.array([float(v) for v in ref["x"]]),
        "sd": np.array([float(v) for v in ref["sd"]]),
        "iterations": int(ref["iterations"][0]),
    }
    return b, dp, cell, settings, expected


def pool_small(sigma, dof, pool):
    """robcal::estimate::pool_small_groups on (15, 3) arrays."""
    sigma, dof = sigma.copy(), dof.copy()
    for a in range(3):
        s, n = sigma[:, a], dof[:, a]
        small = (n > 0) & (n < pool)
        v = n[small].sum()
        if v == 0:
            continue
        pick = small if v >= pool else n > 0
        ss, vv = (s[pick] ** 2 * n[pick]).sum(), n[pick].sum()
        sigma[small, a] = np.sqrt(ss / vv)
        dof[small, a] = vv
    return sigma, dof


def cell_sigma(r, h, cell, count, pool):
    """sigma and dof per cell from the residuals and the rows' leverage."""
    rss = np.bincount(cell, r * r, minlength=CELLS)
    hs = np.bincount(cell, h, minlength=CELLS)
    dof = np.maximum(count - hs, 0.5)
    sigma = np.sqrt(rss / dof)
    s, d = pool_small(sigma.reshape(15, 3), dof.reshape(15, 3), pool)
    return s.ravel(), d.ravel()


def middle_scale(w, sigma, dof, estimated):
    """Per cell: sqrt of the middle term's factor w^4 sigma^2 c."""
    if estimated:
        e = np.clip(1.0 - w, 0.0, 1.0)
        c = dof / np.maximum(dof - 4.0 * e, 0.5 * dof)
    else:
        c = 1.0
    return w * w * sigma * np.sqrt(c)


class Problem:
    def __init__(self, b, dp, cell, settings):
        self.b, self.dp, self.cell, self.s = b, dp, cell, settings
        self.count = np.bincount(cell, minlength=CELLS).astype(float)

    def weights(self, sigma):
        s0, lam = self.s["sigma0"], self.s["lam"]
        return s0 / (s0 + lam * sigma)

    def irls(self, fit):
        """The iteration around one library's fit; returns x, sd, iterations."""
        w = np.ones(CELLS)
        x, sd, sigma, dof = fit(w, False)
        for k in range(1, self.s["max_it"] + 1):
            w = self.weights(sigma)
            nx, nsd, sigma, dof = fit(w, True)
            change = np.max(np.abs(nx - x) / nsd)
            x, sd = nx, nsd
            if change < self.s["tol"]:
                return x, sd, k
        return x, sd, self.s["max_it"]

    def fit_numpy(self, w, estimated):
        b, dp, cell = self.b, self.dp, self.cell
        wr = w[cell]
        bw = b * wr[:, None]
        lam = bw.T @ bw
        eta = bw.T @ (dp * wr)
        li = np.linalg.inv(lam)
        li = 0.5 * (li + li.T)
        x = li @ eta
        r = dp - b @ x
        h = wr * wr * np.einsum("ij,jk,ik->i", b, li, b)
        sigma, dof = cell_sigma(r, h, cell, self.count, self.s["pool"])
        bs = b * middle_scale(w, sigma, dof, estimated)[cell][:, None]
        cov = li @ (bs.T @ bs) @ li
        return x, np.sqrt(np.diag(cov)), sigma, dof

    def fit_statsmodels(self, w, estimated):
        b, dp, cell = self.b, self.dp, self.cell
        wr = w[cell]
        res = sm.WLS(dp, b, weights=wr * wr).fit()
        li = res.normalized_cov_params
        model = res.model
        h = (model.wexog * model.pinv_wexog.T).sum(1)
        sigma, dof = cell_sigma(res.resid, h, cell, self.count, self.s["pool"])
        bs = b * middle_scale(w, sigma, dof, estimated)[cell][:, None]
        cov = li @ (bs.T @ bs) @ li
        return res.params, np.sqrt(np.diag(cov)), sigma, dof


class Robcal:
    """robcal's timing program, driven over a pipe: each batch is timed
    in-process, one time per calibration."""

    def __init__(self, binary, variant):
        self.variant = variant
        self.p = subprocess.Popen(
            [binary, "serve"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )

    def run(self, k):
        self.p.stdin.write(f"run {k} {self.variant}\n")
        self.p.stdin.flush()
        return [int(t) for t in self.p.stdout.readline().split()]

    def close(self):
        self.p.stdin.write("quit\n")
        self.p.stdin.close()
        self.p.wait()


def timed(f, k):
    t = []
    for _ in range(k):
        s = time.perf_counter_ns()
        f()
        t.append(time.perf_counter_ns() - s)
    return t


def check(name, got, expected):
    x, sd, it = got
    ex = np.max(np.abs(x - expected["x"]) / np.abs(expected["x"]))
    es = np.max(np.abs(sd - expected["sd"]) / expected["sd"])
    ok = it == expected["iterations"] and ex < 1e-6 and es < 1e-6
    print(
        f"  {name:<12} iterations {it}, max relative difference to robcal: "
        f"x {ex:.1e}, sd {es:.1e}  {'ok' if ok else 'MISMATCH'}"
    )
    return ok


class Stream:
    """robcal's stream timing program (host-tests/examples/stream_timing.rs)
    for one N, driven over a pipe."""

    def __init__(self, binary, n):
        self.p = subprocess.Popen(
            [binary, "serve", str(n)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )

    def ask(self, line):
        self.p.stdin.write(line + "\n")
        self.p.stdin.flush()
        return self.p.stdout.readline().split()

    def close(self):
        self.p.stdin.write("quit\n")
        self.p.stdin.close()
        self.p.wait()


def numpy_stream(rows, n, chunks):
    """Normal equations of the stream, chunk by chunk (one ring a chunk)."""
    a, dp, w2 = rows[:, :n], rows[:, n], rows[:, n + 1] ** 2
    lam = np.zeros((n, n))
    eta = np.zeros(n)
    yy = 0.0
    for _ in range(chunks):
        aw = a * w2[:, None]
        lam += a.T @ aw
        eta += aw.T @ dp
        yy += dp @ (w2 * dp)
    return lam, eta, yy


def stream_main(args):
    sizes = [int(v) for v in args.sizes.split(",")]
    rounds = 3 if args.quick else args.stream_rounds
    blocks, ring = 1_000_000, 1000
    print(
        f"streaming update: {blocks} blocks (3 rows x N, weighted), ring of {ring}; "
        f"python {sys.version.split()[0]}, numpy {np.__version__}, "
        f"BLAS threads {os.environ.get('OPENBLAS_NUM_THREADS', 'default')}"
    )
    print("load average before: %.2f %.2f %.2f" % os.getloadavg())
    results = []
    for n in sizes:
        rows = np.fromfile(f"{args.data}/stream_{n}.f64").reshape(3 * ring, n + 2)
        ref = {}
        with open(f"{args.data}/stream_{n}_sums.txt") as f:
            for line in f:
                if line.startswith("#") or not line.strip():
                    continue
                key, *vals = line.split()
                ref[key] = np.array([float(v) for v in vals])
        lam, eta, yy = numpy_stream(rows, n, blocks // ring)
        # robcal writes the upper triangle column by column.
        cols = [(i, j) for j in range(n) for i in range(j + 1)]
        upper = np.array([lam[i, j] for i, j in cols])
        scale = np.sqrt(np.array([lam[i, i] * lam[j, j] for i, j in cols]))
        el = np.max(np.abs(upper - ref["upper"]) / scale)
        ee = np.max(np.abs(eta - ref["eta"]) / np.sqrt(np.diag(lam) * yy))
        ey = abs(yy - ref["yy"][0]) / yy
        ok = max(el, ee, ey) < 1e-10
        print(
            f"  N = {n}: numpy vs robcal sums: Lambda {el:.1e}, eta {ee:.1e}, yy {ey:.1e} "
            f"(relative to sqrt(Lii Ljj), sqrt(Lii yy), yy)  {'ok' if ok else 'MISMATCH'}"
        )
        if not ok:
            sys.exit("numpy does not reproduce robcal's sums: not timing")
        rc = Stream(args.stream, n)
        isa = rc.ask("info")[0]
        flops = (3 * n * (n + 1) + 3 * n * 2) * blocks  # Λ (upper) and η
        times = {"core": [], "wide": [], "many": [], "rows": [], "peak": [], "numpy": []}
        peak_flops = float(rc.ask("peak 1")[0])
        for mode in ("wide", "many", "rows"):
            rc.ask(f"run 1 {mode}")
        for _ in range(rounds):
            times["core"] += [int(t) for t in rc.ask("run 1 core")]
            for mode in ("wide", "many", "rows"):
                times[mode] += [int(t) for t in rc.ask(f"run 1 {mode}")]
            times["peak"] += [int(t) for t in rc.ask("peak 5")[1:]]
            times["numpy"] += timed(lambda: numpy_stream(rows, n, blocks // ring), 1)
        rc.close()
        med = {k: statistics.median(v) / 1e9 for k, v in times.items()}
        peak = peak_flops / min(times["peak"])  # flops per ns: GFLOP/s
        peak_med = peak_flops / med["peak"] / 1e9
        results.append((n, isa, flops, med, peak, peak_med, times))
    print(f"\n{rounds} rounds, interleaved core, wide (update, update_many, update_rows), peak, numpy; median [best] of each:")
    print(
        "  N   core (scalar)            wide (SIMD)              numpy                    "
        "peak GFLOP/s         wide % of peak       core/wide  numpy/wide"
    )
    for n, isa, flops, med, peak, peak_med, times in results:
        best = {k: min(v) / 1e9 for k, v in times.items()}

        def cell(k):
            return f"{med[k] * 1e3:7.1f} [{best[k] * 1e3:7.1f}] ms"

        print(
            f"  {n:<3} {cell('core')}  {cell('wide')}  {cell('numpy')}  "
            f"{peak_med:5.1f} [{peak:5.1f}] {isa}  "
            f"{100 * flops / med['wide'] / 1e9 / peak_med:4.1f} [{100 * flops / best['wide'] / 1e9 / peak:4.1f}] %"
            f"       {med['core'] / med['wide']:5.2f}x     {med['numpy'] / med['wide']:5.2f}x"
        )
    print("\nthe batched entry points (same stream, same sums): update_many (1000 blocks a call), update_rows (3000 rows a call):")
    print("  N   wide update              update_many              update_rows              % of peak: update, many, rows")
    for n, isa, flops, med, peak, peak_med, times in results:
        best = {k: min(v) / 1e9 for k, v in times.items()}

        def cell(k):
            return f"{med[k] * 1e3:7.1f} [{best[k] * 1e3:7.1f}] ms"

        def pct(k):
            return f"{100 * flops / med[k] / 1e9 / peak_med:4.1f} [{100 * flops / best[k] / 1e9 / peak:4.1f}]"

        print(f"  {n:<3} {cell('wide')}  {cell('many')}  {cell('rows')}  {pct('wide')}, {pct('many')}, {pct('rows')} %")
    print("load average after: %.2f %.2f %.2f" % os.getloadavg())
    for n, isa, flops, med, peak, peak_med, times in results:
        print(
            f"  N = {n} ranges (ms): "
            + ", ".join(f"{k} [{min(v) / 1e6:.1f}, {max(v) / 1e6:.1f}]" for k, v in times.items() if k != "peak")
        )


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--robcal")
    ap.add_argument("--data", required=True)
    ap.add_argument("--stream", help="the stream timing program: the streaming mode")
    ap.add_argument("--sizes", default="9,30,60", help="N of the streaming mode")
    ap.add_argument("--stream-rounds", type=int, default=7)
    ap.add_argument(
        "--before",
        help="a second robcal timing program (e.g. built from another commit), timed beside",
    )
    ap.add_argument("--rounds", type=int, default=100)
    ap.add_argument("--quick", action="store_true", help="5 rounds")
    args = ap.parse_args()
    if args.stream:
        stream_main(args)
        return
    rounds = 5 if args.quick else args.rounds

    b, dp, cell, settings, expected = load(args.data)
    prob = Problem(b, dp, cell, settings)
    print(
        f"KR-270 iterative WLS: {b.shape[0]} rows x {b.shape[1]} parameters, "
        f"{CELLS} cells (configuration x axis)"
    )
    print(
        f"python {sys.version.split()[0]}, numpy {np.__version__}, "
        f"statsmodels {statsmodels.__version__}"
    )
    ok = check("numpy", prob.irls(prob.fit_numpy), expected)
    ok &= check("statsmodels", prob.irls(prob.fit_statsmodels), expected)
    if not ok:
        sys.exit("the peers do not reproduce robcal's estimate: not timing")

    # Batches sized to take ~10-40 ms each; A B C A B C ... per round.
    peers = [
        ("robcal Const<9>", Robcal(args.robcal, "const").run, 200),
        ("robcal Dyn(9)", Robcal(args.robcal, "dyn").run, 100),
        ("numpy", lambda k: timed(lambda: prob.irls(prob.fit_numpy), k), 20),
        ("statsmodels", lambda k: timed(lambda: prob.irls(prob.fit_statsmodels), k), 8),
    ]
    if args.before:
        peers[2:2] = [
            ("before Const<9>", Robcal(args.before, "const").run, 200),
            ("before Dyn(9)", Robcal(args.before, "dyn").run, 100),
        ]
    times = {name: [] for name, _, _ in peers}
    for name, run, k in peers:  # warm-up
        run(max(1, k // 4))
    for _ in range(rounds):
        for name, run, k in peers:
            times[name] += run(k)

    med = {name: statistics.median(t) / 1e3 for name, t in times.items()}
    print(f"\n{rounds} rounds, interleaved; median per calibration (us):")
    for name, t in times.items():
        q1, _, q3 = statistics.quantiles(t, n=4)
        print(f"  {name:<16} {med[name]:9.1f}   [{q1 / 1e3:.1f}, {q3 / 1e3:.1f}]  n = {len(t)}")
    print("\nratios (peer / robcal):")
    for r in [name for name in med if name.startswith(("robcal", "before"))]:
        print(
            f"  {r:<16} statsmodels {med['statsmodels'] / med[r]:6.1f}x   "
            f"numpy {med['numpy'] / med[r]:6.1f}x"
        )


if __name__ == "__main__":
    main()
