"""Data sources: which clouds a run uses, and how each one is made.

Four sources, chosen by `data.source` in params.yaml (`DataConfig`):
* `procedural`: the embedded shapes of `refinenet.data.shapes`, sampled and noised at the paper's levels;
* `meshes`: a folder `PATH/<split>/<category>/*.{off,obj,ply}`, sampled the same way;
* `pcpnet`: a PCPNet-format folder (`.xyz`, `.normals`, optional `.pidx`) with list files, used as given;
* `points`: a folder `PATH/<split>/<category>/*.{xyz,ply,pcd,npy}` of clouds with normals, used as given.
Splits are `train` and `test`; categories are those of the paper's tables. `data.train_meshes` adds the train split
of a folder of meshes to any source's training clouds.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from refinenet.config import DataConfig, NoiseConfig
from refinenet.data import shapes
from refinenet.data.io import POINT_FILE_SUFFIXES, Cloud, check_array, read_cloud
from refinenet.data.meshes import MESH_SUFFIXES, read_mesh, sample_mesh
from refinenet.data.noise import add_gaussian_noise, bbox_diagonal, derive_seed
from refinenet.errors import InputError, ParamsError, first_line

SPLITS = ("train", "test")
CATEGORY_ALIASES = {
    "sharp": shapes.SHARP, "smooth": shapes.SMOOTH, "rich": shapes.RICH, "big": shapes.BIG_NOISE,
    **{category.lower(): category for category in shapes.CATEGORIES},
}
_SAFE = re.compile(r"[^A-Za-z0-9_.+-]")


@dataclass(frozen=True)
class CloudSpec:
    """One cloud of a run. `origin` is a procedural shape name or a file; `noise` is None for given clouds."""

    split: str
    category: str
    name: str
    origin: str
    noise: float | None

    @property
    def key(self) -> str:
        """The cloud's path below a results folder: `<split>/<category>/<name>`."""
        return f"{self.split}/{self.category}/{self.name}"


def cloud_key(path: str | Path, cloud: Cloud) -> str:
    """The key of a cloud record (`CloudSpec.key`, from its metadata), or the file name of any other cloud: the
    name that per-cloud seeds are derived from."""
    meta = cloud.meta
    if {"split", "category", "name"} <= set(meta):
        return CloudSpec(meta["split"], meta["category"], meta["name"], meta.get("origin", ""), None).key
    return Path(path).name


def _category(folder: str) -> str:
    return CATEGORY_ALIASES.get(folder.lower(), _SAFE.sub("_", folder))


def _noisy_specs(split: str, category: str, stem: str, origin: str, levels: list[float]) -> list[CloudSpec]:
    return [CloudSpec(split, category, f"{stem}_n{level:.2f}", origin, float(level)) for level in levels]


def list_clouds(data: DataConfig, noise: NoiseConfig) -> list[CloudSpec]:
    """Every cloud a run uses, in a deterministic order, from the `data` and `noise` params blocks."""
    source = data.source
    if source == "procedural":
        specs = _procedural(data, noise)
    elif source == "meshes":
        specs = _folder(data, noise, MESH_SUFFIXES, synthesise=True)
    elif source == "points":
        specs = _folder(data, noise, POINT_FILE_SUFFIXES, synthesise=False)
    elif source == "pcpnet":
        specs = _pcpnet(data)
    else:
        raise ParamsError("data.source", f"unknown source '{source}' (procedural, meshes, pcpnet or points)")
    if not any(s.split == "test" for s in specs):
        raise ParamsError("data.path", f"the {source} source yields no test clouds")
    return specs + _train_meshes(data, noise, {s.key for s in specs})


def _train_meshes(data: DataConfig, noise: NoiseConfig, taken: set[str]) -> list[CloudSpec]:
    """The training clouds of `data.train_meshes`: its train split, sampled and noised as the meshes source's."""
    if data.train_meshes is None:
        return []
    folder = Path(data.train_meshes)
    if not folder.is_dir():
        raise ParamsError("data.train_meshes", f"'{folder}' is not a folder")
    specs = [s for s in _folder(replace(data, path=str(folder)), noise, MESH_SUFFIXES, synthesise=True)
             if s.split == "train"]
    if not specs:
        raise ParamsError("data.train_meshes", f"no meshes in '{folder / data.split_folders['train']}/<category>/'")
    clash = sorted(taken & {s.key for s in specs})
    if clash:
        raise ParamsError("data.train_meshes", f"a mesh named as a cloud of data.source: {clash[0]}")
    return specs


