"""Which files each Refine-Net variant owns. The steps run once per variant (features, clustering, training,
inference) get an instance of their own for a variant only where its overrides reach the step's keys or it owns an
upstream step; otherwise the variant reads full's files, so a variant shared by two tables is trained once."""

from __future__ import annotations

from typing import Any

from refinenet.config import Params
from refinenet.errors import ParamsError
from refinenet.pipeline.methods import FULL

#: The keys that fix the network (`network.model.architecture`): X and m come from the features block.
ARCHITECTURE_KEYS = ("features.sigma_s", "features.sigma_r", "features.include_initial", "features.hmp_size",
                     "features.pca_k", "features.jet_k", "network", "patches")
#: The steps run once per Refine-Net variant, the keys each reads, and the steps whose files it reads.
VARIANT_STEPS = {
    "features": (("features",), ()),
    "clustering": (("clustering", "seed"), ("features",)),
    "training": ((*ARCHITECTURE_KEYS, "training", "seed"), ("features", "clustering")),
    "inference": ((*ARCHITECTURE_KEYS, "inference", "seed"), ("features", "clustering", "training")),
}


def leaves(tree: Any, prefix: str = "") -> dict[str, Any]:
    """The leaves of nested dicts by dotted key; an empty dict is a leaf (an override may name a block alone)."""
    if isinstance(tree, dict) and tree:
        return {k: v for key, value in tree.items() for k, v in leaves(value, f"{prefix}{key}.").items()}
    return {prefix.rstrip("."): tree}


def written(tree: Any, dotted: str) -> bool:
    """Whether the raw params file (or one of its blocks) writes the dotted key."""
    for part in dotted.split("."):
        if not isinstance(tree, dict) or part not in tree:
            return False
        tree = tree[part]
    return True


def _overlaps(a: str, b: str) -> bool:
    return a == b or a.startswith(f"{b}.") or b.startswith(f"{a}.")


def override_keys(raw: dict[str, Any], variant: str) -> set[str]:
    """The dotted keys a variant overrides, in params.yaml's `variants` and `variant_budget` (which every variant
    but full takes) and in any profile's."""
    if variant == FULL:
        return set()
    sources = [raw, *((raw.get("profiles") or {}).values())]
    blocks = [((s or {}).get("variants") or {}).get(variant) for s in sources]
    blocks += [(s or {}).get("variant_budget") for s in sources]
    return {leaf for block in blocks if block for leaf in leaves(block)}


def owners(raw: dict[str, Any], variant: str) -> dict[str, str]:
    """For each per-variant step, the variant whose files `variant` uses: itself or full. Decided by the keys
    written, not their values, so that the pipeline (and dvc.yaml) is the same whichever profile is active."""
    overridden = override_keys(raw, variant)
    own: dict[str, str] = {}
    for family, (keys, upstream) in VARIANT_STEPS.items():
        reached = any(_overlaps(k, o) for k in keys for o in overridden)
        own[family] = variant if reached or any(own[u] == variant for u in upstream) else FULL
    return own


def typed(variant: str, resolved: dict[str, Any], source: str) -> Params:
    """A variant's typed params; full's are checked first, so a value only a variant's overrides make bad (e.g. a
    missing folder of initial normals) is reported under the variant's key."""
    try:
        return Params.from_resolved(resolved, source)
    except ParamsError as err:
        if variant == FULL:
            raise
        raise ParamsError(f"variants.{variant}.{err.key}", err.problem, source) from None
