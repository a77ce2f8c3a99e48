"""The repository is self-contained in what it cites.

- No tracked file cites a document outside the repository: the normative texts are
  docs/algorithm.md, docs/design.md and docs/robot_arm.md.
- Every docs/ path cited anywhere (code, comments, --help texts, tests, README) is a
  tracked file or folder, and every "docs/<file>.md section N" names a section that file
  has.
- Every repository path the README and the docs name is tracked, the README's layout tree
  included, and every ``dopus_codegen.<module>[.<name>]`` (and ``dopus_lab.<module>...``)
  named in any tracked file resolves to a module or an attribute of one.
- The README is a newcomer's page (at most about 200 lines: what it is, the two commands,
  a minimal OCP file, the verbs, the map of the code, links); usage details live in
  docs/usage.md and results in docs/results.md, and its OCP file generates and runs.

Each scanner is first run on planted text with known findings, so that a scanner that finds
nothing cannot pass for a clean tree. The planted text is written with "@" inside every
citation, removed by ``planted()``, so that this file does not cite what it plants.
"""
from __future__ import annotations

import importlib
import re
import subprocess
import tomllib
from functools import lru_cache
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
BINARY_SUFFIXES = {".png", ".npz", ".pdf", ".so", ".a", ".o", ".pyc"}


@lru_cache(maxsize=None)
def tracked() -> tuple[str, ...]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return tuple(sorted(p for p in out.decode().split("\0") if p))


@lru_cache(maxsize=None)
def tracked_dirs() -> frozenset[str]:
    dirs = set()
    for p in tracked():
        parts = p.split("/")[:-1]
        for i in range(1, len(parts) + 1):
            dirs.add("/".join(parts[:i]))
    return frozenset(dirs)


def is_tracked(path: str) -> bool:
    path = path.rstrip("/")
    return path in tracked() or path in tracked_dirs()


def text_files() -> list[tuple[str, str]]:
    files = []
    for rel in tracked():
        if Path(rel).suffix in BINARY_SUFFIXES:
            continue
        data = (ROOT / rel).read_bytes()
        if b"\0" in data:
            continue
        files.append((rel, data.decode("utf-8")))
    assert len(files) > 50, "the scan found too few text files; is this a git checkout?"
    return files


def planted(text: str) -> str:
    return text.replace("@", "")


