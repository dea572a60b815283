"""The D-cache model of the bus cost model (h743twin/dcache.py) against
hit, miss and eviction sequences worked out by hand:
`cd host-tests/twin && python3 -m unittest discover -s tests`."""

import unittest

from h743twin.dcache import LINE, SETS, WAYS, DCache

COST = {"axi": (12, 2), "sram": (24, 4), "flash": (12, 0)}
AXI = 0x2400_0000
SRAM = 0x3000_0000
FLASH = 0x0800_0000
# Addresses this far apart fall in the same set.
WAY_STRIDE = SETS * LINE


def region_of(addr):
    if addr >= SRAM:
        return "sram"
    if addr >= AXI:
        return "axi"
    return "flash"


def cache():
    return DCache(COST, region_of)


class DCacheTest(unittest.TestCase):
    def test_geometry_is_the_m7s(self):
        self.assertEqual((LINE, WAYS, SETS), (32, 4, 128))
        self.assertEqual(WAY_STRIDE, 4096)

    def test_a_line_is_filled_once(self):
        c = cache()
        self.assertEqual(c.access(AXI, False, "axi"), 12)
        # Every other word of the same line hits, reads and writes alike.
        for off in range(4, LINE, 4):
            self.assertEqual(c.access(AXI + off, off % 8 == 0, "axi"), 0)
        # The next line is a miss of its own, at its memory's cost.
        self.assertEqual(c.access(SRAM + LINE, False, "sram"), 24)
        self.assertEqual((c.misses, c.writebacks), (2, 0))

    def test_least_recently_used_way_is_replaced(self):
        c = cache()
        lines = [AXI + k * WAY_STRIDE for k in range(WAYS + 1)]
        for a in lines[:WAYS]:
            self.assertEqual(c.access(a, False, "axi"), 12)
        # Touch the first line again: the second is now the oldest.
        self.assertEqual(c.access(lines[0], False, "axi"), 0)
        self.assertEqual(c.access(lines[WAYS], False, "axi"), 12)
        self.assertEqual(c.access(lines[0], False, "axi"), 0)
        self.assertEqual(c.access(lines[1], False, "axi"), 12)
        # Other sets are untouched by all this.
        self.assertEqual(c.access(AXI + LINE, False, "axi"), 12)
        self.assertEqual(c.writebacks, 0)

    def test_dirty_lines_are_written_back_at_their_memorys_cost(self):
        c = cache()
        # Write-allocate: a write miss fills the line, and dirties it.
        self.assertEqual(c.access(SRAM, True, "sram"), 24)
        for k in range(1, WAYS):
            self.assertEqual(c.access(AXI + k * WAY_STRIDE, False, "axi"), 12)
        # Evicting the dirty SRAM1-3 line: the AXI fill plus its write-back.
        self.assertEqual(c.access(AXI + WAYS * WAY_STRIDE, False, "axi"), 12 + 4)
        # Evicting a clean line costs the fill alone.
        self.assertEqual(c.access(AXI + (WAYS + 1) * WAY_STRIDE, False, "axi"), 12)
        self.assertEqual((c.misses, c.writebacks), (WAYS + 2, 1))

    def test_a_write_hit_dirties_a_clean_line(self):
        c = cache()
        self.assertEqual(c.access(AXI, False, "axi"), 12)
        self.assertEqual(c.access(AXI + 4, True, "axi"), 0)
        for k in range(1, WAYS + 1):
            c.access(AXI + k * WAY_STRIDE, False, "axi")
        self.assertEqual(c.writebacks, 1)

    def test_write_through_memory_is_never_written_back(self):
        c = cache()
        self.assertEqual(c.access(FLASH, True, "flash"), 12)
        for k in range(1, WAYS + 1):
            self.assertEqual(c.access(FLASH + k * WAY_STRIDE, False, "flash"), 12)
        self.assertEqual(c.writebacks, 0)


if __name__ == "__main__":
    unittest.main()
