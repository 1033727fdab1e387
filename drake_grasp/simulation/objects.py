"""Object sets: the shipped `primitives` and `novel` sets, or any folder of SDF/URDF/OBJ files."""

from __future__ import annotations

import dataclasses as dc
import functools
import hashlib
import logging
import os
from pathlib import Path

import numpy as np

from drake_grasp.datasets.shards import run_jobs
from drake_grasp.robot.model_files import prepare_object_model, scaled_object_file
from drake_grasp.robot.object_files import MAX_OBJECT_SIZE, MESH_UNITS
from drake_grasp.robot.paths import OBJECT_SETS_DIR, SDF_DIR, cache_dir
from drake_grasp.robot.plant import ObjectModel

_log = logging.getLogger(__name__)

MODEL_SUFFIXES = (".sdf", ".urdf")
MESH_SUFFIXES = (".obj",)


def object_set_names() -> list[str]:
    return sorted(p.name for p in OBJECT_SETS_DIR.iterdir() if p.is_dir())


def load_object_set(name_or_path: str, units: str = "m") -> list[ObjectModel]:
    """The models of a shipped set (by name) or of a folder (by path).

    A folder may hold SDF/URDF files (one free body each), model folders as Gazebo keeps them
    (`NAME/model.sdf`, or a folder with one SDF/URDF file: the object is named after the folder) and
    bare OBJ meshes, which are wrapped as compliant objects of 0.1 kg (concave ones as their CoACD
    pieces). Model files are made ready for Drake (`robot.model_files.prepare_object_model`: meshes
    named by `model://` or `package://` paths, in STL or DAE or without normals; impossible inertias);
    a folder's lengths are read in `units` ("m" or "mm"), and an object too large for a table top is
    refused. Raises ValueError when the set is unknown or holds nothing usable.
    """
    shipped = OBJECT_SETS_DIR / name_or_path
    if "/" not in name_or_path and shipped.is_dir():
        return [
            ObjectModel(p.stem, f"package://drake_grasp/objects/{name_or_path}/{p.name}")
            for p in sorted(shipped.glob("*.sdf"))
        ]
    folder = Path(name_or_path).expanduser()
    if not folder.is_dir():
        raise ValueError(
            f"unknown object set '{name_or_path}': not one of {', '.join(object_set_names())} "
            "and not a folder"
        )
    entries = sorted(folder.iterdir())
    found = [(p.stem, p) for p in entries if p.is_file() and p.suffix.lower() in MODEL_SUFFIXES]
    found += [(sub.name, model) for sub in entries
              if sub.is_dir() and (model := model_file_of(sub)) is not None]
    # An OBJ that a model file references is not an object of its own.
    referenced = " ".join(path.read_text(errors="ignore") for _, path in found)
    prepared = [(name, prepare_object_model(path, folder, units)) for name, path in found]
    models = [ObjectModel(name, ready.path.resolve().as_uri(), ready.notes) for name, ready in prepared]
    meshes = [p for p in entries if p.suffix.lower() in MESH_SUFFIXES and p.name not in referenced]
    notes = (f"lengths read in {units} (scaled by {MESH_UNITS[units]:g})",) if units != "m" else ()
    models += [ObjectModel(p.stem, sdf.as_uri(), notes)
               for p, sdf in zip(meshes, wrap_objs(meshes, units=units), strict=True)]
    if not models:
        raise ValueError(f"object set folder {folder} holds no usable .sdf, .urdf or .obj file")
    return models


def object_file(model: ObjectModel) -> Path:
    """The model file of an object (a shipped set's `package://drake_grasp/...` or a `file://` URL)."""
    if model.url.startswith("package://drake_grasp/"):
        return SDF_DIR / model.url.removeprefix("package://drake_grasp/")
    if model.url.startswith("file://"):
        return Path(model.url.removeprefix("file://"))
    return Path(model.url)


def scaled_object(model: ObjectModel, scale: float) -> ObjectModel:
    """The object with every length scaled by `scale` (a cached copy of its model file; mass kept)."""
    original = object_file(model)
    path = scaled_object_file(original, scale)
    return model if path == original else dc.replace(model, url=path.resolve().as_uri())


