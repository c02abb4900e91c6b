"""No module of wavecore imports another module's private name (``from .x import _y``).

A private name is the defining module's own business: when another module needs it, it gets a
public name (no underscore) in its home module.  Private *modules* (``_kernels``, the compiled
loops) are the package's own and may be imported as modules.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "wavecore"


def _is_module(node: ast.ImportFrom, path: Path, name: str) -> bool:
    """Whether ``from <node's module> import <name>`` imports a submodule, not a name."""
    base = path.parent
    for _ in range(max(node.level - 1, 0)):
        base = base.parent
    if node.level == 0:
        parts = (node.module or "").split(".")
        if parts[0] != "wavecore":
            return False
        base = PACKAGE.joinpath(*parts[1:])
    elif node.module:
        base = base.joinpath(*node.module.split("."))
    return (base / f"{name}.py").exists() or (base / name / "__init__.py").exists()


def _private_imports() -> list[str]:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom):
                continue
            internal = node.level > 0 or (node.module or "").split(".")[0] == "wavecore"
            if not internal:
                continue
            for alias in node.names:
                name = alias.name
                private = name.startswith("_") and not name.startswith("__")
                if private and not _is_module(node, path, name):
                    where = path.relative_to(PACKAGE.parent)
                    module = "." * node.level + (node.module or "")
                    found.append(f"{where}:{node.lineno}: from {module} import {name}")
    return found


def test_no_private_name_is_imported_across_modules() -> None:
    found = _private_imports()
    assert not found, (
        "private names imported from other modules (give them a public name in their home "
        "module):\n" + "\n".join(found)
    )


def test_the_check_sees_a_private_import() -> None:
    """The walk above finds what it looks for (a fake module outside the package)."""
    source = "from .multilevel import _as_int\nfrom . import _kernels\n"
    tree = ast.parse(source)
    names = [
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
        if alias.name.startswith("_") and not _is_module(node, PACKAGE / "fake.py", alias.name)  # type: ignore[arg-type]
    ]
    assert names == ["_as_int"]
