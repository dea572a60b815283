"""Calibration rules against each other on unseen parts (docs/experiments.md,
"Calibration" and "Thresholds from a target rate"), run by
`scripts/measure.sh calibration-rule`.

Per set-up, calibrated on the reference parts (seeds 11-15 prototype, 11-13
paper-sim), the thresholds of:

- `exact`: the rule before the streaming one (exact medians, the mean of
  the middle two, over every magnitude), recomputed here from the
  references' integer magnitudes as `dmap listen` decodes them from `dmap
  stream --scores`, written as a version 2 calibration file;
- `spread`: `dmap calibrate --rule spread` (thr = max + ceil(3 1.4826 MAD)
  + 1, the board's streaming rule);
- `tail`, `tail f=...`: `dmap calibrate --rule tail` (one false position in
  1000 parts, the top 1 % fitted; other tail shares);
- `maxima`: an extreme-value fit of the per-reference maxima (Gumbel by the
  method of moments, the part maximum's 0.999 quantile), in f64 here,
  written as a version 2 file: the alternative the tail rule was chosen
  over.

Then, with each file, the firmware's objects (`dmap stream --calibration`)
on the defective part (seed 1), matched with its truth by
`scripts/measure.sh objects`, and on the unseen defect-free parts (seeds
21-40). Last, the tail fit's prediction against what the unseen parts
show: the positions per part at or above the levels where the fit expects
1, 0.1 and 0.01 of them; and, with the spread and tail files, whether a
scattering disc (`{v}_halo{share}.npy`, `dmap simulate --scatter`) of each
share is found.

usage: calibration_rule.py DMAP OUT_DIR
"""
import array
import ast
import json
import math
import os
import struct
import subprocess
import sys

dmap, out = sys.argv[1], sys.argv[2]
root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SETUPS = [
    ("proto", "prototype", [11, 12, 13, 14, 15]),
    ("simblur", "paper-sim, 300 um spot", [11, 12, 13]),
    ("sim", "paper-sim, point spot", [11, 12, 13]),
]
UNSEEN = list(range(21, 41))
POWER_MAX, POWER_OFF = 46340, 4294967295
TARGET = 1e-3


def run(*args, stdout=None):
    done = subprocess.run([dmap, *args], stdout=stdout or subprocess.PIPE,
                          stderr=subprocess.PIPE, text=stdout is None)
    if done.returncode != 0:
        sys.exit(f"calibration_rule: dmap {' '.join(args)} failed:\n{done.stderr}")
    return done.stdout


def magnitudes(path):
    """Channel 2 (the magnitude) of a decoded image, positions with data."""
    b = open(path, "rb").read()
    hl = struct.unpack("<H", b[8:10])[0]
    h = ast.literal_eval(b[10:10 + hl].decode())
    a = array.array("d")
    a.frombytes(b[10 + hl:])
    assert h["descr"] == "<f8" and h["shape"][2] == 3, h
    return [a[i] for i in range(2, len(a), 3) if not math.isnan(a[i])]


def decoded(stem, cal, q):
    """Integer CVM and power magnitudes of a scan, as the firmware scores it."""
    with open(f"{stem}_rule.lines", "wb") as f:
        run("stream", f"{stem}.npy", "--scores", "--calibration", cal, stdout=f)
    run("listen", "--input", f"{stem}_rule.lines", "-o", f"{stem}_rule_cvm.npy",
        "--power-output", f"{stem}_rule_power.npy")
    return ([round(x * 2.0**q) for x in magnitudes(f"{stem}_rule_cvm.npy")],
            [round(x * 32768) for x in magnitudes(f"{stem}_rule_power.npy")])


def med(v):
    n = len(v)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2


def exact_rule(m, k=3.0):
    """The rule before the streaming one, as dmap computed it (f64)."""
    m = sorted(m)
    median = med(m)
    mad = med(sorted(abs(x - median) for x in m))
    return min(int(m[-1] + math.ceil(k * 1.4826 * mad) + 1), 2**32 - 1)


def maxima_rule(maxima):
    """Gumbel fit of per-part maxima (moments); the 1 - TARGET quantile."""
    n = len(maxima)
    mean = sum(maxima) / n
    sd = math.sqrt(sum((x - mean) ** 2 for x in maxima) / (n - 1))
    beta = sd * math.sqrt(6) / math.pi
    mu = mean - 0.5772156649 * beta
    t = mu - beta * math.log(-math.log(1 - TARGET))
    return min(max(math.ceil(t), max(maxima) + 1), 2**32 - 1)


def v2_file(path, config, q, thr, pthr, text):
    pthr = pthr if pthr <= POWER_MAX else POWER_OFF
    json.dump({"format": "dmap-calibration", "version": 2, "config": config,
               "rule": {"text": text},
               "channels": {"cvm": {"threshold": thr * 2.0**-q, "thr": thr, "q": q},
                            "power": {"threshold": pthr / 32768, "thr": pthr, "q": 15}}},
              open(path, "w"), indent=1)
    return thr, pthr


def objects(lines, truth):
    """`N/M defects found, F false objects, ...` of measure.sh objects."""
    done = subprocess.run(["bash", f"{root}/scripts/measure.sh", "objects", lines, truth],
                          capture_output=True, text=True, check=True)
    return [ln for ln in done.stdout.splitlines() if "defects found" in ln][0]


def unseen(stem, cal):
    """Objects and defective positions the firmware reports on a part."""
    path = f"{stem}.lines"
    with open(path, "wb") as f:
        run("stream", f"{stem}.npy", "--calibration", cal, stdout=f)
    v = json.loads(run("listen", "--input", path, "--json"))
    return len(v["objects"]), v["totals"]["defects"]


