"""Versioned HDF5 model files (no pickle anywhere).

Layout (format ``simreal-model``, version 1)::

    /                       attrs: format, format_version, name, description, created, simreal_version
    /mesh/points            (n, 3) float64, object frame, metres
    /mesh/cells             (n_cells, k) int64, attr cell_type
    /mesh/surface           (n_tri, 3) int64, outward triangles
    /axes/<name>            grid values; attrs unit, kind, interpolation, description, order
    /fields/<name>/space    (n_modes, n_nodes, n_comp); attrs unit, components (JSON)
    /fields/<name>/params/<axis>   (n_modes, n_axis)
    /fields/<name>/error_vs_modes  (n_modes,)
    /load_points, /load_directions (optional)
    /meta                   attrs (JSON): material, boundary_conditions, loads, rigid_parameters, provenance

The file's first 512 bytes are an HDF5 user block holding the SHA-256 of the rest of the file
(``simreal-model sha256 <hex>``): a reader checks it before handing a byte to the HDF5 library, so a corrupt file
(a flipped bit, a zeroed block, a truncation) is one clear error instead of whatever libhdf5 makes of it -- on
zeroed metadata blocks that was a hang (``benchmarks/fuzz.py``). Files written before the user block load as
before. Every non-empty dataset also carries a Fletcher-32 checksum per chunk. Loading validates everything and
raises :class:`ModelFileError` with the reason; a reader may ask for some fields only and for the first
``n_modes`` modes only (read by slicing, not loaded then cut).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from simreal_nodes import __version__
from simreal_nodes.errors import ModelFileError
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.separated import Axis, SeparatedField

FORMAT = "simreal-model"
FORMAT_VERSION = 1
CELL_TYPES = {"tet4": 4, "hex8": 8, "tri3": 3, "quad4": 4}
MAX_EXPANSION = 100  # a dataset over 64 MiB may declare at most this times the bytes the file stores of it
USERBLOCK = 512
CHECKSUM_TAG = b"simreal-model sha256 "
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def save_model(model: ReducedModel, path: str | Path) -> str:
    """Write ``model``; returns its id (name@sha256 prefix of the file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f"{path.suffix}.{os.getpid()}.partial")  # two processes may build the same model
    with h5py.File(tmp, "w", userblock_size=USERBLOCK) as f:
        f.attrs.update(format=FORMAT, format_version=FORMAT_VERSION, name=model.name, description=model.description,
                       created=time.strftime("%Y-%m-%dT%H:%M:%S%z"), simreal_version=__version__)
        g = f.create_group("mesh")
        _dataset(g, "points", np.asarray(model.points, np.float64), compression="gzip")
        c = _dataset(g, "cells", np.asarray(model.cells, np.int64), compression="gzip")
        c.attrs["cell_type"] = model.cell_type
        _dataset(g, "surface", np.asarray(model.surface, np.int64).reshape(-1, 3), compression="gzip")
        ga = f.create_group("axes")
        for i, a in enumerate(model.axes):
            d = _dataset(ga, a.name, a.values)
            d.attrs.update(unit=a.unit, kind=a.kind, interpolation=a.interpolation, description=a.description, order=i)
        gf = f.create_group("fields")
        for name, fld in model.fields.items():
            h = gf.create_group(name)
            s = _dataset(h, "space", np.asarray(fld.space, np.float64), compression="gzip",
                         chunks=(1,) + fld.space.shape[1:])
            s.attrs.update(unit=fld.unit, components=json.dumps(list(fld.components)))
            hp = h.create_group("params")
            for a, p in zip(fld.axes, fld.params):
                _dataset(hp, a.name, np.asarray(p, np.float64))
            if fld.error_vs_modes is not None:
                _dataset(h, "error_vs_modes", np.asarray(fld.error_vs_modes, np.float64))
        if model.load_points is not None:
            _dataset(f, "load_points", np.asarray(model.load_points, np.int64))
        if model.load_directions is not None:
            _dataset(f, "load_directions", np.asarray(model.load_directions, np.float64))
        m = f.create_group("meta")
        for key in ("material", "boundary_conditions", "loads", "rigid_parameters", "provenance"):
            m.attrs[key] = json.dumps(getattr(model, key), default=_json_default)
    stamp_checksum(tmp)
    tmp.replace(path)  # never leave a half-written model under the real name
    model.path = str(path)
    model.model_id = model_id(path, model.name)
    return model.model_id


def _dataset(g: h5py.Group, name: str, data: Any, **kw: Any) -> h5py.Dataset:
    """A dataset with a Fletcher-32 checksum on each chunk (HDF5 checks it on every read): a flipped bit in stored
    numbers is a read error, not a silently wrong mode. HDF5 cannot chunk an empty array, so that one has none."""
    return g.create_dataset(name, data=data, fletcher32=bool(np.size(data)), **kw)


