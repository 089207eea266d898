"""The type stub the package ships (`splatray/_splatray.pyi`, what editors
and type checkers read) against the compiled module: every function and
method the module gives a signature has the stub's parameters, by name,
order and kind, and the same defaults where the stub writes one."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import splatray
from splatray import _splatray

STUB = Path(splatray.__file__).parent / "_splatray.pyi"


def stub_params(fn: ast.FunctionDef) -> list[tuple[str, str, str | None]]:
    """(name, kind, default as written) of a stub function's parameters,
    `self` left out."""
    a = fn.args
    out: list[tuple[str, str, str | None]] = []
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    for p, d in zip(positional, defaults):
        kind = "positional" if p in a.posonlyargs else "either"
        out.append((p.arg, kind, None if d is None else ast.unparse(d)))
    for p, d in zip(a.kwonlyargs, a.kw_defaults):
        out.append((p.arg, "keyword", None if d is None else ast.unparse(d)))
    return [p for p in out if p[0] != "self"]


def runtime_params(obj: object) -> list[tuple[str, str, str | None]] | None:
    """The same of a compiled function, from its text signature (None
    where the module gives none)."""
    if getattr(obj, "__text_signature__", None) is None:
        return None
    sig = inspect.signature(obj)  # type: ignore[arg-type]
    kinds = {
        inspect.Parameter.POSITIONAL_ONLY: "positional",
        inspect.Parameter.POSITIONAL_OR_KEYWORD: "either",
        inspect.Parameter.KEYWORD_ONLY: "keyword",
    }
    out = []
    for p in sig.parameters.values():
        if p.name == "self" or p.kind not in kinds:
            continue
        d = None if p.default is inspect.Parameter.empty else repr(p.default)
        out.append((p.name, kinds[p.kind], d))
    return out


def same_default(stub: str | None, runtime: str | None) -> bool:
    """A stub's `...` stands for any default; otherwise the two read the
    same value (`None`, `True`, `0.0`, `1024`, a string)."""
    if stub == "...":
        return runtime is not None
    if stub is None or runtime is None:
        return stub == runtime
    return ast.literal_eval(stub) == ast.literal_eval(runtime)


def test_the_stub_says_what_the_module_takes() -> None:
    tree = ast.parse(STUB.read_text())
    checked, wrong = 0, []
    for node in tree.body:
        pairs: list[tuple[str, ast.FunctionDef, object]] = []
        if isinstance(node, ast.FunctionDef) and hasattr(_splatray, node.name):
            pairs.append((node.name, node, getattr(_splatray, node.name)))
        elif isinstance(node, ast.ClassDef) and hasattr(_splatray, node.name):
            cls = getattr(_splatray, node.name)
            for fn in node.body:
                if isinstance(fn, ast.FunctionDef) and fn.name in vars(cls):
                    pairs.append((f"{node.name}.{fn.name}", fn, vars(cls)[fn.name]))
        for name, fn, obj in pairs:
            runtime = runtime_params(obj)
            if runtime is None:
                continue
            stub = stub_params(fn)
            checked += 1
            names = ([(n, k) for n, k, _ in stub], [(n, k) for n, k, _ in runtime])
            if names[0] != names[1] or not all(
                same_default(s[2], r[2]) for s, r in zip(stub, runtime)
            ):
                wrong.append(f"{name}: stub {stub}, module {runtime}")
    # 19 functions and methods with signatures today (`splat`,
    # `scan_check`, `Scene.render`, `SplatScene.cast_rays`, ...): none
    # may drop out of the comparison unseen.
    assert checked >= 19, checked
    assert not wrong, "\n".join(wrong)
