"""Loading params.yaml: apply the selected profile's overrides, then validate against the schema.

Errors name the dotted key and the problem in one line, e.g.
`params.yaml: baselines.pca_k: -3 is less than the minimum of 3`.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import jsonschema
import yaml

from refinenet.errors import ParamsError

SCHEMA = Path("workflow/schemas/params.schema.yaml")
#: Mappings whose keys are data (categories, list names), replaced whole by an override.
OPEN_MAPPINGS = frozenset({"test_lists", "test"})


def deep_merge(base: dict[str, Any], override: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """`base` with `override` applied key by key; an override key absent from `base` is an error (a typo)."""
    merged = copy.deepcopy(base)
    for key, value in override.items():
        dotted = f"{prefix}{key}"
        if key not in base:
            raise ParamsError(dotted, "overrides a key that does not exist")
        if isinstance(value, dict) and isinstance(base[key], dict) and key not in OPEN_MAPPINGS:
            merged[key] = deep_merge(base[key], value, f"{dotted}.")
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def get(params: dict[str, Any], dotted: str) -> Any:
    """The value at a dotted key, e.g. `get(p, "data.n_points")`."""
    value: Any = params
    for part in dotted.split("."):
        value = value[part]
    return value


def resolve(raw: dict[str, Any], source: str = "params.yaml", schema: Path = SCHEMA) -> dict[str, Any]:
    """Validated parameters with the active profile's overrides applied."""
    if not isinstance(raw, dict):
        raise ParamsError("(top level)", "expected a mapping of keys to values", source)
    profile = raw.get("profile")
    profiles = raw.get("profiles") or {}
    if profile not in profiles:
        raise ParamsError("profile", f"'{profile}' is not one of the profiles {sorted(profiles)}", source)
    try:
        resolved = deep_merge(raw, {**profiles[profile], "profile": profile}, "")
        for name, block in profiles.items():
            deep_merge(raw, block, f"profiles.{name}.")
    except ParamsError as err:
        raise ParamsError(err.key, err.problem, source) from None
    validate(resolved, source, schema)
    return resolved


def validate(params: dict[str, Any], source: str = "params.yaml", schema: Path = SCHEMA) -> None:
    """Check every value against the JSON schema; report the first problem with its dotted key."""
    spec = yaml.safe_load(Path(schema).read_text())
    errors = sorted(jsonschema.Draft202012Validator(spec).iter_errors(params), key=lambda e: list(e.path))
    if errors:
        err = errors[0]
        key = ".".join(str(p) for p in err.path) or "(top level)"
        raise ParamsError(key, err.message, source)


def load(path: str | Path = "params.yaml", schema: Path = SCHEMA) -> dict[str, Any]:
    """Read, resolve and validate a params file."""
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ParamsError("(file)", f"cannot be read as YAML ({str(err).splitlines()[0]})", str(path)) from None
    return resolve(raw, str(path), schema)