def level(fit, scans, expected):
    """Where the fit expects `expected` positions per part (integers)."""
    u, n_u, e = fit["start"], fit["positions"], fit["excess"]
    return u + e / n_u * math.log(n_u / (expected * scans))


def rate(ch):
    r = ch.get("false_positions_per_part")
    return "-" if r is None else f"{r:.2g}"


def halo(v, f, share):
    """The scattering disc of `{v}_halo{share}.npy`: found (channels) or missed, peaks."""
    stem = f"{v}_halo{share}"
    with open(f"{stem}_{os.path.basename(f)[:-5]}.lines", "wb") as fh:
        run("stream", f"{stem}.npy", "--scores", "--calibration", f, stdout=fh)
    done = subprocess.run(["bash", f"{root}/scripts/measure.sh", "objects", fh.name, f"{stem}.truth.npy"],
                          capture_output=True, text=True, check=True)
    line = [ln for ln in done.stdout.splitlines() if ln.startswith("  truth")][0]
    peaks = line[line.index("[peaks: ") + 8:-1].replace(" vs thr ", " / ").replace(" vs ", " / ")
    return ("found, " + line.split("channels ")[1].split(" ")[0] if "missed" not in line
            else "missed") + f" ({peaks})"


os.chdir(out)
rows, checks, halos = [], [], []
for v, title, seeds in SETUPS:
    refs = [f"{v}_free_s{s}.npy" for s in seeds]
    files = {}
    for name, args in [("spread", ["--rule", "spread"]), ("tail", ["--rule", "tail"]),
                       ("tail f=0.001", ["--rule", "tail", "--tail-fraction", "0.001"]),
                       ("tail f=0.05", ["--rule", "tail", "--tail-fraction", "0.05"])]:
        path = f"rule_{v}_{name.replace(' ', '_').replace('=', '')}.json"
        run("calibrate", *refs, *args, "-o", path)
        files[name] = path
    cal = json.load(open(files["tail"]))
    q = cal["channels"]["cvm"]["q"]
    cvm, pw = [], []
    for r in refs:
        c, p = decoded(r[:-4], files["tail"], q)
        cvm += c
        pw += p
    files["exact"] = f"rule_{v}_exact.json"
    v2_file(files["exact"], cal["config"], q, exact_rule(cvm), exact_rule(pw),
            "the rule before version 3: exact medians over every magnitude")
    files["maxima"] = f"rule_{v}_maxima.json"
    v2_file(files["maxima"], cal["config"], q,
            maxima_rule([r["integers"]["max"] for r in cal["references"]]),
            maxima_rule([r["power"]["integers"]["max"] for r in cal["references"]]),
            "Gumbel fit of the references' maxima, 0.999 quantile (f64)")
    # The fit against the unseen parts' magnitudes.
    seen = [decoded(f"{v}_free_s{s}", files["tail"], q) for s in UNSEEN]
    for ch, idx in (("cvm", 0), ("power", 1)):
        fit = cal["channels"][ch]["tail"]["integers"]
        if not fit["positions"]:
            continue
        for e in (1.0, 0.1, 0.01):
            t = level(fit, len(seeds), e)
            obs = sum(sum(1 for x in part[idx] if x >= t) for part in seen) / len(seen)
            checks.append(f"| {title} | {ch} | {e:g} | {obs:.3g} |")
    for name in ["exact", "spread", "tail", "tail f=0.001", "tail f=0.05", "maxima"]:
        f = files[name]
        c = json.load(open(f))["channels"]
        t, pt = c["cvm"]["thr"], c["power"]["thr"]
        with open(f"{v}_{name.replace(' ', '_').replace('=', '')}.lines", "wb") as fh:
            run("stream", f"{v}.npy", "--scores", "--calibration", f, stdout=fh)
        found = objects(fh.name, f"{v}.truth.npy").split(", ")
        counts = [unseen(f"{v}_free_s{s}", f) for s in UNSEEN]
        ptext = "off" if pt == POWER_OFF else f"{pt / 32768:.5f}"
        rows.append(f"| {title} | {name} | {t * 2.0**-q:.5g} | {ptext} | "
                    f"{rate(c['cvm'])} / {rate(c['power'])} | {found[0]}, {found[1]} | "
                    f"{sum(o for o, _ in counts)} ({sum(1 for o, _ in counts if o)} parts) | "
                    f"{sum(d for _, d in counts)} |")
for v, title, _ in SETUPS:
    for name in ("spread", "tail"):
        f = f"rule_{v}_{name}.json"
        if os.path.exists(f"{v}_halo0.05.npy"):
            halos.append(f"| {title} | {name} | "
                         + " | ".join(halo(v, f, s) for s in ("0.05", "0.1", "0.2", "0.3")) + " |")
print("| set-up | rule | CVM thr | power thr | estimated false positions per part (CVM / power) | "
      f"defective part | false objects on {len(UNSEEN)} unseen parts | defective positions on them |")
print("|---|---|---|---|---|---|---|---|")
print("\n".join(rows))
print()
print("| set-up | channel | the fit expects per part | observed per unseen part (mean) |")
print("|---|---|---|---|")
print("\n".join(checks))
print()
print("Scattering discs, two positions across, share of the light crossing them 5 / 10 / 20 / 30 %"
      " (peaks: CVM / its thr, power / its thr):")
print()
print("| set-up | rule | 5 % | 10 % | 20 % | 30 % |")
print("|---|---|---|---|---|---|")
print("\n".join(halos))
