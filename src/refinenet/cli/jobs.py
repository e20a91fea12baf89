"""One cloud's normals as separate jobs, one per tile, for a scan too large for one process's patience.

`make_plan` measures once what every tile takes from the whole cloud (per stratum: `estimate.CloudLayout`), a
job (`job_normals`) computes one tile's own normals from the plan, and `merged` puts them together and reconciles
the strata. Strata and tiles are cut the same way in every job, so the normals are those `estimate_normals` gives
with the same tile size. `refinenet tiles plan|run|merge` are the three steps as commands; workflow/tiles.smk
makes them Snakemake jobs, so that a cluster profile spreads the tiles over nodes.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from refinenet.cli.estimate import (
    TILE_POINTS,
    CloudLayout,
    cloud_layout,
    reconciled,
    stratum_cloud,
    stratum_rows,
    tile_normals,
)
from refinenet.errors import InputError
from refinenet.estimators.mfps import Candidacy
from refinenet.network.release import Release

#: The plan file's format; a plan of another format is refused.
PLAN_FORMAT = 1


@dataclass(frozen=True)
class Plan:
    """What the jobs of one cloud share: the cloud (by path and content), the method's settings, and the layout
    of each stratum with its number of tiles."""

    cloud: str
    """The cloud's file."""
    digest: str
    n_points: int
    method: str
    scale: str
    release: str | None
    """The release folder (None: the shipped networks)."""
    initial: str | None
    """The file of the initial normals Refine-Net refines (None: MFPS's)."""
    layouts: tuple[CloudLayout, ...]
    n_tiles: tuple[int, ...]

    @property
    def n_jobs(self) -> int:
        return sum(self.n_tiles)

    def locate(self, job: int) -> tuple[int, int]:
        """The stratum and the tile within it of job number `job` (0 to n_jobs - 1)."""
        for stratum, n in enumerate(self.n_tiles):
            if job < n:
                return stratum, job
            job -= n
        raise IndexError(job)

    def to_json(self) -> str:
        return json.dumps({"format": PLAN_FORMAT, **asdict(self)}, indent=1) + "\n"

    @classmethod
    def read(cls, path: str | Path) -> Plan:
        """The plan in `path`; anything else is an InputError naming it."""
        try:
            raw = json.loads(Path(path).read_text())
            if raw.pop("format") != PLAN_FORMAT:
                raise ValueError(f"format is not {PLAN_FORMAT}")
            n_tiles = tuple(raw.pop("n_tiles"))
            layouts = tuple(CloudLayout(**{**layout, "candidacy": layout["candidacy"] and
                                           Candidacy(**layout["candidacy"])}) for layout in raw.pop("layouts"))
            if len(layouts) != len(n_tiles):
                raise ValueError("one tile count per stratum")
            return cls(**raw, layouts=layouts, n_tiles=n_tiles)
        except OSError as err:
            raise InputError(path, f"cannot be read ({err.strerror})") from None
        except KeyError as err:
            raise InputError(path, f"is not a plan of `refinenet tiles plan` (no {err.args[0]})") from None
        except (ValueError, TypeError, AttributeError) as err:
            raise InputError(path, f"is not a plan of `refinenet tiles plan` ({err})") from None

    def check_cloud(self, points: np.ndarray, plan_path: str | Path) -> None:
        """Refuse a cloud other than the one the plan was made for."""
        if len(points) != self.n_points or points_digest(points) != self.digest:
            raise InputError(self.cloud, f"is not the cloud {plan_path} was made for (it changed since); make the "
                                         f"plan again")


def points_digest(points: np.ndarray) -> str:
    """A fingerprint of the coordinates (as float64), so that a job refuses a cloud its plan was not made for."""
    return hashlib.blake2b(np.ascontiguousarray(points, dtype=np.float64), digest_size=16).hexdigest()


def make_plan(points: np.ndarray, cloud: str, release: Release, method: str, n_strata: int,
              release_folder: str | None = None, initial: str | None = None, scale: str = "spacing",
              tile_points: int = TILE_POINTS) -> Plan:
    """The plan of `points`, read from the file `cloud`, estimated by `method` as `n_strata` strata of tiles of at
    most `tile_points` own points (`initial`: the file of the initial normals, if given)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    layouts, n_tiles = [], []
    for rows in stratum_rows(len(points), n_strata):
        sub = stratum_cloud(points, None, rows, n_strata)[0]
        layout, cut = cloud_layout(sub, release, method, initial is not None, scale, tile_points)
        layouts.append(layout)
        n_tiles.append(len(cut))
    return Plan(cloud, points_digest(points), len(points), method, scale, release_folder, initial, tuple(layouts),
                tuple(n_tiles))


def job_normals(plan: Plan, job: int, points: np.ndarray, release: Release, initial: np.ndarray | None = None,
                device: str = "auto", workers: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The ids (positions in the whole cloud) and normals of the own points of job `job`'s tile."""
    stratum, index = plan.locate(job)
    points = np.ascontiguousarray(points, dtype=np.float64)
    rows = stratum_rows(len(points), len(plan.n_tiles))[stratum]
    sub, given = stratum_cloud(points, initial, rows, len(plan.n_tiles))
    layout = plan.layouts[stratum]
    tile = layout.tiles(sub)[index]
    return rows[tile.own], tile_normals(sub, tile, layout, release, plan.method, given, device, workers)


def merged(plan: Plan, pieces: list[tuple[np.ndarray, np.ndarray, str]], points: np.ndarray) -> np.ndarray:
    """The whole cloud's normals from every job's (ids, normals, file), each point's exactly once."""
    normals = np.full((plan.n_points, 3), np.nan)
    seen = np.zeros(plan.n_points, dtype=bool)
    for ids, piece, path in pieces:
        if seen[ids].any():
            raise InputError(path, "gives normals another piece gave already (a job's piece named twice?)")
        seen[ids] = True
        normals[ids] = piece
    if not seen.all():
        raise InputError("pieces", f"{(~seen).sum():,} of {plan.n_points:,} points have no normals: name the "
                                   f"pieces of all {plan.n_jobs} jobs of the plan")
    return reconciled(np.ascontiguousarray(points, dtype=np.float64), normals, len(plan.n_tiles))