def model_file_of(folder: Path) -> Path | None:
    """The model of a model folder: its `model.sdf` (Gazebo's layout), else its one SDF or URDF file."""
    if (folder / "model.sdf").is_file():
        return folder / "model.sdf"
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MODEL_SUFFIXES]
    return files[0] if len(files) == 1 else None


WRAP_VERSION = b"hulls of at most 48 vertices"  # (a cached wrap of an older version is remade)


def _wrap_place(mesh: Path, units: str = "m") -> tuple[Path, Path]:
    """(the cache folder, the SDF) of a bare OBJ's wrap, by the mesh's content and units."""
    extra = b"" if units == "m" else units.encode()
    digest = hashlib.sha256(mesh.read_bytes() + WRAP_VERSION + extra).hexdigest()[:16]
    out_dir = cache_dir() / "objects" / f"{mesh.stem}-{digest}"
    return out_dir, out_dir / f"{mesh.stem}.sdf"


def wrapped_obj(mesh: Path, units: str = "m") -> Path:
    """The SDF of a bare OBJ (`wrap_obj`), made once per mesh content and cached."""
    out_dir, sdf = _wrap_place(mesh, units)
    return sdf if sdf.exists() else wrap_obj(mesh, out_dir, units=units)


def wrap_objs(meshes: list[Path], workers: int | None = None, units: str = "m") -> list[Path]:
    """The SDFs of bare OBJs (`wrapped_obj`); the ones not cached yet are decomposed on every core,
    with a progress bar and an estimate (the first use of a folder of meshes takes minutes)."""
    todo = [m for m in meshes if not _wrap_place(m, units)[1].exists()]
    if todo:
        from tqdm import tqdm

        workers = min(workers or os.cpu_count() or 1, len(todo))
        _log.info(f"decomposing {len(todo)} new mesh(es) into convex pieces on {workers} core(s), once "
                  f"(cached in {cache_dir() / 'objects'})")
        with tqdm(total=len(todo), unit="mesh", dynamic_ncols=True) as bar:
            wrap = functools.partial(wrapped_obj, units=units)
            if workers == 1:
                for mesh in todo:
                    wrap(mesh)
                    bar.update(1)
            else:
                for _ in run_jobs(wrap, todo, workers=workers):
                    bar.update(1)
    return [wrapped_obj(m, units) for m in meshes]


def wrap_obj(mesh: Path, out_dir: Path, mass: float = 0.1, units: str = "m") -> Path:
    """Writes an SDF that makes a bare OBJ a compliant object of `mass`: its convex hull when it nearly
    fills it, else the convex pieces of its CoACD decomposition (so that a mug keeps its opening). Its
    lengths are read in `units`; ValueError for a mesh too large to be a table-top object."""
    import trimesh

    from drake_grasp.robot.contact_model import OBJECT_CONTACT
    from drake_grasp.simulation.object_generation import (
        GeneratedObject,
        Piece,
        convex_pieces,
        mass_properties,
        write_sdf,
    )

    try:
        loaded = trimesh.load(mesh, force="mesh", process=True)
    except Exception as e:  # trimesh raises many types for a file it cannot read
        raise ValueError(f"mesh {mesh} could not be read: {str(e).splitlines()[0]}") from None
    if len(loaded.vertices) < 4 or not np.isfinite(loaded.vertices).all():
        raise ValueError(f"mesh {mesh} has no usable vertices")
    loaded.apply_scale(MESH_UNITS[units])
    if (size := float(np.max(loaded.extents))) > MAX_OBJECT_SIZE:
        hint = "; its lengths look like millimetres: --object-units mm reads them so" if units == "m" else ""
        raise ValueError(f"mesh {mesh} is {size:.3g} m across, too large for a table-top object{hint}")
    pieces = [Piece("mesh", mesh=p) for p in convex_pieces(loaded)]
    _, p_OScm, I_SScm_O = mass_properties(pieces, mass=mass)
    obj = GeneratedObject(mesh.stem, "mesh", pieces, mass, OBJECT_CONTACT.friction, (0.7, 0.7, 0.7, 1.0),
                          p_OScm, I_SScm_O)
    return write_sdf(obj, out_dir)
