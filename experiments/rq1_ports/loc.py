"""``python experiments/rq1_ports/loc.py``: lines of code of the algorithm ports beside paper Table 1 (RQ1).

Counting convention (cloc-style, as the reference reconciliation of Table 1 does):

- a line counts when it holds code: blank lines and comment-only lines do not; a line with code and a
  trailing comment does; lines holding only brackets do;
- Python: ``#`` comments and docstrings are comments — a docstring being any statement that is only
  a string literal (module, class and function docstrings, and bare strings elsewhere), as cloc does.
  Every line of a multi-line string that is part of an expression is code. Found with ``tokenize``
  and ``ast``, so a ``#`` inside a string is never mistaken for a comment;
- YAML: a line counts when a YAML token (key, value, bracket, ...) lies on it, so ``#`` comments
  never count and every line of a block scalar does. Found with the YAML scanner.

What an algorithm's *core logic* is: the modules named by its ``conf/algo`` YAML (``drone`` and
``ground`` ``_target_``), every module under ``algorithms/`` they import (followed transitively),
plus the YAML itself and any algo YAML it extends through ``defaults``. Algorithms sharing their
modules (e.g. variants that only change parameters) form one row whose YAML files are all counted.
This matches how the paper's ported numbers were obtained: algorithm sources + the package's config.

*Boilerplate* is what the framework needs besides the core logic — build files, package manifests,
launch files, registration code. A SwarmBox algorithm needs none (a module and one YAML file are the
whole plug-in), so the ported boilerplate is 0 lines; the paper's C++ port needed 44
(``CMakeLists.txt`` + ``package.xml``).
"""

from __future__ import annotations

import argparse
import ast
import functools
import io
import sys
import tokenize
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2] / "swarmbox"   # the package: holds algorithms/ and conf/
PACKAGE = "swarmbox.algorithms"

#: Paper Table 1: (legacy boilerplate, legacy core, C++ port boilerplate, C++ port core) per
#: algorithm, and the name of our port's algo config.
PAPER_TABLE_1: dict[str, tuple[int, int, int, int, str]] = {
    "Adaptive Swarm": (729, 673, 44, 540, "adaptive"),
    "Optimized Flocking": (6110, 1582, 44, 291, "flocking"),
    "Socratic Swarm": (8134, 1244, 44, 284, "socratic"),
}
#: Lines of build/manifest/launch/registration code a SwarmBox algorithm needs: none.
BOILERPLATE_LOC = 0

_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_NOT_CODE = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
             tokenize.ENDMARKER, tokenize.ENCODING}


def count_python(source: str) -> int:
    """Code lines of a Python source (see the module docstring for the convention)."""
    docstrings = [((n.lineno, n.col_offset), (n.end_lineno, n.end_col_offset))
                  for n in ast.walk(ast.parse(source))
                  if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)
                  and isinstance(n.value.value, str)]
    lines: set[int] = set()
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type in _NOT_CODE:
            continue
        if tok.type == tokenize.STRING and any(a <= tok.start and tok.end <= b for a, b in docstrings):
            continue
        lines.update(range(tok.start[0], tok.end[0] + 1))
    return len(lines)


def count_yaml(text: str) -> int:
    """Code lines of a YAML document (see the module docstring for the convention)."""
    lines: set[int] = set()
    for tok in yaml.scan(text):
        start, end = tok.start_mark, tok.end_mark
        if start.index == end.index:
            continue   # zero-width tokens (block starts and ends, implicit keys)
        last = end.line - 1 if end.column == 0 and end.line > start.line else end.line
        lines.update(range(start.line, last + 1))
    return len(lines)


def count_file(path: Path) -> int:
    text = path.read_text()
    return count_python(text) if path.suffix == ".py" else count_yaml(text)


