"""Maps per second through cvm_dmap.score against dmap on the same machine
and the same scan, and cvm_dmap's exact EMD against POT's ot.emd2.

Run by scripts/bench-python.sh (which builds and installs what it needs);
docs/performance.md quotes its output. One thread unless --threads says
otherwise (RAYON_NUM_THREADS, read when the first scan is scored).
"""

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def cpu():
    """CPU time of this process and its finished children, seconds."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def timed(fn, seconds, least=5):
    """Median wall time and median CPU time of fn() over at least `least`
    runs and `seconds`, after one warm-up."""
    fn()
    walls, cpus = [], []
    t_end = time.perf_counter() + seconds
    while len(walls) < least or time.perf_counter() < t_end:
        t0, c0 = time.perf_counter(), cpu()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(cpu() - c0)
    return statistics.median(walls), statistics.median(cpus)


def pot_gradient(scan, ot, np):
    """Eq. 1 with the border rule and ot.emd2 on normalised maps, Euclidean cell distances."""
    rows, cols, j1, j2 = scan.shape
    yy, xx = np.meshgrid(np.arange(j1), np.arange(j2), indexing="ij")
    pts = np.stack([yy.ravel(), xx.ravel()], 1).astype(np.float64)
    cost = np.sqrt(((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1))
    maps = scan.reshape(rows, cols, -1).astype(np.float64)
    maps /= maps.sum(-1, keepdims=True)
    g = np.zeros((rows, cols, 2))
    for r in range(rows):
        for c in range(cols):
            left, right = maps[r, max(c - 1, 0)], maps[r, min(c + 1, cols - 1)]
            up, down = maps[max(r - 1, 0), c], maps[min(r + 1, rows - 1), c]
            g[r, c, 0] = ot.emd2(left, right, cost)
            g[r, c, 1] = ot.emd2(up, down, cost)
    return g


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dmap", required=True, help="the dmap binary")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=5.0, help="timing budget per figure")
    ap.add_argument("--bench-seconds", type=float, default=10.0, help="dmap bench --seconds")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--emd-positions", type=int, default=8, help="side of the EMD comparison's square of positions")
    a = ap.parse_args()
    os.environ["RAYON_NUM_THREADS"] = str(a.threads)
    import numpy as np
    import cvm_dmap

    tile, _ = cvm_dmap.simulate("paper-sim", seed=1, rows=60, cols=60)
    scan = np.ascontiguousarray(np.tile(tile, (5, 5, 1, 1)))  # 300 x 300 beams of 15x15 maps
    maps = scan.shape[0] * scan.shape[1]
    out = {"threads": a.threads, "scan": list(scan.shape), "python": sys.version.split()[0],
           "numpy": np.__version__, "rounds": []}
    # The machine is shared: the three are measured in turn, round after
    # round, and each one's best round is its figure (others' work only
    # slows a run down).
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "scan.npy"
        np.save(f, scan)
        env = {**os.environ, "RAYON_NUM_THREADS": str(a.threads)}
        cmd = [a.dmap, "score", str(f), "-o", str(Path(d) / "g.npy"), "--distance", "cvm-fixed"]
        subprocess.run(cmd, env=env, check=True)
        assert cvm_dmap.score(scan, "cvm-fixed").tobytes() == np.load(Path(d) / "g.npy").tobytes()
        for _ in range(a.rounds):
            t_py, c_py = timed(lambda: cvm_dmap.score(scan, "cvm-fixed"), a.seconds)
            t_cli, c_cli = timed(lambda: subprocess.run(cmd, env=env, check=True), a.seconds)
            bench = json.loads(subprocess.run(
                [a.dmap, "bench", "--geometry", "15x15", "--json", "--seconds", str(a.bench_seconds)],
                check=True, capture_output=True).stdout)
            out["rounds"].append({"python_score": round(maps / t_py), "dmap_score": round(maps / t_cli),
                                  "python_score_cpu": round(maps / c_py), "dmap_score_cpu": round(maps / c_cli),
                                  "dmap_bench_fixed": round(bench["maps_per_s"]["fixed"]),
                                  "dmap_bench_fixed_batch": round(bench["maps_per_s"]["fixed_batch"]),
                                  "dmap_bench_emd": round(bench["maps_per_s"]["emd"], 1)})
    out["best"] = {k: max(r[k] for r in out["rounds"]) for k in out["rounds"][0]}
    b = out["best"]
    out["python_over_dmap_bench_fixed"] = round(b["python_score"] / b["dmap_bench_fixed"], 3)
    out["python_over_dmap_bench_fixed_batch"] = round(b["python_score"] / b["dmap_bench_fixed_batch"], 3)
    out["python_over_dmap_score"] = round(b["python_score"] / b["dmap_score"], 3)
    out["python_over_dmap_score_cpu"] = round(b["python_score_cpu"] / b["dmap_score_cpu"], 3)
    n = a.emd_positions
    small = np.ascontiguousarray(tile[20:20 + n, 20:20 + n])
    t_emd, c_emd = timed(lambda: cvm_dmap.score(small, "emd"), a.seconds, least=3)
    out["emd_positions"] = n * n
    out["python_emd"] = {"maps_per_s": round(n * n / t_emd, 1), "maps_per_s_cpu": round(n * n / c_emd, 1)}
    try:
        import ot
    except ImportError as e:
        out["pot"] = f"not installed: {e}"
    else:
        t_pot, c_pot = timed(lambda: pot_gradient(small, ot, np), a.seconds, least=2)
        g_pot = pot_gradient(small, ot, np)
        g = cvm_dmap.score(small, "emd")[..., :2]
        out["pot"] = {"version": ot.__version__, "maps_per_s": round(n * n / t_pot, 1),
                      "maps_per_s_cpu": round(n * n / c_pot, 1),
                      "largest_difference_relative_to_largest_value": float(np.abs(g - g_pot).max() / np.abs(g_pot).max())}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
