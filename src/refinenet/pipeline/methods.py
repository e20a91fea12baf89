"""The normal estimators the pipeline compares, by method name (`pca`, `mfps`, ...; a Refine-Net variant is the
method `refinenet/<variant>`), and the params blocks that configure each: table captions name their values and a
table's step tracks them."""

from __future__ import annotations

from refinenet import config
from refinenet.estimators.baselines import METHODS as BASELINES
from refinenet.estimators.mfps import METHODS as MFPS_METHODS
from refinenet.evaluation.table import METHOD_NAMES

REFINENET = "refinenet"
FULL = config.FULL
REFERENCE = config.REFERENCE

#: Normal estimators and the params blocks that configure each.
METHODS = {**{m: ("baselines",) for m in BASELINES}, **{m: ("mfps",) for m in MFPS_METHODS},
           REFINENET: ("mfps", "features", "clustering", "network", "patches", "training")}


def refinenet(variant: str) -> str:
    """The method name of a Refine-Net variant in tables: `refinenet` for full, `refinenet/<variant>` otherwise."""
    return REFINENET if variant == FULL else f"{REFINENET}/{variant}"


def variant_of(method: str) -> str | None:
    """The variant of a Refine-Net method name; None for the other estimators."""
    if method == REFINENET:
        return FULL
    return method.removeprefix(f"{REFINENET}/") if method.startswith(f"{REFINENET}/") else None


def figure_name(method: str) -> str:
    """A method's name in figures: its table name, or `Refine-Net <variant>` for a variant."""
    variant = variant_of(method)
    return METHOD_NAMES[method] if variant in (None, FULL) else f"{METHOD_NAMES[REFINENET]} {variant}"


def blocks(methods: tuple[str, ...]) -> tuple[str, ...]:
    """The params blocks that configure the given methods (a Refine-Net variant's as Refine-Net's)."""
    return tuple(dict.fromkeys(b for m in methods for b in METHODS[REFINENET if variant_of(m) else m]))
