#!/usr/bin/env python3
"""Time the project's exact EMD against POT's ot.emd2 on the same map pairs.

Needs numpy and POT (`pip install numpy pot`). Builds random pairs of 9x9
and 15x15 deflection maps of two kinds -- dense (every cell lit, the worst
case) and beam-like (a few-cell spot and the same spot slightly moved and
noised, as neighbouring scan positions are) -- runs
`cargo run --release -p dmap --example emd_pairs` on them, then ot.emd2 with
the Euclidean cell-centre cost matrix, and prints both timings and the
largest relative disagreement.

Usage (from the repository root): python3 scripts/emd_vs_pot.py [--pairs N] [--seed S]
"""
import argparse
import pathlib
import subprocess
import sys
import tempfile
import time

try:
    import numpy as np
    import ot
except ImportError as e:
    missing = {"ot": "POT (module ot)", "numpy": "numpy"}.get(e.name, e.name or "numpy or POT")
    sys.exit(f"emd_vs_pot.py: {missing} is not installed; install both with `pip install numpy pot`")

ROOT = pathlib.Path(__file__).resolve().parent.parent
HOST = ROOT / "host-tests"


def dense_pairs(rng, n, j):
    return rng.integers(0, 65536, size=(n, 2, j, j)).astype(np.float64)


def beam_pairs(rng, n, j):
    out = np.zeros((n, 2, j, j))
    y, x = np.mgrid[0:j, 0:j]
    for p in range(n):
        c = rng.uniform(2, j - 3, size=2)
        for k in range(2):
            cc = c + (rng.normal(0, 0.7, size=2) if k else 0)
            spot = 4000 * np.exp(-((y - cc[0]) ** 2 + (x - cc[1]) ** 2) / (2 * 0.8**2))
            out[p, k] = np.floor(spot + rng.poisson(0.3, size=(j, j)))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    subprocess.run(
        ["cargo", "build", "--release", "-q", "-p", "dmap", "--example", "emd_pairs"],
        cwd=HOST, check=True)
    exe = next((HOST / "target").glob("*/release/examples/emd_pairs"))
    print(f"{'maps':>6} {'kind':>6} {'pairs':>6} {'rust us/pair':>13} {'POT us/pair':>12} {'max rel diff':>13}")
    with tempfile.TemporaryDirectory() as tmp:
        for j in (9, 15):
            for kind, make in (("dense", dense_pairs), ("beam", beam_pairs)):
                pairs = make(rng, args.pairs, j)
                src, dst = pathlib.Path(tmp, "pairs.npy"), pathlib.Path(tmp, "out.npy")
                np.save(src, pairs)
                line = subprocess.run([exe, src, dst], check=True, capture_output=True, text=True).stdout
                rust_us = float(line.split("(")[1].split(" us")[0])
                ours = np.load(dst)[:, 0, 0]
                cells = np.array([(a, b) for a in range(j) for b in range(j)], dtype=np.float64)
                cost = ot.dist(cells, cells, metric="euclidean")
                hists = [(p[0].ravel() / p[0].sum(), p[1].ravel() / p[1].sum()) for p in pairs]
                t0 = time.perf_counter()
                pot = np.array([ot.emd2(a, b, cost, numItermax=10_000_000) for a, b in hists])
                pot_us = 1e6 * (time.perf_counter() - t0) / len(hists)
                rel = np.max(np.abs(ours - pot) / np.maximum(np.abs(pot), 1e-300))
                print(f"{j:>3}x{j:<2} {kind:>6} {len(hists):>6} {rust_us:>13.1f} {pot_us:>12.1f} {rel:>13.2e}")


if __name__ == "__main__":
    main()
