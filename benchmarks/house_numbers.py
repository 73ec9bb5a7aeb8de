"""The house's numbers (issue 28): how far the code is from its own rules, counted by reading it.

    python -m benchmarks.house_numbers            # the summary
    python -m benchmarks.house_numbers --detail   # and every offender

Counts, over ``synth/``, ``app/``, ``jobs/``, ``worker/`` and ``benchmarks/`` (the static page too for
the limit variables):

- the longest module docstring (source lines) and every module whose docstring is above 30 lines;
- the most positional parameters of a function in ``synth/`` and every function above 16;
- the files that read a pixel/voxel/output limit's environment variable (``TEXSYNTH_MAX_*PIXELS``,
  ``*_VOXELS``, ``*_OUTPUT``) or that set ``OPENBLAS_NUM_THREADS``;
- the arrows back up: imports from a package of ``synth/`` into one on a higher floor (:data:`FLOORS`);
- the luma constants: modules that spell out ``0.299, 0.587, 0.114`` as numbers;
- the atomic writers: modules outside ``synth/io/atomic.py`` that call ``os.replace``/``os.rename``.
"""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TREES = ("synth", "app", "jobs", "worker", "benchmarks")

#: The floors of ``synth/``'s packages, lowest first: a module may import from its own floor's
#: package and from lower floors. ``api`` finds the methods by name (importlib), not by import.
FLOORS = {
    "errors": 0,
    "kernels": 0,
    "colour": 1,
    "params": 1,
    "threads": 1,
    "io": 2,
    "grid": 3,
    "analysis": 4,
    "evaluate": 5,
    "patch": 6,
    "pixel": 6,
    "api": 7,
    "methods": 8,
    "output": 8,
    "pipeline": 9,
    "cli": 10,
}

_LUMA = re.compile(r"0\.299\s*,\s*0\.587\s*,\s*0\.114")


def _files(trees: tuple[str, ...] = TREES) -> list[Path]:
    return sorted(
        p
        for t in trees
        for p in (ROOT / t).rglob("*.py")
        if "__pycache__" not in p.parts and p.resolve() != Path(__file__).resolve()
    )


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def docstring_lines() -> tuple[int, str, list[str]]:
    rows = []
    for path in _files():
        tree = ast.parse(path.read_text())
        first = tree.body[0] if tree.body else None
        if (
            isinstance(first, ast.Expr)
            and isinstance(first.value, ast.Constant)
            and isinstance(first.value.value, str)
        ):
            rows.append((first.end_lineno - first.lineno + 1, _rel(path)))
    rows.sort(reverse=True)
    return rows[0][0], rows[0][1], [f"{n:4d}  {p}" for n, p in rows if n > 30]


def positional_parameters() -> tuple[int, str, list[str]]:
    rows = []
    for path in _files(("synth",)):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = len(node.args.posonlyargs) + len(node.args.args)
                rows.append((n, f"{_rel(path)}:{node.lineno} {node.name}"))
    rows.sort(reverse=True)
    return rows[0][0], rows[0][1], [f"{n:4d}  {w}" for n, w in rows if n > 16]


#: The environment variables of the engine's and the service's pixel, voxel and output limits.
LIMIT_VARIABLES = (
    "TEXSYNTH_MAX_PIXELS",
    "TEXSYNTH_MAX_INPUT_PIXELS",
    "TEXSYNTH_MAX_VOXELS",
    "TEXSYNTH_MAX_OUTPUT",
    "TEXSYNTH_MAX_OUTPUT_PIXELS",
)


def limit_readers() -> tuple[list[str], list[str]]:
    """Files that read a limit variable (a string constant naming it in code, or a settings field
    that ``from_env`` reads as ``TEXSYNTH_<FIELD>``), and files that set ``OPENBLAS_NUM_THREADS``."""
    fields = {v.removeprefix("TEXSYNTH_").lower() for v in LIMIT_VARIABLES}
    readers, blas = [], []
    for path in _files():
        tree = ast.parse(path.read_text())
        reads = sets = False
        # A settings class whose from_env reads TEXSYNTH_<FIELD> itself (not through limit_from_env).
        generic = "from_env" in {
            n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)
        } and not any(
            isinstance(n, ast.Call) and getattr(n.func, "id", "") == "limit_from_env" for n in ast.walk(tree)
        )
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and node.value in LIMIT_VARIABLES:
                reads = True
            if generic and isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                reads = reads or node.target.id in fields
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                args = [a.value if isinstance(a, ast.Constant) else getattr(a, "id", None) for a in node.args]
                args = ["OPENBLAS_NUM_THREADS" if a == "BLAS_THREADS" else a for a in args]
                sets = sets or (node.func.attr in ("setdefault", "putenv") and "OPENBLAS_NUM_THREADS" in args)
            if isinstance(node, ast.Assign):
                for target in node.targets:
                    if isinstance(target, ast.Subscript) and isinstance(target.slice, ast.Constant):
                        sets = sets or target.slice.value == "OPENBLAS_NUM_THREADS"
        if reads:
            readers.append(_rel(path))
        if sets:
            blas.append(_rel(path))
    return readers, blas