def _limit(names: list[Any], data: DataConfig) -> list[Any]:
    return names if data.max_shapes is None else names[:data.max_shapes]


def _procedural(data: DataConfig, noise: NoiseConfig) -> list[CloudSpec]:
    specs: list[CloudSpec] = []
    catalogue = shapes.catalogue()
    for split in SPLITS:
        for category in shapes.CATEGORIES:
            names = [n for n, s in catalogue.items() if s.split == split and s.category == category]
            for name in _limit(names, data):
                specs += _noisy_specs(split, category, name, name, noise.levels(split, category))
    return specs


def _folder(data: DataConfig, noise: NoiseConfig, suffixes: tuple[str, ...], synthesise: bool) -> list[CloudSpec]:
    root = _root(data)
    specs: list[CloudSpec] = []
    for split in SPLITS:
        split_dir = root / data.split_folders[split]
        if not split_dir.is_dir():
            continue
        for cat_dir in sorted(p for p in split_dir.iterdir() if p.is_dir()):
            category = _category(cat_dir.name)
            files = _limit(sorted(p for p in cat_dir.iterdir() if p.suffix.lower() in suffixes), data)
            for f in files:
                stem = _SAFE.sub("_", f.stem)
                if synthesise:
                    specs += _noisy_specs(split, category, stem, str(f), noise.levels(split, category))
                else:
                    specs.append(CloudSpec(split, category, stem, str(f), None))
    return specs


def _read_list(path: Path) -> list[str]:
    if not path.is_file():
        raise InputError(path, "PCPNet list file not found")
    try:
        names = [line.strip() for line in path.read_text(encoding="utf-8-sig").splitlines() if line.strip()]
    except UnicodeDecodeError:
        raise InputError(path, "not a text file (a PCPNet list names one shape per line)") from None
    if not names:
        raise InputError(path, "empty PCPNet list file (no shape names)")
    return names


def _root(data: DataConfig) -> Path:
    if not data.path or not Path(data.path).is_dir():
        raise ParamsError("data.path", f"'{data.path}' is not a folder (needed by source '{data.source}')")
    return Path(data.path)


def _pcpnet(data: DataConfig) -> list[CloudSpec]:
    root = _root(data)
    lists = data.pcpnet
    specs = [CloudSpec("train", "train", n, str(root / f"{n}.xyz"), None)
             for n in _limit(_read_list(root / lists.train_list), data)] if lists.train_list else []
    for category, list_file in lists.test_lists.items():
        for n in _limit(_read_list(root / list_file), data):
            specs.append(CloudSpec("test", category, _SAFE.sub("_", n), str(root / f"{n}.xyz"), None))
    return specs


def make_cloud(spec: CloudSpec, n_points: int, seed: int, min_points: int = 1) -> Cloud:
    """Build one cloud: sample a shape or mesh and add seeded noise, or read a given file.

    The clean sample of a shape depends only on the shape, a mesh's on its file name and not on the folder it lies
    in (so every noise level perturbs the same points, wherever the meshes are); the noise seed depends on the
    cloud. Both seeds, the noise sigma and l_d are recorded in `meta`.
    """
    meta: dict[str, Any] = {"split": spec.split, "category": spec.category, "name": spec.name, "origin": spec.origin}
    if spec.noise is None:
        cloud = read_cloud(spec.origin, min_points=min_points, sibling_normals=True)
        if cloud.normals is None:
            raise InputError(spec.origin, "no normals found (give NAME.normals, 6 columns, or normals in the file)")
        pidx = Path(spec.origin).with_suffix(".pidx")
        if pidx.exists():
            meta["pidx"] = _read_pidx(pidx, len(cloud))
        meta.update(noise_percent=None, l_d=bbox_diagonal(cloud.points))
        return Cloud(cloud.points, cloud.normals, meta)
    sample_seed = derive_seed(seed, "sample", Path(spec.origin).name)
    clean, normals = _sample(spec.origin, n_points, sample_seed)
    noise_seed = derive_seed(seed, "noise", spec.key)
    l_d = bbox_diagonal(clean)
    meta.update(noise_percent=spec.noise, noise_sigma=spec.noise / 100 * l_d, l_d=l_d,
                sample_seed=sample_seed, noise_seed=noise_seed, n_points=n_points)
    return Cloud(add_gaussian_noise(clean, spec.noise, noise_seed), normals, meta)