@dataclass(frozen=True)
class AlgorithmLoc:
    """One algorithm's configs, files and their code lines."""

    name: str
    configs: tuple[str, ...]
    modules: tuple[tuple[Path, int], ...]   # (file, code lines)
    yamls: tuple[tuple[Path, int], ...]

    @classmethod
    def of(cls, name: str, configs: Sequence[str], modules: Iterable[Path],
           yamls: Iterable[Path]) -> AlgorithmLoc:
        return cls(name, tuple(configs), tuple((p, count_file(p)) for p in modules),
                   tuple((p, count_file(p)) for p in yamls))

    @property
    def module_loc(self) -> int:
        return sum(n for _, n in self.modules)

    @property
    def yaml_loc(self) -> int:
        return sum(n for _, n in self.yamls)

    @property
    def core_loc(self) -> int:
        return self.module_loc + self.yaml_loc


def _module_file(root: Path, dotted: str) -> Path | None:
    if not dotted.startswith(PACKAGE + "."):
        return None
    path = (root / "algorithms").joinpath(*dotted[len(PACKAGE) + 1:].split(".")).with_suffix(".py")
    return path if path.is_file() else None


@functools.cache
def _direct_imports(root: Path, path: Path) -> tuple[Path, ...]:
    """Modules of the ``algorithms`` package that ``path`` imports itself."""
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1 and path.parent == root / "algorithms":
            names += [f"{PACKAGE}.{node.module}"] if node.module else [f"{PACKAGE}.{a.name}"
                                                                        for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names += [node.module] if node.module.startswith(PACKAGE + ".") else []
        elif isinstance(node, ast.Import):
            names += [a.name for a in node.names if a.name.startswith(PACKAGE + ".")]
    return tuple(f for f in (_module_file(root, n) for n in names) if f is not None)


def _imported_modules(root: Path, path: Path) -> set[Path]:
    """``path`` and the modules of the ``algorithms`` package it imports, transitively."""
    seen, todo = set(), [path]
    while todo:
        cur = todo.pop()
        if cur not in seen:
            seen.add(cur)
            todo += _direct_imports(root, cur)
    return seen


@functools.cache
def _load_yaml(path: Path) -> dict:
    raw = yaml.load(path.read_text(), Loader=_LOADER)
    return raw if isinstance(raw, dict) else {}


def _config_files(conf: Path, name: str) -> list[Path]:
    """The algo YAML ``name`` and the YAMLs it extends through ``defaults``, base first (a ``/base``
    entry is a file at the config root, e.g. ``conf/delivery_base.yaml``)."""
    path = conf / f"{name}.yaml" if not name.startswith("/") else conf.parent / f"{name[1:]}.yaml"
    raw = _load_yaml(path)
    files: list[Path] = []
    for entry in raw.get("defaults") or []:
        ref = entry.split("@")[0] if isinstance(entry, str) else ""
        base = conf.parent / f"{ref[1:]}.yaml" if ref.startswith("/") else conf / f"{ref}.yaml"
        if ref and ref != "_self_" and base.is_file():
            files += [f for f in _config_files(conf, ref) if f not in files]
    return [*files, path]


def _targets(files: Sequence[Path]) -> list[str]:
    """Modules named by the ``drone`` / ``ground`` ``_target_`` of the merged config files."""
    merged: dict[str, str] = {}
    for f in files:
        raw = _load_yaml(f)
        for role in ("drone", "ground"):
            node = raw.get(role)
            if isinstance(node, dict) and node.get("_target_"):
                merged[role] = str(node["_target_"]).rsplit(".", 1)[0]
    return [merged[r] for r in ("drone", "ground") if r in merged]


def algorithms(root: Path = ROOT) -> list[AlgorithmLoc]:
    """Every algorithm of ``conf/algo`` grouped by its modules, plus modules no config names."""
    conf = root / "conf" / "algo"
    groups: dict[tuple[Path, ...], tuple[list[str], list[Path]]] = {}
    for cfg in sorted(conf.glob("*.yaml")):
        files = _config_files(conf, cfg.stem)
        modules: set[Path] = set()
        for target in _targets(files):
            found = _module_file(root, target)
            if found is not None:
                modules |= _imported_modules(root, found)
        if not modules:
            continue   # a base config used only through defaults, or a non-algorithms target
        key = tuple(sorted(modules))
        names, yamls = groups.setdefault(key, ([], []))
        names.append(cfg.stem)
        yamls += [f for f in files if f not in yamls]
    rows = [AlgorithmLoc.of(_group_name(key, names), names, key, yamls)
            for key, (names, yamls) in groups.items()]
    named = {m for key in groups for m in key}
    for orphan in sorted((root / "algorithms").glob("*.py")):
        if orphan not in named and orphan.name != "__init__.py":
            rows.append(AlgorithmLoc.of(orphan.stem, (), (orphan,), ()))
    return sorted(rows, key=lambda r: r.name)


def _group_name(modules: Iterable[Path], configs: list[str]) -> str:
    stems = sorted(p.stem for p in modules)
    return configs[0] if len(configs) == 1 else min(stems, key=len)


def _pct(old: int, new: int) -> str:
    return f"{100.0 * (old - new) / old:.1f}%" if old else "-"


def table_1(rows: Sequence[AlgorithmLoc]) -> str:
    """Paper Table 1 (legacy / the paper's C++ port) beside this port, as text."""
    by_config = {c: r for r in rows for c in r.configs}
    trio = f"{'legacy':>8}{'C++ port':>10}{'ours':>6}"
    out = [f"{'':<20}{'boilerplate (1)':^24}   {'core logic (2)':^24}   {'total (1+2)':^24}   "
           f"{'ours vs legacy':^24}",
           f"{'algorithm':<20}{trio}   {trio}   {trio}   {'(1)':>8}{'(2)':>8}{'(1+2)':>8}"]
    for name, (lb, lc, pb, pc, cfg) in PAPER_TABLE_1.items():
        ours = by_config.get(cfg)
        oc, ob = (ours.core_loc if ours else 0), BOILERPLATE_LOC
        cells = [(lb, pb, ob), (lc, pc, oc), (lb + lc, pb + pc, ob + oc)]
        groups = "   ".join(f"{a:>8}{b:>10}{c:>6}" for a, b, c in cells)
        cuts = "".join(f"{_pct(a, c):>8}" for a, _, c in cells)
        out.append(f"{name:<20}{groups}   {cuts}")
    return "\n".join(out)


def breakdown(rows: Sequence[AlgorithmLoc], root: Path = ROOT) -> str:
    """Every algorithm: its counts, then its files with their own counts, as text."""
    out = [f"{'algorithm':<16}{'modules':>9}{'YAML':>7}{'core':>7}{'boilerplate':>13}  configs"]
    for r in rows:
        configs = ", ".join(r.configs) or "(no conf/algo config names it)"
        out.append(f"{r.name:<16}{r.module_loc:>9}{r.yaml_loc:>7}{r.core_loc:>7}{BOILERPLATE_LOC:>13}"
                   f"  {configs}")
        out += [f"  {n:>5}  {p.relative_to(root)}" for p, n in (*r.modules, *r.yamls)]
    return "\n".join(out)


def report(root: Path = ROOT) -> str:
    rows = algorithms(root)
    lines = [
        "RQ1: lines of code (cloc-style: non-blank, non-comment lines; docstrings are comments).",
        "Core logic = algorithm modules + their algo YAML; boilerplate = build/manifest/launch/",
        "registration files the framework needs besides them (none in SwarmBox).",
        "",
        "Paper Table 1 (legacy implementation and the paper's C++/ROS 2 port) vs this Python port",
        table_1(rows),
        "",
        "Every algorithm under algorithms/",
        breakdown(rows, root),
    ]
    return "\n".join(line.rstrip() for line in "\n".join(lines).splitlines())


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python experiments/rq1_ports/loc.py",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=ROOT,
                        help="the package directory holding algorithms/ and conf/ (default: this checkout's)")
    args = parser.parse_args(argv)
    print(report(args.root.resolve()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
