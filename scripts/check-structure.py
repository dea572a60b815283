#!/usr/bin/env python3
"""The repository's shape rules, checked mechanically.

1. No import circle of any length between source files: a Rust module file
   refers to another file's module with `use crate::a`, `crate::a::f()`,
   `super::x` or `self::child`; a Python module imports another of its
   package. A crate root's `pub use` and `mod` lines are its public face,
   not imports, so a module may name `crate::Item`.
2. No import circle between folders: a module folder (`a/` with `a.rs` or
   `a/mod.rs`) depends on another when one of its files imports one of the
   other's, leaving out a folder's own ancestors and descendants (a
   module's children are its parts).
3. No source file outside the tests over 700 lines, unless it says in its
   first lines that it is generated.
4. No Rust function over 120 lines in the firmware's crates (cvm-core,
   fw-app, src/) and the firmware's build.rs.
Files and functions at 90 % of a cap are listed as warnings (exit 0).

Usage: scripts/check-structure.py [ROOT]   (default: this repository)
Prints each breach on one line and exits 1 when there is any.
"""

import os
import re
import sys

MAX_FILE_LINES = 700
MAX_FN_LINES = 120
FN_RULE_DIRS = ("cvm-core/", "fw-app/", "src/", "build.rs", "boards/")
WARN_SHARE = 0.9
SKIP_DIRS = {".git", "target", "corpus", "__pycache__", "node_modules"}
TEST_PARTS = ("/tests/", "/benches/", "/fuzz/", "/examples/")


def source_files(root):
    for top, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d not in SKIP_DIRS)
        for name in sorted(files):
            if name.endswith((".rs", ".py", ".sh")):
                yield os.path.relpath(os.path.join(top, name), root)


