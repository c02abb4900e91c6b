"""The installed packages are the tree's: a package folder missing from pyproject.toml's list
works in a checkout (and an editable install) but is absent from ``pip install .``."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_folder_is_listed_in_pyproject() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    installed_as = {folder: name for name, folder in config["package-dir"].items()}
    found = set()
    for folder in installed_as:
        for init in sorted((ROOT / folder).rglob("__init__.py")):
            relative = init.parent.relative_to(ROOT / folder).parts
            found.add(".".join((installed_as[folder], *relative)))
    assert found == set(config["packages"])
