"""The workflow of one params file (`Pipeline`): every Refine-Net variant's typed params, which files each variant
owns, the run's clouds, where each method's normals are, and one `Step` per DVC stage and Snakemake rule. The
Snakefile, the bridge and the stage scripts read the same object, so the two tools and the scripts agree on every
path."""

from __future__ import annotations

import functools
import os
from typing import Any

from refinenet import config
from refinenet.config import Params, ScannerConfig
from refinenet.data.clouds import CloudSpec, list_clouds
from refinenet.data.scans import check_shapes
from refinenet.errors import ParamsError
from refinenet.pipeline.catalogue import (
    ARCHITECTURE,
    FIGURE_CATEGORIES,
    FIGURE_METHODS,
    MAIN,
    REAL_VARIANT,
    TABLES,
    Table,
)
from refinenet.pipeline.layout import FIGURE_TRAINING, MODEL_DIR, NORMALS, REFINED, REPORT_FILES, SCANS_DIR
from refinenet.pipeline.methods import FULL, REFINENET, refinenet, variant_of
from refinenet.pipeline.steps import Step, declare
from refinenet.pipeline.variants import owners, typed


def clouds(params: Params, split: str | None = None) -> list[CloudSpec]:
    """The run's clouds (optionally of one split)."""
    return [c for c in list_clouds(params.data, params.noise) if split in (None, c.split)]


def first_test_clouds(params: Params) -> dict[str, str]:
    """The first test cloud of each category, category -> key."""
    first: dict[str, str] = {}
    for c in clouds(params, "test"):
        first.setdefault(c.category, c.key)
    return first


def check_keys(params: Params) -> list[str]:
    """One test cloud per category (the first): where the release measures what half precision changes."""
    return list(first_test_clouds(params).values())


