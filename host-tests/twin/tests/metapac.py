"""Reads stm32-metapac's generated register description of the STM32H743ZI
(the crate embassy-stm32 builds on; its sources are in cargo's registry
after any firmware build): instance addresses, register offsets and access
(R, W, RW), field offsets and widths, interrupt numbers and the memory map.

metapac is generated from ST's SVD files through stm32-data, and carries
no reset values and no field access types (read-clear, write-1-to-clear):
those the tests take from RM0433 and check by behaviour.
"""

import glob
import os
import re

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
CHIP = "stm32h743zi"


class Missing(Exception):
    pass


def locate():
    """The src/ directory of the stm32-metapac version in Cargo.lock."""
    with open(os.path.join(REPO, "Cargo.lock")) as f:
        lock = f.read()
    m = re.search(r'name = "stm32-metapac"\nversion = "([^"]+)"', lock)
    if not m:
        raise Missing("Cargo.lock names no stm32-metapac")
    home = os.environ.get("CARGO_HOME", os.path.expanduser("~/.cargo"))
    hits = glob.glob(os.path.join(home, "registry", "src", "*", f"stm32-metapac-{m.group(1)}", "src"))
    if not hits:
        raise Missing(f"stm32-metapac {m.group(1)} is not in {home}/registry/src: "
                      "build the firmware once (cargo build --release) to fetch it")
    return hits[0]


class Register:
    def __init__(self, name, offset, access, fields):
        self.name, self.offset, self.access, self.fields = name, offset, access, fields

    def field(self, name, n=None):
        """(bit offset, width) of field `name` (element n of an array)."""
        offs, width = self.fields[name]
        if n is None:
            if isinstance(offs, list):
                raise KeyError(f"{self.name}.{name} is an array")
            return offs, width
        return offs[n], width

    def mask(self, name, n=None):
        offs, width = self.field(name, n)
        return ((1 << width) - 1) << offs

    def put(self, name, value, n=None):
        offs, width = self.field(name, n)
        assert 0 <= value < 1 << width, (name, value)
        return value << offs

    def get(self, word, name, n=None):
        offs, width = self.field(name, n)
        return word >> offs & ((1 << width) - 1)


_FN = re.compile(
    r"pub const fn (\w+)\(self(?:, n: usize)?\) -> ([^{]+?) \{\s*"
    r"(?:assert!\(n < (\d+)usize\);\s*)?"
    r"unsafe \{ [\w:]+::from_ptr\(self\.ptr\.add\(0x([0-9a-f]+)usize(?: \+ n \* (\d+)usize)?\) as _\) \}")
_REG = re.compile(r"crate::common::Reg<(?:regs::(\w+)|u\d+), crate::common::(RW|R|W)>")
_FIELD = re.compile(
    r"pub const fn (\w+)\(&self(, n: usize)?\) -> [^{]+\{\s*"
    r"(?:assert!\(n < (\d+)usize\);\s*let offs = (\d+)usize \+ (?:n \* (\d+)usize|\(\[([\d, usize]+)\]\[n\] as usize\));\s*)?"
    r"let val = \(self\.0 >> (?:(\d+)usize|offs)\) & (0x[0-9a-f_]+);")


def _split_impls(text, indent):
    """{type name: body} of every `impl Name {` block indented by `indent`."""
    out = {}
    for m in re.finditer(rf"^{indent}impl (\w+) \{{\n(.*?)^{indent}\}}\n", text, re.S | re.M):
        out.setdefault(m.group(1), m.group(2))
    return out


def _fields(body):
    fields = {}
    for m in _FIELD.finditer(body):
        name, arr, count, base, stride, table, fixed, mask = m.groups()
        width = bin(int(mask.replace("_", ""), 16)).count("1")
        if arr:
            base = int(base)
            if stride is not None:
                offs = [base + i * int(stride) for i in range(int(count))]
            else:
                offs = [base + int(x.replace("usize", "")) for x in table.split(",") if x.strip()]
            fields[name] = (offs, width)
        else:
            fields[name] = (int(fixed), width)
    return fields


class Peripheral:
    """One register block type of one metapac peripheral file."""

    def __init__(self, path, block):
        with open(path) as f:
            text = f.read()
        top, _, regs = text.partition("pub mod regs {")
        self.blocks = _split_impls(top, "")
        self.reg_types = _split_impls(regs, "    ")
        self.registers = {}  # offset -> [Register] (several names can share one)
        self._walk(block, 0, "")

    def _walk(self, block, base, prefix):
        for m in _FN.finditer(self.blocks[block]):
            name, ret, count, off, stride = m.groups()
            offsets = [base + int(off, 16) + i * int(stride or 0) for i in range(int(count or 1))]
            names = [f"{prefix}{name}" + (f"[{i}]" if count else "") for i in range(len(offsets))]
            reg = _REG.match(ret.strip())
            for n, o in zip(names, offsets):
                if reg:
                    typ, access = reg.groups()
                    fields = _fields(self.reg_types.get(typ, "")) if typ else {}
                    self.registers.setdefault(o, []).append(Register(n, o, access, fields))
                else:
                    self._walk(ret.strip(), o, n + ".")

    def reg(self, name):
        for regs in self.registers.values():
            for r in regs:
                if r.name == name:
                    return r
        raise KeyError(name)


class Chip:
    def __init__(self, src=None):
        self.src = src or locate()
        chip = os.path.join(self.src, "chips", CHIP)
        with open(os.path.join(chip, "pac.rs")) as f:
            pac = f.read()
        self.modules = dict((m, p) for p, m in re.findall(
            r'#\[path = "\.\./\.\./peripherals/([\w.]+)"\]\npub mod (\w+);', pac))
        self.instances = {name: (mod, typ, int(addr.replace("_", ""), 16)) for name, mod, typ, addr in
                          re.findall(r"pub const (\w+): (\w+)::(\w+) = unsafe \{ \w+::\w+::from_ptr\("
                                     r"0x([0-9a-f_]+)usize as _\) \};", pac)}
        self.interrupts = {n: int(v) for n, v in re.findall(r"^    (\w+) = (\d+),$", pac, re.M)}
        with open(os.path.join(chip, "metadata.rs")) as f:
            meta = f.read()
        self.memory = {n: (int(a, 16), int(s)) for n, a, s in re.findall(
            r'MemoryRegion \{\s*name: "(\w+)",\s*kind: [\w:]+,\s*address: (0x[0-9a-f]+),\s*size: (\d+),', meta)}
        self._cache = {}

    def address(self, instance):
        return self.instances[instance][2]

    def peripheral(self, instance):
        mod, typ, _ = self.instances[instance]
        key = (mod, typ)
        if key not in self._cache:
            self._cache[key] = Peripheral(os.path.join(self.src, "peripherals", self.modules[mod]), typ)
        return self._cache[key]