def _code_only(text: str) -> str:
    """The source's string constants that are not docstrings, and its names (comments dropped)."""
    tree = ast.parse(text)
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                docs.add(id(first.value))
    parts = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            parts.append(repr(node.value))
        elif isinstance(node, ast.JoinedStr):
            parts.append(ast.unparse(node))
    return "\n".join(parts)


def arrows_back_up() -> list[str]:
    found = []
    for path in _files(("synth",)):
        parts = path.relative_to(ROOT / "synth").with_suffix("").parts
        if parts[0] == "__init__":
            continue
        here = parts[0]
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for name in names:
                bits = name.removeprefix("texsynth.").split(".")
                if bits[0] != "synth" or len(bits) < 2 or bits[1] == here:
                    continue
                if FLOORS.get(bits[1], -1) > FLOORS.get(here, 99):
                    found.append(
                        f"{_rel(path)}:{node.lineno} ({here}, floor {FLOORS[here]}) imports {name} "
                        f"(floor {FLOORS[bits[1]]})"
                    )
    return found


def luma_constants() -> list[str]:
    return [_rel(p) for p in _files() if _LUMA.search(_code_only(p.read_text())) or _luma_array(p)]


def _luma_array(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.List | ast.Tuple) and len(node.elts) == 3:
            vals = [e.value for e in node.elts if isinstance(e, ast.Constant)]
            if vals == [0.299, 0.587, 0.114]:
                return True
    return False


def atomic_writers() -> list[str]:
    found = []
    for path in _files():
        if _rel(path) == "synth/io/atomic.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr in ("replace", "rename")
                and isinstance(node.func.value, ast.Name)
                and node.func.value.id == "os"
            ):
                found.append(f"{_rel(path)}:{node.lineno}")
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--detail", action="store_true", help="list every offender")
    detail = parser.parse_args().detail
    n_doc, where_doc, long_docs = docstring_lines()
    n_pos, where_pos, many = positional_parameters()
    readers, blas = limit_readers()
    arrows = arrows_back_up()
    luma = luma_constants()
    writers = atomic_writers()
    print(f"longest module docstring: {n_doc} lines ({where_doc}); above 30 lines: {len(long_docs)}")
    print(f"most positional parameters (synth/): {n_pos} ({where_pos}); above 16: {len(many)}")
    print(f"files that read limit variables: {len(readers)} ({', '.join(readers)})")
    print(f"files that set OPENBLAS_NUM_THREADS: {len(blas)} ({', '.join(blas)})")
    print(f"arrows back up: {len(arrows)}")
    print(
        f"luma constants (besides texsynth.synth.colour): {len([f for f in luma if f != 'synth/colour.py'])}"
        f" ({', '.join(luma)})"
    )
    print(f"atomic writers besides texsynth.synth.io.atomic: {len(writers)} ({', '.join(writers)})")
    solid = ("solid_", "pixel/solid.py")
    mine_doc = [r for r in long_docs if not any(k in r for k in solid)]
    mine_pos = [r for r in many if not any(k in r for k in solid)]
    longest = f" (longest: {mine_doc[0].strip()})" if mine_doc else ""
    print(
        f"outside the solid machinery (solid_*.py, pixel/solid.py): docstrings above 30 lines: "
        f"{len(mine_doc)}{longest}; functions above 16 positional: {len(mine_pos)}"
    )
    if detail:
        for title, rows in (
            ("module docstrings", long_docs),
            ("positional parameters", many),
            ("arrows back up", arrows),
        ):
            print(f"\n{title}:")
            for row in rows:
                print(f"  {row}")


if __name__ == "__main__":
    main()
