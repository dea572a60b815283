"""Lists the panic call sites left in a cvm-nopanic image and the source
lines that reach them (inlined frames included), from the disassembly.

    python3 panic_sites.py ELF DISASSEMBLY ROOT
"""
import re
import subprocess
import sys

elf, dis, root = sys.argv[1], sys.argv[2], sys.argv[3]
target = re.compile(
    r"^\s*([0-9a-f]+):\s+\S+\s+.*<(core::panicking::[^>+]*|core::slice::[^>+]*fail[^>+]*"
    r"|core::option::[^>+]*|core::result::[^>+]*)>"
)
current, sites = None, []
for line in open(dis):
    m = re.match(r"^([0-9a-f]+) <(.*)>:", line)
    if m:
        current = m.group(2)
        continue
    m = target.match(line)
    if m and current and not current.startswith("core::"):
        sites.append((m.group(1), m.group(2)))
print(f"{len(sites)} panic call site(s):")
for addr, callee in sites:
    out = subprocess.run(
        ["llvm-addr2line", "-f", "-i", "-C", "-e", elf, "0x" + addr],
        capture_output=True, text=True,
    ).stdout.strip().split("\n")
    chain = []
    for i in range(0, len(out) - 1, 2):
        if "/rustc/" in out[i + 1]:
            continue
        fn = re.sub(r"::h[0-9a-f]{16}$", "", out[i]).replace("$LT$", "<").replace("$GT$", ">")
        chain.append(f"{fn} ({out[i + 1].replace(root, '')})")
    print(f"- {callee}: " + " <- ".join(chain))
