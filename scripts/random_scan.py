"""A scan of random counts (uint16 .npy, shape rows x cols x J x J, each
sample uniform in 200..4000, seeded by J) for the instruction counts:

    python3 scripts/random_scan.py PATH J ROWS COLS
"""
import random
import struct
import sys

path, j, rows, cols = sys.argv[1], *map(int, sys.argv[2:5])
random.seed(j)
hdr = "{'descr': '<u2', 'fortran_order': False, 'shape': (%d, %d, %d, %d), }" % (rows, cols, j, j)
hdr += " " * (64 - (10 + len(hdr) + 1) % 64) + "\n"
with open(path, "wb") as f:
    f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(hdr)) + hdr.encode())
    n = rows * cols * j * j
    f.write(struct.pack("<%dH" % n, *[random.randint(200, 4000) for _ in range(n)]))