def surface_sample(path: str | Path, meta: dict[str, Any], n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """A fresh, dense sample of the clean surface a cloud record was made from (points and true normals), where
    distances to the true surface are measured; only a synthesised cloud (a procedural shape or a mesh) has one."""
    if meta.get("noise_percent") is None:
        raise InputError(path, "a given cloud has no known clean surface (only procedural or mesh clouds have one)")
    return _sample(meta["origin"], n_points, derive_seed(meta["sample_seed"], "surface"))


def _sample(origin: str, n_points: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Points uniform by area on a catalogued shape or a mesh file, with their true normals."""
    if origin in shapes.catalogue():
        return shapes.sample_shape(origin, n_points, seed)
    vertices, faces = read_mesh(origin)
    return sample_mesh(vertices, faces, n_points, np.random.default_rng(seed))


#: Files of a folder of real scans (params.yaml `figures.scans`): point files, and meshes whose vertices are the points.
SCAN_SUFFIXES = tuple(dict.fromkeys((*POINT_FILE_SUFFIXES, *MESH_SUFFIXES)))


def scan_files(folder: str | Path) -> list[Path]:
    """The scans of a folder, by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(folder, "not a folder of scans")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SCAN_SUFFIXES)
    if not files:
        raise InputError(folder, f"no scans here (files ending {', '.join(SCAN_SUFFIXES)})")
    return files


def read_scan(path: str | Path, max_points: int | None, seed: int, min_points: int = 1) -> np.ndarray:
    """A real scan's points (N, 3): a point file's, or a scanned mesh's vertices (its measured points); a subset
    of at most `max_points`, seeded by the scan's name."""
    path = Path(path)
    if path.suffix.lower() in POINT_FILE_SUFFIXES:
        points = read_cloud(path, min_points).points
    else:
        points = check_array(path, read_mesh(path)[0], "vertices", min_points)
    if max_points is not None and len(points) > max_points:
        rng = np.random.default_rng(derive_seed(seed, "scan", path.name))
        points = points[np.sort(rng.choice(len(points), max_points, replace=False))]
    return points


def scored_points(cloud: Cloud, points: int | None = None) -> np.ndarray | None:
    """The points of a cloud record that the tables score, or None for all: a test cloud's `.pidx` subset (PCPNet's
    evaluation points), and of those (of all, without one) a seeded subset of `points` (`inference.points`, which
    `variant_budget` sets for the variants). Only these need a network pass, so a PCPNet shape of 100k points costs
    the network 5,000. The subset depends on the cloud's name alone, not on the seed a variant runs with, so every
    row of a table scores the same points; a smaller subset is a prefix of a larger one."""
    meta = cloud.meta
    if meta.get("split") != "test":
        return None
    pool = np.asarray(meta["pidx"], dtype=np.int64) if "pidx" in meta else None
    size = len(cloud) if pool is None else len(pool)
    if points is None or points >= size:
        return pool
    order = np.random.default_rng(derive_seed(0, "scored", meta["category"], meta["name"])).permutation(size)
    chosen = np.sort(order[:points])
    return chosen if pool is None else pool[chosen]


def _read_pidx(path: Path, n_points: int) -> list[int]:
    try:
        with warnings.catch_warnings():  # an empty file is reported below, not as a warning on stderr
            warnings.simplefilter("ignore", UserWarning)
            idx = np.loadtxt(path, dtype=np.int64, ndmin=1)
    except (ValueError, OSError) as err:
        raise InputError(path, f"malformed .pidx file ({first_line(err)})") from None
    if idx.size == 0:
        raise InputError(path, "empty .pidx file (no point indices)")
    if idx.min() < 0 or idx.max() >= n_points:
        raise InputError(path, f".pidx indices must lie in 0..{n_points - 1}")
    return idx.tolist()