class Pipeline:
    """The steps of one params file: every Refine-Net variant's settings, which files each variant owns, and one
    `Step` per DVC stage and Snakemake rule."""

    def __init__(self, raw: dict[str, Any], source: str = "params.yaml"):
        self.raw = raw
        self.resolved = config.resolve_variants(raw, source)
        """Each variant's resolved params (dotted keys apply: `config.get(resolved[v], key)`)."""
        self.params = {v: typed(v, resolved, source) for v, resolved in self.resolved.items()}
        self.full = self.params[FULL]
        self.scanner = ScannerConfig.from_resolved(self.resolved[FULL], source)
        """The simulated scans' sensor: a pipeline block, read from full's resolved params."""
        try:
            check_shapes(self.scanner.shapes)
        except ParamsError as err:
            raise ParamsError(err.key, err.problem, source) from None
        for name, variants in [*((n, t.variants) for n, t in TABLES.items()), ("table_architecture", ARCHITECTURE),
                               ("fig_real and table_scans", [REAL_VARIANT])]:
            for v in variants:
                if v not in self.params:
                    raise ParamsError("variants", f"{name} needs the variant '{v}', which is not defined", source)
        for v in self.full.figures.variants:
            if v not in self.params:
                raise ParamsError("figures.variants", f"'{v}' is not a variant (variants: {sorted(self.params)})",
                                  source)
        self.scored = {v for t in TABLES.values() for v in t.variants} | set(self.full.figures.variants)
        """The variants whose normals of the test clouds a table or the normals figure shows: only these have
        test-cloud features and inference (x8 serves the scans alone)."""
        for name, methods in [*((n, t.methods) for n, t in TABLES.items()), ("fig_normals", self.figure_methods())]:
            self.scored_subset(methods, f"{name}: ")
        self.owners = {v: owners(raw, v) for v in self.params}
        self.steps: dict[str, Step] = {s.name: s for s in declare(self)}

    def scored_subset(self, methods: tuple[str, ...], where: str = "") -> int | None:
        """How many points of each test cloud the rows of a table (or the panels of a figure) are scored on: the
        `inference.points` of its Refine-Net variants (None: all). Every row scores the same points, so the variants
        that refine a subset must agree on its size; the others refined every point, any subset included."""
        sizes = {self.params[v].inference.points for v in map(variant_of, methods) if v is not None} - {None}
        if len(sizes) > 1:
            raise ParamsError("inference.points", f"{where}its Refine-Net variants refine subsets of different sizes "
                              f"{sorted(sizes)}; a table scores one subset")
        return next(iter(sizes), None)

    @functools.cached_property
    def clouds(self) -> list[CloudSpec]:
        return clouds(self.full)

    def owner(self, variant: str, family: str) -> str:
        return self.owners[variant][family]

    def family(self, name: str) -> list[Step]:
        """The instances of one step family, full's first."""
        return [s for s in self.steps.values() if s.family == name]

    def keys(self, split: str | None = None) -> list[str]:
        return [c.key for c in self.clouds if split in (None, c.split)]

    def normals_path(self, method: str, cloud: str) -> str:
        """Estimated normals of the cloud with key `cloud` (a Refine-Net variant's from the variant that owns them)."""
        variant = variant_of(method)
        if variant is None:
            return NORMALS.format(method=method, cloud=cloud)
        return REFINED.format(variant=self.owner(variant, "inference"), cloud=cloud)

    def normals_dir(self, method: str, split: str = "test") -> str:
        """The folder of a method's normals of one split (a step's dependency)."""
        return os.path.dirname(self.normals_path(method, f"{split}/x"))

    def initial_path(self, variant: str, cloud: str) -> str:
        """The normals the features of `variant` start from, for the cloud with key `cloud`."""
        initial = self.params[variant].features.initial
        if initial in config.INITIAL_ESTIMATORS:
            return self.normals_path(initial, cloud)
        return f"{initial}/{cloud}.normals"

    def variant_dir(self, family: str, variant: str, split: str) -> str:
        """The folder of a per-variant step's files of one split (or the cluster model's, the networks'), from the
        variant that owns them."""
        owner = self.owner(variant, family)
        return {"features": f"results/features/{owner}/{split}", "clustering": f"results/clusters/{owner}",
                "training": MODEL_DIR.format(variant=owner),
                "inference": f"results/normals/{REFINENET}/{owner}/{split}"}[family]

    @property
    def trained(self) -> list[str]:
        """The variants with networks of their own (full's first)."""
        return [v for v in self.params if self.owner(v, "training") == v]

    def swept(self, method: str, key: str) -> Any:
        """The value of a dotted params key for a Refine-Net variant's method."""
        return config.get(self.resolved[variant_of(method)], key)

    def protocol(self, table: Table) -> str:
        return table.protocol or self.full.evaluation.protocol

    def main_targets(self) -> list[str]:
        """The main job's files (`snakemake main`): those of the MAIN steps, the release's training curves and the
        page of them, beside the committed results of the rest."""
        return [*(t for name in MAIN for t in self.steps[name].targets()), FIGURE_TRAINING.format(variant=FULL),
                *REPORT_FILES.values()]

    def scans_folder(self) -> str:
        """fig_real's scans: the folder params.yaml `figures.scans` names, or the simulated scans."""
        return self.full.figures.scans or SCANS_DIR

    def denoise_keys(self) -> list[str]:
        """The test clouds the denoising application covers: those synthesised from a surface (a procedural shape or
        a mesh), against which distances are measured."""
        return [c.key for c in self.clouds if c.split == "test" and c.noise is not None]

    def denoise_figure_key(self) -> str:
        """The cloud of the denoising figure: the normals figure's first cloud, if the application covers it."""
        keys = self.denoise_keys()
        return next((k for k in self.figure_keys() if k in keys), keys[0])

    def figure_methods(self) -> tuple[str, ...]:
        """The columns of the normals figure: FIGURE_METHODS, then the variants of params.yaml `figures.variants`."""
        return tuple(dict.fromkeys((*FIGURE_METHODS, *map(refinenet, self.full.figures.variants))))

    def figure_keys(self) -> list[str]:
        """The test clouds of the normals figure: the first of each FIGURE_CATEGORIES category, or (a source
        without them) the first test cloud."""
        first = first_test_clouds(self.full)
        return [first[c] for c in FIGURE_CATEGORIES if c in first] or [next(iter(first.values()))]

    def loss_figure_keys(self) -> list[str]:
        """The test clouds of the L1/L2 figure: the first figure cloud's shape at each of its noise levels, least
        noise first (the first figure cloud alone where the data gives no shape at several levels)."""
        first = next(c for c in self.clouds if c.key == self.figure_keys()[0])
        levels = [c for c in self.clouds if c.split == "test" and c.origin == first.origin and c.noise is not None]
        return [c.key for c in sorted(levels, key=lambda c: c.noise)] or [first.key]
