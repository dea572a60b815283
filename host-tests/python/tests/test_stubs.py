"""Every public function has a docstring and a type-hinted stub whose
parameters are the function's own."""

import ast
import inspect
from pathlib import Path

import cvm_dmap

STUBS = Path(cvm_dmap.__file__).with_name("__init__.pyi")


def stub_functions():
    tree = ast.parse(STUBS.read_text())
    return {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}


def test_every_public_name_has_a_docstring_and_a_stub():
    stubs = ast.parse(STUBS.read_text())
    names = {n.name for n in stubs.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    names |= {t.id for n in stubs.body if isinstance(n, (ast.AnnAssign,)) for t in [n.target]}
    for name in cvm_dmap.__all__:
        obj = getattr(cvm_dmap, name)
        assert name in names, f"{name} has no stub"
        if callable(obj):
            assert inspect.getdoc(obj), f"{name} has no docstring"


def test_stub_parameters_are_the_functions():
    for name, node in stub_functions().items():
        fn = getattr(cvm_dmap, name)
        real = [(p.name, p.kind) for p in inspect.signature(fn).parameters.values()]
        a = node.args
        stub = [(x.arg, inspect.Parameter.POSITIONAL_OR_KEYWORD) for x in a.args]
        stub += [(x.arg, inspect.Parameter.KEYWORD_ONLY) for x in a.kwonlyargs]
        if a.kwarg:
            stub.append((a.kwarg.arg, inspect.Parameter.VAR_KEYWORD))
        assert stub == real, name
        every = a.args + a.kwonlyargs + ([a.kwarg] if a.kwarg else [])
        assert all(x.annotation is not None for x in every) and node.returns is not None, name
