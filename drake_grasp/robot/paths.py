"""Where the project's files live, and the package map that resolves `package://drake_grasp`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # (imported where used: training and reading data need no Drake)
    from pydrake.multibody.parsing import PackageMap, Parser

PACKAGE_DIR = Path(__file__).resolve().parents[1]
REPO_ROOT = PACKAGE_DIR.parent
SDF_DIR = REPO_ROOT / "sdf"
MODELS_DIR = REPO_ROOT / "models"
OBJECT_SETS_DIR = SDF_DIR / "objects"
SCENARIOS_DIR = PACKAGE_DIR / "simulation" / "scenarios"


def model_path(name: str | Path) -> Path:
    """A weights file named as given (absolute, or relative to the working directory) or, when no such
    file is there, relative to the repository (`models/grasp_cnn_all.pt` from any working directory)."""
    path = Path(name)
    return path if path.is_absolute() or path.exists() else REPO_ROOT / path


def repo_name(path: str | Path) -> str:
    """`path` as the repository names it where it lies inside it (`models/x.pt`: the same record on every
    checkout), else as given."""
    resolved = Path(path)
    return str(resolved.relative_to(REPO_ROOT)) if resolved.is_absolute() and resolved.is_relative_to(
        REPO_ROOT) else str(path)


def cache_dir() -> Path:
    """Where prepared models (arms, decomposed meshes) go: DRAKE_GRASP_CACHE, else ~/.cache/drake_grasp."""
    return Path(os.environ.get("DRAKE_GRASP_CACHE", Path.home() / ".cache" / "drake_grasp"))


def make_parser(plant) -> Parser:
    """A Parser that resolves `package://drake_grasp/...` from `sdf/`, offline."""
    from pydrake.multibody.parsing import Parser

    parser = Parser(plant)
    add_package(parser.package_map())
    return parser


def add_package(package_map: PackageMap) -> None:
    if not package_map.Contains("drake_grasp"):
        package_map.AddPackageXml(str(SDF_DIR / "package.xml"))
