"""The structure checker finds what it is meant to find, on small trees made
here, and passes a tree without breaches."""

import os
import subprocess
import sys
import tempfile
import unittest

CHECKER = os.path.join(os.path.dirname(__file__), "..", "check-structure.py")


def run(tree):
    with tempfile.TemporaryDirectory() as root:
        for path, text in tree.items():
            full = os.path.join(root, path)
            os.makedirs(os.path.dirname(full), exist_ok=True)
            with open(full, "w") as f:
                f.write(text)
        r = subprocess.run([sys.executable, CHECKER, root], capture_output=True, text=True)
        return r.returncode, r.stdout


CRATE = {"cvm-core/Cargo.toml": "[package]\n", "cvm-core/src/lib.rs": "pub mod a;\npub mod b;\npub use a::A;\n"}


class Checker(unittest.TestCase):
    def test_clean_tree_passes(self):
        tree = dict(CRATE, **{"cvm-core/src/a.rs": "use crate::b::B;\npub struct A;\n",
                              "cvm-core/src/b.rs": "pub struct B;\n// use crate::a::A;\nconst S: &str = \"crate::a::A\";\n"})
        self.assertEqual(run(tree), (0, "structure: ok\n"))

    def test_rust_circle_through_use_tree_and_path(self):
        tree = dict(CRATE, **{"cvm-core/src/a.rs": "use crate::{b::{B, C}};\npub struct A;\n",
                              "cvm-core/src/b.rs": "pub struct B;\nfn f() { crate::a::A; }\n"})
        rc, out = run(tree)
        self.assertEqual(rc, 1)
        self.assertIn("import circle: cvm-core/src/a.rs <-> cvm-core/src/b.rs", out)

    def test_child_using_parent_while_parent_uses_child(self):
        tree = dict(CRATE, **{"cvm-core/src/a.rs": "mod inner;\nuse inner::X;\npub struct A;\n",
                              "cvm-core/src/a/inner.rs": "use super::A;\npub struct X;\n",
                              "cvm-core/src/b.rs": ""})
        rc, out = run(tree)
        self.assertIn("cvm-core/src/a.rs <-> cvm-core/src/a/inner.rs", out)
        tree["cvm-core/src/a.rs"] = "mod inner;\nuse self::inner::X;\npub struct A;\n"
        self.assertIn("cvm-core/src/a.rs <-> cvm-core/src/a/inner.rs", run(tree)[1])

    def test_super_in_inline_test_module_is_the_file_itself(self):
        tree = dict(CRATE, **{"cvm-core/src/a.rs": "use crate::b::B;\npub struct A;\n#[cfg(test)]\nmod tests {\n    use super::*;\n    use crate::b::B;\n}\n",
                              "cvm-core/src/b.rs": "pub struct B;\n"})
        self.assertEqual(run(tree)[0], 0)

    def test_three_file_circle(self):
        tree = dict(CRATE, **{"cvm-core/src/lib.rs": "pub mod a;\npub mod b;\npub mod c;\n",
                              "cvm-core/src/a.rs": "use crate::b::B;\npub struct A;\n",
                              "cvm-core/src/b.rs": "use crate::c::C;\npub struct B;\n",
                              "cvm-core/src/c.rs": "pub struct C;\nfn f() { crate::a::A; }\n"})
        rc, out = run(tree)
        self.assertEqual(rc, 1)
        self.assertIn("import circle: cvm-core/src/a.rs -> cvm-core/src/b.rs -> cvm-core/src/c.rs -> cvm-core/src/a.rs", out)
        tree["cvm-core/src/c.rs"] = "pub struct C;\n"
        self.assertEqual(run(tree), (0, "structure: ok\n"))

    def test_folder_circle_without_file_circle(self):
        tree = dict(CRATE, **{"cvm-core/src/lib.rs": "pub mod a;\npub mod b;\n",
                              "cvm-core/src/a/mod.rs": "pub mod x;\npub mod y;\n",
                              "cvm-core/src/a/x.rs": "use crate::b::p::P;\npub struct X;\n",
                              "cvm-core/src/a/y.rs": "pub struct Y;\n",
                              "cvm-core/src/b/mod.rs": "pub mod p;\npub mod q;\n",
                              "cvm-core/src/b/p.rs": "pub struct P;\n",
                              "cvm-core/src/b/q.rs": "use crate::a::y::Y;\npub struct Q;\n"})
        rc, out = run(tree)
        self.assertEqual(rc, 1)
        self.assertIn("folder circle: cvm-core/src/a/ -> cvm-core/src/b/ -> cvm-core/src/a/", out)
        self.assertNotIn("import circle", out)
        # A file beside a folder counts as its own module.
        tree["cvm-core/src/b/q.rs"] = "pub struct Q;\n"
        tree["cvm-core/src/lib.rs"] = "pub mod a;\npub mod b;\npub mod s;\n"
        tree["cvm-core/src/s.rs"] = "use crate::a::y::Y;\n"
        tree["cvm-core/src/b/p.rs"] = "use crate::s;\npub struct P;\n"
        self.assertIn("folder circle: cvm-core/src/a/ -> cvm-core/src/b/ -> cvm-core/src/s.rs -> cvm-core/src/a/",
                      run(tree)[1])
        # A child using its parent is not a circle.
        del tree["cvm-core/src/s.rs"]
        tree["cvm-core/src/lib.rs"] = "pub mod a;\npub mod b;\n"
        tree["cvm-core/src/b/p.rs"] = "use super::q::Q;\npub struct P;\n"
        tree["cvm-core/src/b/q.rs"] = "use super::Z;\npub struct Q;\n"
        tree["cvm-core/src/b/mod.rs"] = "pub mod p;\npub mod q;\npub struct Z;\n"
        self.assertEqual(run(tree), (0, "structure: ok\n"))

    def test_build_script_function_rule_and_warnings(self):
        long = "fn main() {\n" + "    let x = 1;\n" * 119 + "}\n"  # 121 lines
        tree = dict(CRATE, **{"cvm-core/src/a.rs": "", "cvm-core/src/b.rs": "", "build.rs": long})
        rc, out = run(tree)
        self.assertIn("build.rs:1: fn main is 121 lines", out)
        tree["build.rs"] = "fn main() {\n" + "    let x = 1;\n" * 110 + "}\n"  # 112 lines
        tree["tool/a.py"] = "x = 1\n" * 640
        rc, out = run(tree)
        self.assertEqual(rc, 0)
        self.assertIn("warning: build.rs:1: fn main is 112 lines (90 % of 120)", out)
        self.assertIn("warning: tool/a.py: 640 lines (90 % of 700)", out)

    def test_python_circle(self):
        tree = {"pkg/__init__.py": "", "pkg/x.py": "from .y import f\n", "pkg/y.py": "from . import x\n"}
        rc, out = run(tree)
        self.assertIn("import circle: pkg/x.py <-> pkg/y.py", out)

    def test_long_file_and_generated_exemption(self):
        body = "x = 1\n" * 701
        rc, out = run({"tool/a.py": body, "tool/b.py": "# generated by make.py\n" + body,
                       "tool/tests/c.py": body})
        self.assertIn("tool/a.py: 701 lines", out)
        self.assertNotIn("b.py", out)
        self.assertNotIn("c.py", out)

    def test_long_function_ignores_braces_in_strings(self):
        body = "\n".join(["    let s = \"}}}\";"] * 119)
        short = "fn short() {\n" + body + "\n}\n"  # 121 lines
        tree = dict(CRATE, **{"cvm-core/src/a.rs": short, "cvm-core/src/b.rs": "fn ok() {\n}\n"})
        rc, out = run(tree)
        self.assertIn("cvm-core/src/a.rs:1: fn short is 121 lines", out)
        tree["cvm-core/src/a.rs"] = "fn short() {\n" + "\n".join(["    let s = \"}}}\";"] * 118) + "\n}\n"
        self.assertEqual(run(tree)[0], 0)


if __name__ == "__main__":
    unittest.main()
