"""Angular error metrics and the two aggregation protocols of docs/algorithm.md §10.

Per point: the unoriented angle theta = arccos(|n . g|) in degrees. Per cloud we keep sufficient
statistics (count, sum theta, sum theta^2, counts below 5 and 10 degrees) so categories can be pooled
exactly without re-reading every point.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, fields

import numpy as np

PGP_THRESHOLDS = (5.0, 10.0)


def unoriented_angles(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Angle in degrees between unit normals, ignoring orientation."""
    cos = np.abs(np.einsum("ij,ij->i", estimated, truth))
    cos /= np.linalg.norm(estimated, axis=1) * np.linalg.norm(truth, axis=1)
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


@dataclass(frozen=True)
class ErrorStats:
    """Sufficient statistics of a set of per-point angles."""

    n: int
    sum_deg: float
    sum_sq_deg: float
    below_5: int
    below_10: int

    @classmethod
    def from_angles(cls, angles: np.ndarray) -> ErrorStats:
        return cls(
            n=int(angles.size),
            sum_deg=float(angles.sum()),
            sum_sq_deg=float(np.square(angles).sum()),
            below_5=int((angles < PGP_THRESHOLDS[0]).sum()),
            below_10=int((angles < PGP_THRESHOLDS[1]).sum()),
        )

    @property
    def mean(self) -> float:
        return self.sum_deg / self.n

    @property
    def rmse(self) -> float:
        return float(np.sqrt(self.sum_sq_deg / self.n))

    @property
    def pgp5(self) -> float:
        return self.below_5 / self.n

    @property
    def pgp10(self) -> float:
        return self.below_10 / self.n

    def summary(self) -> dict[str, float]:
        return {"mean": self.mean, "rmse": self.rmse, "pgp5": self.pgp5, "pgp10": self.pgp10, "n": self.n}

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


#: The fields of ErrorStats, in constructor order (the columns of per-cloud statistics files).
STAT_FIELDS = tuple(f.name for f in fields(ErrorStats))


def pooled(stats: Iterable[ErrorStats]) -> ErrorStats:
    """All points of several clouds taken together."""
    stats = list(stats)
    return ErrorStats(*(sum(getattr(s, f) for s in stats) for f in STAT_FIELDS))


def synthetic_category(stats: Sequence[ErrorStats]) -> dict[str, float]:
    """Synthetic/Kinect protocol for one category: mean and PGP pooled over all points; `rmse` is the
    point-weighted mean of per-cloud RMSE (as the release computes it), `rmse_pooled` the pooled RMSE."""
    total = pooled(stats)
    weighted_rmse = sum(s.n * s.rmse for s in stats) / total.n
    return {**total.summary(), "rmse": weighted_rmse, "rmse_pooled": total.rmse}


def pcpnet_category(stats: Sequence[ErrorStats]) -> dict[str, float]:
    """PCPNet protocol for one category: the unweighted mean over shapes of per-shape values (`.pidx` subset)."""
    return {key: float(np.mean([s.summary()[key] for s in stats])) for key in ("mean", "rmse", "pgp5", "pgp10")}


def average_over_categories(per_category: dict[str, dict[str, float]]) -> dict[str, float]:
    """The tables' "Average" column: the unweighted mean of the category values."""
    keys = next(iter(per_category.values())).keys()
    return {k: float(np.mean([c[k] for c in per_category.values()])) for k in keys if k != "n"}