def _json_default(o: object) -> object:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def model_id(path: str | Path, name: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return f"{name}@{h.hexdigest()[:12]}"


def _sha256_after_userblock(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        fh.seek(USERBLOCK)
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def stamp_checksum(path: str | Path) -> None:
    """Write the SHA-256 of everything after the user block into the user block (a file written with one)."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(USERBLOCK + len(HDF5_SIGNATURE))
    if head[USERBLOCK:] != HDF5_SIGNATURE:
        raise ModelFileError(f"{path} has no {USERBLOCK}-byte user block to hold its checksum")
    tag = CHECKSUM_TAG + _sha256_after_userblock(path).encode() + b"\n"
    with open(path, "r+b") as fh:
        fh.write(tag.ljust(USERBLOCK, b"\0"))


def verify_checksum(path: str | Path) -> bool:
    """True when the file's user block holds a SHA-256 that matches the rest of it; False for a file written
    before the user block (HDF5 signature at byte 0); :class:`ModelFileError` for anything else -- a mismatch, a
    damaged user block, a file too short to hold one."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(USERBLOCK + len(HDF5_SIGNATURE))
    if head.startswith(HDF5_SIGNATURE):
        return False
    if not head.startswith(CHECKSUM_TAG):
        if head[USERBLOCK:] == HDF5_SIGNATURE:
            raise ModelFileError(f"{path}: its checksum block is damaged (corrupt file?)")
        raise ModelFileError(f"{path} is not a readable HDF5 file (truncated or corrupt?): no HDF5 signature")
    stored = head[len(CHECKSUM_TAG):len(CHECKSUM_TAG) + 64].decode("ascii", errors="replace")
    if stored != _sha256_after_userblock(path):
        raise ModelFileError(f"{path}: its contents do not match the SHA-256 stored when it was written "
                             "(corrupt, truncated or modified since; rebuild it)")
    return True


def _open(path: Path) -> h5py.File:
    if not path.exists():
        raise ModelFileError(f"model file not found: {path}")
    verify_checksum(path)
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise ModelFileError(f"{path} is not a readable HDF5 file (truncated or corrupt?): {e}") from None
    try:
        with _as_model_error(path):
            if f.attrs.get("format") != FORMAT:
                raise ModelFileError(f"{path} is not a simreal model file (format attribute: "
                                     f"{f.attrs.get('format')!r})")
            v = int(f.attrs.get("format_version", -1))
        if v > FORMAT_VERSION or v < 1:
            raise ModelFileError(f"{path} has model format version {v}; this simreal reads version {FORMAT_VERSION}")
    except ModelFileError:
        f.close()
        raise
    return f


@contextlib.contextmanager
def _as_model_error(path: Path) -> Iterator[None]:
    """What h5py, json or numpy raise on a file whose structure is damaged or not ours (a corrupt object header, a
    group where a dataset belongs, text where numbers belong) becomes a ModelFileError naming the file: the file is
    at fault, and the user gets one line instead of a traceback (found by ``benchmarks/fuzz.py``)."""
    try:
        yield
    except (OSError, KeyError, RuntimeError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as e:
        raise ModelFileError(f"{path}: not a valid model file ({type(e).__name__}: {e})") from None


def _get(f: h5py.Group, key: str, path: Path) -> h5py.Group | h5py.Dataset:
    if key not in f:
        raise ModelFileError(f"{path}: missing '{key}' (the file is incomplete or of another schema)")
    return f[key]


def _read(ds: h5py.Dataset, path: Path, sel: Any = ()) -> Any:
    """The dataset's value (array or scalar, as stored; h5py ships no types), ``sel`` an h5py selection.

    A dataset that declares far more than the file stores of it is refused before anything is allocated: a damaged
    or hostile header must not make a reader allocate (and HDF5 fill) gigabytes. Compression shrinks real modes a
    few times; :data:`MAX_EXPANSION` leaves room for far more."""
    if not isinstance(ds, h5py.Dataset):
        raise ModelFileError(f"{path}: '{ds.name}' is a group where a dataset belongs (corrupt file?)")
    declared = int(ds.size or 0) * ds.dtype.itemsize
    stored = ds.id.get_storage_size()
    if declared > 1 << 26 and declared > MAX_EXPANSION * stored:
        raise ModelFileError(f"{path}: '{ds.name}' declares shape {ds.shape} ({declared / 2**30:.1f} GiB) but the "
                             f"file stores {stored} bytes of it (corrupt file?)")
    try:
        return ds[sel] if sel != () else ds[()]
    except Exception as e:  # noqa: BLE001 - h5py raises OSError/KeyError/RuntimeError on corrupt data
        raise ModelFileError(f"{path}: cannot read '{ds.name}' (corrupt file?): {e}") from None


def _axes(f: h5py.File, path: Path) -> list[Axis]:
    axes = []
    g = _get(f, "axes", path)
    items = sorted(g.items(), key=lambda kv: int(kv[1].attrs.get("order", 0)))
    for name, d in items:
        try:
            axes.append(Axis(name, _read(d, path), str(d.attrs.get("unit", "")), str(d.attrs.get("kind", "continuous")),
                             str(d.attrs.get("interpolation", "cubic")), str(d.attrs.get("description", ""))))
        except ValueError as e:
            raise ModelFileError(f"{path}: axis '{name}': {e}") from None
    return axes


def read_header(path: str | Path) -> dict[str, Any]:
    """Name, parameters, fields and rigid parameters, without reading modes (cheap; for scene checks)."""
    path = Path(path)
    with _open(path) as f, _as_model_error(path):
        axes = _axes(f, path)
        fields = list(_get(f, "fields", path).keys())
        meta = _get(f, "meta", path)
        rigid = json.loads(meta.attrs.get("rigid_parameters", "[]"))
        n_modes = {k: int(_get(f, f"fields/{k}/space", path).shape[0]) for k in fields}
        return {"name": str(f.attrs.get("name", "")), "axes": [a.as_dict() for a in axes], "fields": fields,
                "n_modes": n_modes, "rigid_parameters": [r["name"] for r in rigid],
                "rigid": rigid}


def load_model(path: str | Path, fields: list[str] | tuple[str, ...] | None = None,
               n_modes: int | None = None, mesh: bool = True) -> ReducedModel:
    """Read and validate a model. ``fields``: only these (default all); ``n_modes``: only the first modes."""
    path = Path(path)
    with _open(path) as f, _as_model_error(path):
        name = str(f.attrs.get("name", path.stem))
        axes = _axes(f, path)
        pts = _read(_get(f, "mesh/points", path), path)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ModelFileError(f"{path}: mesh/points has shape {pts.shape}, expected (n, 3)")
        n_nodes = pts.shape[0]
        cells_ds = _get(f, "mesh/cells", path)
        cell_type = str(cells_ds.attrs.get("cell_type", ""))
        if cell_type not in CELL_TYPES:
            raise ModelFileError(f"{path}: unknown cell type '{cell_type}'")
        cells = _read(cells_ds, path) if mesh else np.zeros((0, CELL_TYPES[cell_type]), np.int64)
        surface = _read(_get(f, "mesh/surface", path), path)
        for what, arr in (("cells", cells), ("surface", surface)):
            if arr.size and (arr.min() < 0 or arr.max() >= n_nodes):
                raise ModelFileError(f"{path}: mesh/{what} refers to nodes outside 0..{n_nodes - 1}")
        gf = _get(f, "fields", path)
        wanted = list(gf.keys()) if fields is None else list(fields)
        out = {}
        for fname in wanted:
            if fname not in gf:
                raise ModelFileError(f"{path}: no field '{fname}' (the file has: {', '.join(gf.keys())})")
            h = gf[fname]
            s = _get(h, "space", path)
            m_all = s.shape[0]
            m = m_all if n_modes in (None, 0) else int(n_modes)
            if m > m_all:
                raise ModelFileError(f"{path}: field '{fname}' has {m_all} modes; {m} were requested")
            space = _read(s, path, np.s_[:m])
            if space.ndim != 3 or space.shape[1] != n_nodes:
                raise ModelFileError(f"{path}: field '{fname}' space modes have shape {space.shape}, "
                                     f"expected (modes, {n_nodes}, components)")
            params = []
            for a in axes:
                p = _read(_get(h, f"params/{a.name}", path), path, np.s_[:m])
                if p.shape != (m, len(a.values)):
                    raise ModelFileError(f"{path}: field '{fname}' modes of '{a.name}' have shape {p.shape}, "
                                         f"expected ({m}, {len(a.values)})")
                params.append(p)
            for arr in [space] + params:
                if not np.all(np.isfinite(arr)):
                    raise ModelFileError(f"{path}: field '{fname}' has NaN or inf in its modes")
            err = _read(h["error_vs_modes"], path, np.s_[:m]) if "error_vs_modes" in h else None
            out[fname] = SeparatedField(fname, space, params, axes, str(s.attrs.get("unit", "")),
                                        json.loads(s.attrs.get("components", "[]")), err)
        meta = _get(f, "meta", path)
        try:
            md = {k: json.loads(meta.attrs.get(k, "null")) for k in
                  ("material", "boundary_conditions", "loads", "rigid_parameters", "provenance")}
        except (TypeError, ValueError) as e:
            raise ModelFileError(f"{path}: metadata is not valid JSON: {e}") from None
        lp = _read(f["load_points"], path) if "load_points" in f else None
        ld = _read(f["load_directions"], path) if "load_directions" in f else None
        model = ReducedModel(name, pts, cells, cell_type, axes, out, surface, str(f.attrs.get("description", "")),
                             md["material"] or {}, md["boundary_conditions"] or [], md["loads"] or {}, lp, ld,
                             md["rigid_parameters"] or [], md["provenance"] or {}, path=str(path))
    model.model_id = model_id(path, name)
    return model
