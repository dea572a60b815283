"""The streaming calibration rule against the rule before it
(docs/experiments.md, "Calibration"), run by `scripts/measure.sh
calibration-rule`.

Per set-up: the new rule is `dmap calibrate` on the reference parts (the
board's calibrator); the old one (exact medians, the mean of the middle two,
over every magnitude) is recomputed here from the references' integer
magnitudes as `dmap listen` decodes them from `dmap stream --scores`, and
written as a version 2 calibration file, which `--calibration` still
applies. Then, with each file, the firmware's objects (`dmap stream
--calibration`) on the defective part, matched with its truth by
`scripts/measure.sh objects`, and on the unseen defect-free parts.

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
UNSEEN = list(range(21, 31))
POWER_MAX, POWER_OFF = 46340, 4294967295


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


def med(v):
    n = len(v)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2


def old_rule(m, k=3.0):
    """The rule before the streaming one, as dmap computed it (f64)."""
    m = sorted(m)
    median = med(m)
    mad = med(sorted(abs(x - median) for x in m))
    t = m[-1] + math.ceil(k * 1.4826 * mad) + 1
    return min(int(t), 2**32 - 1), median, mad


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


os.chdir(out)
print("| set-up | rule | CVM thr (median, MAD) | power thr (median, MAD) | defective part | "
      "objects on ten unseen parts | defective positions on them |")
print("|---|---|---|---|---|---|---|")
for v, title, seeds in SETUPS:
    refs = [f"{v}_free_s{s}.npy" for s in seeds]
    new = f"rule_{v}_new.json"
    run("calibrate", *refs, "-o", new)
    cal = json.load(open(new))
    q = cal["channels"]["cvm"]["q"]
    cvm, pw = [], []
    for r in refs:
        stem = r[:-4]
        with open(f"{stem}_rule.lines", "wb") as f:
            run("stream", r, "--scores", "--calibration", new, stdout=f)
        run("listen", "--input", f"{stem}_rule.lines", "-o", f"{stem}_rule_cvm.npy",
            "--power-output", f"{stem}_rule_power.npy")
        cvm += [round(x * 2.0**q) for x in magnitudes(f"{stem}_rule_cvm.npy")]
        pw += [round(x * 32768) for x in magnitudes(f"{stem}_rule_power.npy")]
    thr, cmed, cmad = old_rule(cvm)
    pthr, pmed, pmad = old_rule(pw)
    pthr = pthr if pthr <= POWER_MAX else POWER_OFF
    old = f"rule_{v}_old.json"
    json.dump({"format": "dmap-calibration", "version": 2, "config": cal["config"],
               "rule": {"text": "the rule before version 3: exact medians over every magnitude"},
               "channels": {"cvm": {"threshold": thr * 2.0**-q, "thr": thr, "q": q},
                            "power": {"threshold": pthr / 32768, "thr": pthr, "q": 15}}},
              open(old, "w"), indent=1)
    c, p = cal["channels"]["cvm"], cal["channels"]["power"]
    rows = [("old", thr, cmed, cmad, pthr, pmed, pmad, old),
            ("new", c["thr"], c["integers"]["median"], c["integers"]["mad"], p["thr"],
             p["integers"]["median"], p["integers"]["mad"], new)]
    for name, t, tm, td, pt, pm, pd, f in rows:
        with open(f"{v}_{name}.lines", "wb") as fh:
            run("stream", f"{v}.npy", "--scores", "--calibration", f, stdout=fh)
        found = objects(f"{v}_{name}.lines", f"{v}.truth.npy").split(", ")
        counts = [unseen(f"{v}_free_s{s}", f) for s in UNSEEN]
        unit = 2.0**-q
        ptext = "off" if pt == POWER_OFF else f"{pt / 32768:.5f}"
        print(f"| {title} | {name} | {t * unit:.5g} ({tm * unit:.4g}, {td * unit:.4g}) | "
              f"{ptext} ({pm / 32768:.4g}, {pd / 32768:.4g}) | {found[0]}, {found[1]} | "
              f"{' '.join(str(o) for o, _ in counts)} | {' '.join(str(d) for _, d in counts)} |")
