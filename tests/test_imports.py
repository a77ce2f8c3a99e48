"""The package's imports run one way (docs/design.md section 7).

Every import of every module of ``dopus_codegen`` (those inside functions included) is read
from the source: no two files import each other, directly or around a loop; no module
imports one of a higher layer of the pipeline; nothing in the product imports the lab
(``dopus_lab``), which imports the product. The scanner is first run on planted modules
with a known cycle and a known upward import.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: The layers of the product, bottom up; a module may import its own layer and those below.
LAYERS = (
    ("dopus_codegen/__init__.py", "dopus_codegen/paths.py", "dopus_codegen/cnames.py", "dopus_codegen/outputs.py",
     "dopus_codegen/interrupt.py"),
    ("dopus_codegen/vocabulary.py",),
    ("dopus_codegen/errors.py", "dopus_codegen/settings.py"),
    ("dopus_codegen/problem/",),
    ("dopus_codegen/reference/",),
    ("dopus_codegen/codegen/",),
    ("dopus_codegen/runtime/",),
    ("dopus_codegen/studies/",),
    ("dopus_codegen/verbs.py", "dopus_codegen/cli.py"),
)


def layer_of(rel: str) -> int:
    for i, members in enumerate(LAYERS):
        if any(rel == m or (m.endswith("/") and rel.startswith(m)) for m in members):
            return i
    raise AssertionError(f"{rel} is in no layer of LAYERS")


def module_file(name: str, files: set) -> str | None:
    """The file of ``a.b.c`` among ``files`` (a package's __init__.py, else a module)."""
    base = name.replace(".", "/")
    for cand in (f"{base}.py", f"{base}/__init__.py"):
        if cand in files:
            return cand
    return None


def imports_of(rel: str, text: str, files: set) -> set:
    """The files of ``files`` that ``rel`` imports (``from . import x`` names x's file)."""
    package = rel.rsplit("/", 1)[0].replace("/", ".")
    if rel.endswith("__init__.py"):
        package = rel[: -len("/__init__.py")].replace("/", ".")
    out = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            found = [module_file(a.name, files) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1])
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            # the modules named (from . import settings), else the module the names come from
            found = [module_file(f"{mod}.{a.name}", files) for a in node.names]
            if not any(found):
                found = [module_file(mod, files)]
        else:
            continue
        out |= {f for f in found if f is not None and f != rel}
    return out


def graph(sources: dict) -> dict:
    files = set(sources)
    return {rel: imports_of(rel, text, files) for rel, text in sources.items()}


def cycles(g: dict) -> list:
    """The strongly connected components of more than one file (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def upward(g: dict) -> list:
    return sorted(f"{a} -> {b}" for a, targets in g.items() for b in targets
                  if b.startswith("dopus_codegen/") and layer_of(b) > layer_of(a))


def sources_of(package: str) -> dict:
    return {str(p.relative_to(ROOT)): p.read_text(encoding="utf-8") for p in sorted((ROOT / package).rglob("*.py"))}


def test_the_scanner_finds_planted_cycles_and_upward_imports():
    planted = {
        "dopus_codegen/problem/a.py": "from .b import x\n",
        "dopus_codegen/problem/b.py": "def f():\n    from . import a\n",
        "dopus_codegen/settings.py": "from .studies import sil\n",
        "dopus_codegen/studies/sil.py": "from .. import settings\nimport numpy\n",
        "dopus_codegen/studies/__init__.py": "",
    }
    g = graph(planted)
    assert cycles(g) == [["dopus_codegen/problem/a.py", "dopus_codegen/problem/b.py"],
                         ["dopus_codegen/settings.py", "dopus_codegen/studies/sil.py"]]
    assert upward(g) == ["dopus_codegen/settings.py -> dopus_codegen/studies/sil.py"]


def test_no_cycle_and_no_upward_import_in_the_product():
    g = graph(sources_of("dopus_codegen"))
    assert len(g) > 30
    assert not cycles(g), cycles(g)
    assert not upward(g), upward(g)


def test_the_product_never_imports_the_lab():
    product, lab = sources_of("dopus_codegen"), sources_of("dopus_lab")
    g = graph({**product, **lab})
    into_lab = sorted(f"{a} -> {b}" for a in product for b in g[a] if b.startswith("dopus_lab/"))
    assert not into_lab, into_lab
    assert any(b.startswith("dopus_codegen/") for a in lab for b in g[a])     # the lab uses the product
    assert not cycles({a: {b for b in t if b.startswith("dopus_lab/")} for a, t in g.items() if a in lab})