def strip_rust(text):
    """Text with comments, string and char literals blanked (newlines kept),
    so braces and paths inside them do not count."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            i = j
            continue
        if text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
            continue
        m = re.match(r'b?r(#*)"', text[i:i + 40]) if c in "br" and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")) else None
        if m:
            close = '"' + m.group(1)
            j = text.find(close, i + m.end())
            j = n if j < 0 else j + len(close)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
            continue
        if c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            j = min(n, j + 1)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
            continue
        if c == "'":
            m = re.match(r"'(\\.[^']*|[^\\'])'", text[i:i + 12])
            if m:
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
                continue
        out.append(c)
        i += 1
    return "".join(out)


def drop_test_modules(code):
    """Blanks `#[cfg(test)] mod name { ... }` blocks: their `super::` is
    the file itself."""
    for m in reversed(list(re.finditer(r"#\[cfg\(test\)\]\s*(pub\s+)?mod\s+\w+\s*\{", code))):
        depth, j = 0, m.end() - 1
        while j < len(code):
            if code[j] == "{":
                depth += 1
            elif code[j] == "}":
                depth -= 1
                if depth == 0:
                    break
            j += 1
        code = code[:m.start()] + re.sub(r"[^\n]", " ", code[m.start():j + 1]) + code[j + 1:]
    return code


def expand_use_tree(tree):
    """`a::{b, c::{d, e}}` -> ['a::b', 'a::c::d', 'a::c::e']."""
    tree = re.sub(r"\s+", "", tree)
    i = tree.find("{")
    if i < 0:
        return [tree]
    prefix, body = tree[:i], tree[i + 1:tree.rfind("}")]
    parts, depth, start = [], 0, 0
    for k, ch in enumerate(body):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(body[start:k])
            start = k + 1
    parts.append(body[start:])
    return [p for part in parts if part for p in expand_use_tree(prefix + part)]


class RustCrate:
    def __init__(self, root, crate_dir, entry):
        self.root, self.dir = root, crate_dir
        self.files = {}  # module path tuple -> file
        self._walk(os.path.join(crate_dir, entry), ())

    def _walk(self, path, modpath):
        self.files[modpath] = path
        code = strip_rust(read(os.path.join(self.root, path)))
        base = os.path.dirname(path)
        stem = os.path.basename(path)[:-3]
        if stem not in ("lib", "main", "mod"):
            base = os.path.join(base, stem)
        for m in re.finditer(r"(?m)^\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", code):
            name = m.group(1)
            attr = re.search(r'#\[path\s*=\s*"([^"]+)"\]', read(os.path.join(self.root, path))[m.start():m.end() + 200])
            for cand in ([os.path.join(base, attr.group(1))] if attr else []) + [
                os.path.join(base, name + ".rs"),
                os.path.join(base, name, "mod.rs"),
            ]:
                if os.path.exists(os.path.join(self.root, cand)):
                    self._walk(cand, modpath + (name,))
                    break

    def resolve(self, modpath):
        """The file of the deepest file module that `modpath` names."""
        for k in range(len(modpath), -1, -1):
            if modpath[:k] in self.files:
                return self.files[modpath[:k]]
        return None

    def edges(self):
        by_file = {f: m for m, f in self.files.items()}
        for path, modpath in by_file.items():
            code = drop_test_modules(strip_rust(read(os.path.join(self.root, path))))
            is_root = modpath == ()
            targets = set()
            for m in re.finditer(r"(?s)\b(pub(?:\([^)]*\))?\s+)?use\s+([^;]+);", code):
                if is_root and m.group(1):
                    continue  # the crate's public face
                for p in expand_use_tree(m.group(2)):
                    targets.add(self._absolute(p, modpath))
            no_use = re.sub(r"(?s)\buse\s+[^;]+;", "", code)
            for m in re.finditer(r"\b((?:crate|super|self)(?:::\w+)+)", no_use):
                targets.add(self._absolute(m.group(1), modpath))
            for t in targets:
                if t is None:
                    continue
                f = self.resolve(t)
                if f and f != path:
                    yield os.path.normpath(path), os.path.normpath(f)

    def _absolute(self, p, modpath):
        segs = p.split("::")
        if tuple(modpath) + (segs[0],) in self.files:
            segs = ["self"] + segs  # a child module, named relative to this one
        if segs[0] == "crate":
            return tuple(s for s in segs[1:] if s not in ("*", "self"))
        if segs[0] in ("super", "self"):
            base = list(modpath)
            while segs and segs[0] in ("super", "self"):
                if segs.pop(0) == "super":
                    if not base:
                        return None
                    base.pop()
            return tuple(base + [s for s in segs if s not in ("*", "self")])
        return None  # another crate or a local name


def python_edges(root, pkg_dir):
    pkg = os.path.basename(pkg_dir)
    mods = {f[:-3]: os.path.join(pkg_dir, f) for f in os.listdir(os.path.join(root, pkg_dir)) if f.endswith(".py")}
    for name, path in mods.items():
        text = read(os.path.join(root, path))
        for m in re.finditer(r"(?m)^\s*from\s+(\.+|%s\.?)(\w*)\s+import\s+([\w ,()]+)" % pkg, text):
            target = m.group(2)
            if target:
                cands = [target]
            else:
                cands = [x.strip() for x in m.group(3).strip("() ").split(",")]
            for t in cands:
                if t in mods and t != name:
                    yield path, mods[t]
        for m in re.finditer(r"(?m)^\s*import\s+%s\.(\w+)" % pkg, text):
            if m.group(1) in mods and m.group(1) != name:
                yield path, mods[m.group(1)]


def read(path):
    with open(path, encoding="utf-8", errors="replace") as f:
        return f.read()


def crates(root):
    for top, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in SKIP_DIRS]
        if "Cargo.toml" in files:
            rel = os.path.normpath(os.path.relpath(top, root))
            for entry in ("src/lib.rs", "src/main.rs"):
                if os.path.exists(os.path.join(top, entry)):
                    yield RustCrate(root, rel, entry)


def python_packages(root):
    for top, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in SKIP_DIRS]
        if "__init__.py" in files or "__main__.py" in files:
            yield os.path.relpath(top, root)


def long_functions(code, cap=MAX_FN_LINES):
    lines = code.split("\n")
    sig = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:const\s+)?(?:async\s+)?(?:unsafe\s+)?(?:extern\s+\S*\s+)?fn\s+(\w+)")
    for i, line in enumerate(lines):
        m = sig.match(line)
        if not m:
            continue
        depth, started = 0, False
        for j in range(i, len(lines)):
            for ch in lines[j]:
                if ch == "{":
                    depth, started = depth + 1, True
                elif ch == "}":
                    depth -= 1
                elif ch == ";" and not started and depth == 0:
                    break  # a declaration without a body
            else:
                if started and depth == 0:
                    if j - i + 1 > cap:
                        yield i + 1, m.group(1), j - i + 1
                    break
                continue
            break


def circles(edges):
    """Every strongly connected component of more than one node (Tarjan's
    algorithm, iterative), each as a sorted list."""
    graph = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
        graph.setdefault(b, set())
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            node, it = work[-1]
            nxt = next(it, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter[0]
                    counter[0] += 1
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                elif nxt in on:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == node:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return sorted(out)


def module_path(path):
    """`src/a/b.rs`, `src/a/b/mod.rs` -> `src/a/b`; a crate root -> `src`."""
    stem = path[:-3] if path.endswith((".rs", ".py")) else path
    if os.path.basename(stem) in ("mod", "lib", "main", "__init__"):
        stem = os.path.dirname(stem)
    return stem


def folder_edges(edges, root):
    """An import between files, seen from the two sibling modules that hold
    them below their closest common module; kept when either sibling is a
    folder (file pairs are rule 1's)."""
    for a, b in edges:
        ma, mb = module_path(a).split("/"), module_path(b).split("/")
        k = 0
        while k < min(len(ma), len(mb)) and ma[k] == mb[k]:
            k += 1
        if k == len(ma) or k == len(mb):
            continue  # one holds the other
        ua, ub = "/".join(ma[:k + 1]), "/".join(mb[:k + 1])
        if os.path.isdir(os.path.join(root, ua)) or os.path.isdir(os.path.join(root, ub)):
            yield ua + ("/" if os.path.isdir(os.path.join(root, ua)) else ".rs"), \
                ub + ("/" if os.path.isdir(os.path.join(root, ub)) else ".rs")


def cycle_text(nodes, edges):
    """One cycle through the component, as `a -> b -> ... -> a`."""
    inside = set(nodes)
    graph = {n: sorted(b for a, b in edges if a == n and b in inside) for n in nodes}
    start = nodes[0]
    # Breadth-first from start's successors back to start.
    prev, frontier = {}, [start]
    while frontier:
        nxt = []
        for n in frontier:
            for m in graph[n]:
                if m not in prev:
                    prev[m] = n
                    nxt.append(m)
        if start in prev:
            break
        frontier = nxt
    path, n = [start], prev.get(start)
    while n is not None and n != start:
        path.append(n)
        n = prev.get(n)
    return " -> ".join([start] + path[:0:-1] + [start]) if len(path) > 1 else " -> ".join(nodes + [start])


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), ".."))
    problems = []

    edges = set()
    for crate in crates(root):
        edges.update(crate.edges())
    for pkg in python_packages(root):
        edges.update(python_edges(root, pkg))
    for comp in circles(edges):
        if len(comp) == 2:
            problems.append(f"import circle: {comp[0]} <-> {comp[1]}")
        else:
            problems.append(f"import circle: {cycle_text(comp, edges)}")
    folders = set(folder_edges(edges, root))
    for comp in circles(folders):
        problems.append(f"folder circle: {cycle_text(comp, folders)}")
    warnings = []

    for path in source_files(root):
        full = os.path.join(root, path)
        text = read(full)
        n = text.count("\n")
        slashed = "/" + path
        capped = not any(t in slashed for t in TEST_PARTS) \
            and "generated" not in "\n".join(text.split("\n")[:5]).lower()
        if capped and n > MAX_FILE_LINES:
            problems.append(f"{path}: {n} lines (at most {MAX_FILE_LINES} outside the tests)")
        elif capped and n > WARN_SHARE * MAX_FILE_LINES:
            warnings.append(f"{path}: {n} lines (90 % of {MAX_FILE_LINES})")
        if path.endswith(".rs") and path.startswith(FN_RULE_DIRS):
            for line, name, length in long_functions(strip_rust(text)):
                problems.append(f"{path}:{line}: fn {name} is {length} lines (at most {MAX_FN_LINES})")
            for line, name, length in long_functions(strip_rust(text), int(WARN_SHARE * MAX_FN_LINES)):
                if length <= MAX_FN_LINES:
                    warnings.append(f"{path}:{line}: fn {name} is {length} lines (90 % of {MAX_FN_LINES})")

    for w in warnings:
        print(f"warning: {w}")
    for p in problems:
        print(p)
    print(f"structure: {len(problems)} problem(s)" if problems else "structure: ok")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