def line_of(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


# ------------------------------------------------------------------ outside the repository
_OUTSIDE = [
    (re.compile(r"\b(?:DESIGN|STYLE)\.md\b"), "a design or style note that is not in the repository"),
    (re.compile(r"\brobot-arm\.md\b"), "the reference-problem note (now docs/robot_arm.md)"),
    (re.compile(r"(?<![\w.~])/(?:work|home|root|mnt)/\w"), "an absolute path of one machine"),
]
_UP = re.compile(r"(?<![\w.])((?:\.\./)+)([\w.-]*)")


def outside_citations(rel: str, text: str) -> list[str]:
    """Findings ``path:line: what`` for citations of files outside the repository."""
    found = []
    for rx, what in _OUTSIDE:
        for m in rx.finditer(text):
            found.append(f"{rel}:{line_of(text, m.start())}: {m.group(0)!r}: {what}")
    base = (ROOT / rel).parent.resolve()
    for m in _UP.finditer(text):
        target = (base / m.group(1) / m.group(2)).resolve()
        if target != ROOT and ROOT not in target.parents:
            found.append(f"{rel}:{line_of(text, m.start())}: {m.group(0)!r}: a path out of the repository")
    return found


def test_outside_scanner_finds_planted_citations():
    text = planted("see DESIGN@.md section 8\n"
                   "style: STYLE@.md\n"
                   "numbers of robot-arm@.md\n"
                   "x = open('..@/..@/shared/notes.md')\n"
                   "cat /wo@rk/shared/x\n"
                   "fine: docs/design.md section 8, docs/robot_arm.md, ../runtime_c/dopus_qp.c\n")
    found = outside_citations("tests/planted.py", text)
    assert sorted(int(f.split(":")[1]) for f in found) == [1, 2, 3, 4, 5], found
    assert outside_citations("tests/planted.py", text.splitlines()[-1]) == []


def test_no_tracked_file_cites_outside_the_repository():
    found = [f for rel, text in text_files() for f in outside_citations(rel, text)]
    assert not found, "citations outside the repository:\n" + "\n".join(found)


# ------------------------------------------------------------------ docs/ paths and sections
_DOCS_PATH = re.compile(r"(?<![\w/.-])docs/[\w./-]*[\w/]")
_DOCS_SECTION = re.compile(r"(?<![\w/.-])(docs/[\w/-]+\.md)`?[\s#*]*\(?sections?\s+(\d+)(?:\s+to\s+(\d+))?")


@lru_cache(maxsize=None)
def sections_of(rel: str) -> frozenset[int]:
    text = (ROOT / rel).read_text(encoding="utf-8")
    return frozenset(int(n) for n in re.findall(r"^#{1,6}\s+(\d+)\.\s", text, flags=re.M))


def docs_findings(rel: str, text: str) -> list[str]:
    found = []
    for m in _DOCS_PATH.finditer(text):
        if not is_tracked(m.group(0)):
            found.append(f"{rel}:{line_of(text, m.start())}: {m.group(0)} is not a tracked path")
    for m in _DOCS_SECTION.finditer(text):
        doc = m.group(1)
        if not is_tracked(doc):
            continue  # reported above
        for n in filter(None, (m.group(2), m.group(3))):
            if int(n) not in sections_of(doc):
                found.append(f"{rel}:{line_of(text, m.start())}: {doc} has no section {n}")
    return found


def test_docs_scanner_finds_planted_errors():
    text = planted("docs/design.md section 8 and docs/algorithm.md sections 3 to 7\n"
                   "docs/robot_arm.md sec@tion 9\n"
                   "# docs/design.md\n# sec@tion 12\n"
                   "see do@cs/nothing.md\n"
                   "docs/algorithm.md` section 4, step 5; docs/figures/sil_kkt.png\n")
    found = docs_findings("tests/planted.py", text)
    assert sorted(found) == ["tests/planted.py:2: docs/robot_arm.md has no section 9",
                             "tests/planted.py:3: docs/design.md has no section 12",
                             planted("tests/planted.py:5: do@cs/nothing.md is not a tracked path")], found


def test_every_cited_docs_path_and_section_exists():
    found = [f for rel, text in text_files() for f in docs_findings(rel, text)]
    assert not found, "broken docs/ citations:\n" + "\n".join(found)
    # the normative texts are where the code says they are
    for doc in ("docs/algorithm.md", "docs/design.md", "docs/robot_arm.md"):
        assert is_tracked(doc), doc


# ------------------------------------------------------------------ paths in README and docs
def _markdown_files() -> list[tuple[str, str]]:
    return [(rel, text) for rel, text in text_files() if rel.endswith(".md")]


# Folders the tools write and never track: the benchmarks' results (.gitignore) and the
# separate environment of bench/setup_hpipm.sh (it writes its own .gitignore).
OUTPUT_DIRS = ("bench/results", "bench/.env")


def is_output(path: str) -> bool:
    return any(path.rstrip("/") == d or path.startswith(d + "/") for d in OUTPUT_DIRS)


def repo_path_findings(rel: str, text: str) -> list[str]:
    tops = sorted({p.split("/")[0] for p in tracked() if "/" in p}, key=len, reverse=True)
    rx = re.compile(r"(?<![\w/.-])(?:" + "|".join(re.escape(t) for t in tops) + r")/[\w./-]*")
    found = []
    for m in rx.finditer(text):
        path = m.group(0).rstrip(".")
        if not is_tracked(path) and not is_output(path):
            found.append(f"{rel}:{line_of(text, m.start())}: {path} is not a tracked path")
    return found


def test_output_dirs_are_written_not_tracked():
    assert not any(is_output(p) for p in tracked())
    assert "/bench/results/" in (ROOT / ".gitignore").read_text(encoding="utf-8").split()
    assert ".gitignore" in (ROOT / "bench" / "setup_hpipm.sh").read_text(encoding="utf-8")


def test_every_repository_path_in_the_markdown_exists():
    text = planted("see `dopus_codegen/refer@ence.py` and `runtime_c/dopus_qp.c`, tests/harness/.\n")
    assert repo_path_findings("README.md", text) == [
        "README.md:1: dopus_codegen/reference.py is not a tracked path"]
    found = [f for rel, text in _markdown_files() for f in repo_path_findings(rel, text)]
    assert not found, "paths that do not exist:\n" + "\n".join(found)


def layout_tree(readme: str) -> list[str]:
    """The paths of the README's layout block: names in the first column, nested by two
    spaces of indentation; description lines start further right and are skipped."""
    block = readme.split("\n## Layout\n", 1)[1].split("\n## ", 1)[0]
    paths, stack = [], []
    for line in block.splitlines():
        m = re.match(r"^( {4,})(\S+)", line)
        if not m or len(m.group(1)) >= 24:
            continue
        depth = (len(m.group(1)) - 4) // 2
        stack[depth:] = [m.group(2).rstrip("/")]
        full = "/".join(stack[:depth + 1]).split("/")
        # a name with a slash ("runtime/solver.py") also names its folders
        paths += ["/".join(full[:i]) for i in range(len(full) - m.group(2).rstrip("/").count("/"), len(full) + 1)]
    return paths


def test_readme_layout_names_exist():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    paths = layout_tree(readme)
    # the tree is parsed as a tree: nested names carry their parents
    for expect in ("dopus_codegen/problem/ocp.py", "dopus_codegen/runtime/solver.py",
                   "dopus_codegen/reference/offline.py", "dopus_codegen/studies", "dopus_lab",
                   "runtime_c", "templates", "tests/harness", "docs", "pyproject.toml"):
        assert expect in paths, (expect, paths)
    missing = [p for p in paths if not is_tracked(p)]
    assert not missing, f"README layout names that are not tracked: {missing}"
    # every sub-package of the package appears in the layout
    packages = {p.rsplit("/", 1)[0] for p in tracked()
                if p.startswith("dopus_codegen/") and p.endswith("/__init__.py")}
    assert packages <= set(paths), sorted(packages - set(paths))
    modules = {p for p in tracked() if re.fullmatch(r"dopus_codegen/\w+\.py", p)}
    assert modules <= set(paths), sorted(modules - set(paths))
    # every runtime_c unit (name without the prefix) and every template is described
    block = readme.split("\n## Layout\n", 1)[1].split("\n## ", 1)[0]
    units = {re.sub(r"^dopus_|\.[ch]$", "", Path(p).name) for p in tracked()
             if p.startswith("runtime_c/dopus_")}
    templates = {Path(p).name for p in tracked() if p.startswith("templates/") and p.endswith(".j2")}
    assert {"funcs", "main", "solver", "qp"} <= units and "sizes.h.j2" in templates
    undescribed = sorted(n for n in units | templates if not re.search(r"\b" + re.escape(n) + r"\b", block))
    assert not undescribed, f"README layout does not describe: {undescribed}"


# ------------------------------------------------------------------ module names
_MODULE = re.compile(r"(?<![\w.])(?:dopus_codegen|dopus_lab)(?:\.[A-Za-z_]\w*)+")


@lru_cache(maxsize=None)
def _package_dirs() -> dict[str, str]:
    data = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    return data["tool"]["setuptools"]["package-dir"]


@lru_cache(maxsize=None)
def resolves(name: str) -> bool:
    if name in _package_dirs():
        return (ROOT / _package_dirs()[name]).is_dir()
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_module_names_resolve():
    assert resolves("dopus_codegen.reference.qp.solve_qp_reference")
    assert resolves("dopus_codegen.Ocp") and resolves("dopus_codegen.runtime_c")
    assert not resolves(planted("dopus_codegen@.qpref.solve_qp_reference"))
    assert not resolves(planted("dopus_codegen@.reference.ReferenceDopus"))
    assert resolves("dopus_lab.bench.run_bench") and not resolves(planted("dopus_lab@.studies.bench"))
    found = []
    for rel, text in text_files():
        if rel.startswith("generated/"):
            continue
        for m in _MODULE.finditer(text):
            if not resolves(m.group(0)):
                found.append(f"{rel}:{line_of(text, m.start())}: {m.group(0)}")
    assert not found, "module names that do not resolve:\n" + "\n".join(found)


# ------------------------------------------------------------------ the README, a newcomer's page
def test_readme_is_a_newcomers_page():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 200
    for heading in ("## Two commands on a fresh machine", "## Install and the verbs", "## A minimal OCP file",
                    "## Layout", "## Further reading"):
        assert heading in readme, heading
    assert "make demo" in readme and "make test" in readme
    # the verbs the command line has are all in the README, and the details are in docs/
    from click.testing import CliRunner

    from dopus_codegen.cli import main

    verbs = set(main.commands)
    assert {"generate", "build", "converge", "sil", "campaign", "bench", "firmware-report"} <= verbs
    assert not [v for v in verbs if f"dopus-gen {v}" not in readme]
    assert CliRunner().invoke(main, ["--help"]).exit_code == 0
    for doc in ("docs/usage.md", "docs/results.md"):
        assert is_tracked(doc) and doc in readme


def test_readme_ocp_file_generates_and_runs(tmp_path):
    """The README's OCP file is a working one: it generates and builds, the handle opened on
    its folder runs its options (Gauss-Newton, M = 3), and its scenario runs in sil."""
    from click.testing import CliRunner

    from dopus_codegen import Solver
    from dopus_codegen.cli import main

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    code = readme.split("## A minimal OCP file", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "pendulum.py"
    path.write_text(code)
    res = CliRunner().invoke(main, ["generate", str(path), "-o", str(tmp_path / "pendulum")])
    assert res.exit_code == 0, res.output
    solver = Solver.load(tmp_path / "pendulum")
    assert (solver.settings.hessian, solver.settings.M) == ("gauss-newton", 3)
    res = CliRunner().invoke(main, ["sil", str(path), "--duration", "0.5", "--json", str(tmp_path / "sil.json")])
    assert res.exit_code == 0, res.output
