#!/usr/bin/env python3
"""The defect objects as the firmware reports them (O lines of `dmap stream`/`emulate`/`twin`
output, protocol v4), against a truth mask (docs/experiments.md).

Usage: fw_objects.py LINES.txt [TRUTH.npy] [--pitch-um P] [--count]
  --count   print only the number of object lines (defect-free parts)
Without TRUTH: one line per object. With TRUTH (bool .npy, rows x cols): per truth component
(8-connected, in raster order of its first position) the objects whose bounding box meets the
component's bounding box grown by one position (Eq. 1's reach: a position next to a defect
scores, and the power channel fires around a dimmed beam rather than on it), their union's
extent against the truth's, as detected and corrected by one position per side; objects meeting
no component are false. With S lines (run with --scores), each defect's peak magnitudes of both
channels within that grown box, against the header's thresholds. Standard library only; O line fields: id,row0,row1,col0,col1,area,peak,
peak_row,peak_col,peak_mag,peak_power,centroid_row_q8,centroid_col_q8,channels (16 CVM, 32 power).
"""
import ast
import struct
import sys


B64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_"


def objects(path, scores=None, head=None):
    out, unobj = [], None
    for line in open(path, "rb").read().decode("ascii", "replace").splitlines():
        body = line.split("*")[0]
        if body.startswith("H,") and head is not None:
            head.update(x.split("=", 1) for x in body.split(",")[1:])
        elif body.startswith("S,") and scores is not None:
            _, row, col0, chars = body.split(",")
            for i in range(len(chars) // 9):
                v = 0
                for ch in chars[9 * i:9 * i + 9]:
                    v = v * 64 + B64.index(ch)
                scores[(int(row), int(col0) + i)] = (v & 0xFFFFFFFF, (v >> 32) & 0xFFFF)
        elif body.startswith("O,"):
            f = [int(x) for x in body.split(",")[1:]]
            out.append(dict(zip("id r0 r1 c0 c1 area peak pr pc pmag_cvm ppow cr cc ch".split(), f)))
        elif body.startswith("E,"):
            kv = dict(x.split("=") for x in body.split(",")[1:])
            unobj = int(kv.get("unobj", 0))
    return out, unobj


def load_mask(path):
    b = open(path, "rb").read()
    hl = struct.unpack("<H", b[8:10])[0]
    h = ast.literal_eval(b[10:10 + hl].decode())
    rows, cols = h["shape"][:2]
    return rows, cols, [x != 0 for x in b[10 + hl:10 + hl + rows * cols]]


def components(rows, cols, m):
    seen, comps = [False] * (rows * cols), []
    for start in range(rows * cols):
        if not m[start] or seen[start]:
            continue
        stack, px = [start], []
        seen[start] = True
        while stack:
            k = stack.pop()
            px.append(k)
            r, c = divmod(k, cols)
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    rr, cc = r + dr, c + dc
                    if 0 <= rr < rows and 0 <= cc < cols:
                        j = rr * cols + cc
                        if m[j] and not seen[j]:
                            seen[j] = True
                            stack.append(j)
        rs = [k // cols for k in px]
        cs = [k % cols for k in px]
        comps.append(dict(r0=min(rs), r1=max(rs), c0=min(cs), c1=max(cs), area=len(px)))
    return comps


def chan(ch):
    return "+".join(n for bit, n in ((16, "cvm"), (32, "power")) if ch & bit) or "-"


def main():
    args = sys.argv[1:]
    pitch = 334.0
    if "--pitch-um" in args:
        i = args.index("--pitch-um")
        pitch = float(args[i + 1])
        del args[i:i + 2]
    count = "--count" in args
    args = [a for a in args if a != "--count"]
    scores, head = {}, {}
    objs, unobj = objects(args[0], scores, head)
    if count:
        print(len(objs))
        return
    if len(args) < 2:
        for o in objs:
            h, w = o["r1"] - o["r0"] + 1, o["c1"] - o["c0"] + 1
            ch, cw = max(h - 2, 1), max(w - 2, 1)
            print(f"object {o['id']}: rows {o['r0']}-{o['r1']} cols {o['c0']}-{o['c1']} ({h}x{w}, "
                  f"area {o['area']}), corrected {ch}x{cw} = {ch * pitch / 1000:.2f} x {cw * pitch / 1000:.2f} mm, "
                  f"channels {chan(o['ch'])}")
        print(f"{len(objs)} object(s), {unobj} defective position(s) outside every object")
        return
    rows, cols, m = load_mask(args[1])
    comps = components(rows, cols, m)
    used = set()
    found = 0
    for t in comps:
        hit = [o for o in objs if o["r0"] <= t["r1"] + 1 and o["r1"] >= t["r0"] - 1
               and o["c0"] <= t["c1"] + 1 and o["c1"] >= t["c0"] - 1]
        th, tw = t["r1"] - t["r0"] + 1, t["c1"] - t["c0"] + 1
        peak = ""
        if scores:
            near = [scores.get((r, c), (0, 0)) for r in range(t["r0"] - 1, t["r1"] + 2)
                    for c in range(t["c0"] - 1, t["c1"] + 2)]
            q = int(head.get("q", 0))
            peak = (f" [peaks: cvm {max(v[0] for v in near) * 2.0 ** -q:.4g} vs thr "
                    f"{int(head['thr']) * 2.0 ** -q:.4g}, power {max(v[1] for v in near) / 32768:.4f} vs "
                    f"{int(head['pthr']) / 32768:.4f}]")
        head_ = f"  truth rows {t['r0']}-{t['r1']} cols {t['c0']}-{t['c1']} ({th}x{tw}, area {t['area']}) -> "
        if not hit:
            print(head_ + "missed" + peak)
            continue
        found += 1
        used.update(o["id"] for o in hit)
        r0, r1 = min(o["r0"] for o in hit), max(o["r1"] for o in hit)
        c0, c1 = min(o["c0"] for o in hit), max(o["c1"] for o in hit)
        h, w = r1 - r0 + 1, c1 - c0 + 1
        ch, cw = max(h - 2, 1), max(w - 2, 1)
        chans = 0
        for o in hit:
            chans |= o["ch"]
        print(head_ + f"{len(hit)} object(s), rows {r0}-{r1} cols {c0}-{c1} ({h}x{w}, area "
              f"{sum(o['area'] for o in hit)}), error rows {100 * (h - th) / th:+.0f} % cols "
              f"{100 * (w - tw) / tw:+.0f} % (corrected {ch}x{cw}: {100 * (ch - th) / th:+.0f} % / "
              f"{100 * (cw - tw) / tw:+.0f} %), channels {chan(chans)}" + peak)
    false = [o for o in objs if o["id"] not in used]
    print(f"{found}/{len(comps)} defects found, {len(false)} false objects, {len(objs)} objects, "
          f"{unobj} defective position(s) outside every object")
    for o in false:
        print(f"  false: rows {o['r0']}-{o['r1']} cols {o['c0']}-{o['c1']} area {o['area']} channels {chan(o['ch'])}")


main()
