"""A model of the Cortex-M7's data cache for the bus cost model
(h743twin.cost): tags only, no data. The H743's D-cache is 16 KiB,
4-way set associative, with 32-byte lines. Replacement is taken to be
least recently used, and allocation on both reads and writes (the ARMv7-M
default attributes of the SRAM region are write-back, write-allocate).
The Cortex-M7 also switches to read-allocate on long runs of stores,
which this model does not do."""

LINE = 32
WAYS = 4
SIZE = 16 * 1024
SETS = SIZE // (LINE * WAYS)


class DCache:
    """`access(addr, write, region)` gives the stall cycles of one access
    at `addr` in memory `region`: 0 on a hit; on a miss the line fill
    `line_cost[region][0]`, plus `line_cost[r][1]` when the line it
    replaces is dirty (`r` that line's memory, from `region_of`). Writes
    make a line dirty, except in `write_through` memories."""

    def __init__(self, line_cost, region_of, write_through=("flash",)):
        self.line_cost = line_cost
        self.region_of = region_of
        self.write_through = write_through
        self.sets = [[] for _ in range(SETS)]  # [line, dirty], most recent last
        self.misses = 0
        self.writebacks = 0

    def access(self, addr, write, region):
        line = addr // LINE
        ways = self.sets[line % SETS]
        dirty = write and region not in self.write_through
        for i, w in enumerate(ways):
            if w[0] == line:
                ways.append(ways.pop(i))
                w[1] = w[1] or dirty
                return 0
        self.misses += 1
        stall = self.line_cost[region][0]
        if len(ways) == WAYS:
            old, old_dirty = ways.pop(0)
            if old_dirty:
                self.writebacks += 1
                stall += self.line_cost[self.region_of(old * LINE)][1]
        ways.append([line, dirty])
        return stall
