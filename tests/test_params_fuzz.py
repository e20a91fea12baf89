"""Every leaf key of params.yaml, broken three ways (a wrong type, an out-of-range value, a misspelt name), is
reported by `config.load` as one `ParamsError` line naming the key; and a few of them through the tools, which
must stop with that line (`snakemake -n`, and the bridge command every DVC stage runs).

Each variant is written with the file's keys in effect: a base key that the active profile overrides is tested under
a profile that does not (`live_profile`), since the profile's value would replace it. Values that no profile lets
take effect are `test_masked_values_are_reported`.
"""

from __future__ import annotations

import copy
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from refinenet import config
from refinenet.errors import ParamsError

REPO = Path(__file__).resolve().parents[1]
RAW = yaml.safe_load((REPO / "params.yaml").read_text())
SCHEMA = yaml.safe_load(config.SCHEMA.read_text())
PROFILES = list(RAW["profiles"])
#: A few leaves of the profiles subtree (the active profile's and inactive ones'), besides every base leaf.
PROFILE_SAMPLES = (("profiles", RAW["profile"], "data", "n_points"), ("profiles", "smoke", "clustering", "n_clusters"),
                   ("profiles", "release", "mfps", "theta_t"))
VARIANTS = ("wrong type", "out of range", "misspelt")


Key = tuple[str, ...]


def leaves(node: dict[str, Any], prefix: Key = ()) -> Iterator[Key]:
    """The keys (as tuples: a table column's name may hold a dot) of the leaves below `node`; a list is a leaf, as
    is an empty mapping."""
    for name, value in node.items():
        key = (*prefix, str(name))
        if isinstance(value, dict) and value:
            yield from leaves(value, key)
        else:
            yield key


BASE_KEYS = [key for key in leaves(RAW) if key[0] != "profiles"]
KEYS = [*BASE_KEYS, *PROFILE_SAMPLES]


def dotted(key: Key) -> str:
    return ".".join(key)


def resolved_key(key: Key) -> Key:
    """The key a profile's or a Refine-Net variant's leaf overrides (`profiles.cpu.data.n_points` ->
    `data.n_points`, `variants.l1.training.loss` -> `training.loss`)."""
    return key[2:] if key[0] in ("profiles", "variants") else key


def schema_of(key: Key) -> dict[str, Any]:
    """The schema of a (resolved) key, following `properties`, `additionalProperties` and `$ref`."""
    node = SCHEMA
    for part in resolved_key(key):
        if part in node.get("properties", {}):
            node = node["properties"][part]
        else:
            node = node["additionalProperties"]
        if "$ref" in node:
            node = SCHEMA["definitions"][node["$ref"].rsplit("/", 1)[1]]
    return node


def is_open(key: Key) -> bool:
    """Whether the key's parent is a mapping whose keys are data (categories, table columns): any name goes."""
    parents = resolved_key(key)[:-1]
    return bool(parents) and parents[-1] in config.OPEN_MAPPINGS


def _types(schema: dict[str, Any]) -> set[str]:
    kind = schema.get("type", [])
    return {kind} if isinstance(kind, str) else set(kind)


def _json_types(value: Any) -> set[str]:
    if isinstance(value, bool):
        return {"boolean"}
    if isinstance(value, int):
        return {"integer", "number"}
    if isinstance(value, float):
        return {"number"}
    return {str: {"string"}, list: {"array"}, dict: {"object"}, type(None): {"null"}}[type(value)]


def wrong_type(key: Key) -> Any:
    allowed = _types(schema_of(key))
    return next(v for v in ("text", 7, [1, 2], {"a": 1}) if not _json_types(v) & allowed)


def out_of_range(key: Key) -> Any:
    """A value of the right type outside the schema's range or enum; None where the schema has neither."""
    schema = schema_of(key)
    if "enum" in schema:
        return "not_an_option"
    if "minimum" in schema:
        return schema["minimum"] - 1
    if "exclusiveMinimum" in schema:
        return schema["exclusiveMinimum"]
    if "maximum" in schema:
        return schema["maximum"] + 1
    if "exclusiveMaximum" in schema:
        return schema["exclusiveMaximum"]
    if "minLength" in schema:
        return ""
    if "minItems" in schema:
        return []
    if "minProperties" in schema:
        return {}
    return None


def live_profile(key: Key) -> str:
    """A profile under which the file's value of `key` takes effect: the file's own, or one not overriding it."""
    if key[0] == "profiles":
        return key[1]
    for name in [RAW["profile"], *PROFILES]:
        node: Any = RAW["profiles"][name]
        for part in key:
            if not isinstance(node, dict) or part not in node:
                return name
            node = node[part]
    raise AssertionError(f"every profile overrides {dotted(key)}")


def _parent(raw: dict[str, Any], key: Key) -> dict[str, Any]:
    node = raw
    for part in key[:-1]:
        node = node[part]
    return node


def variant(key: Key, kind: str) -> dict[str, Any]:
    """params.yaml with `key` broken as `kind`, under a profile that lets the file's value take effect."""
    raw = copy.deepcopy(RAW)
    if key != ("profile",):
        raw["profile"] = live_profile(key)
    node, last = _parent(raw, key), key[-1]
    if kind == "wrong type":
        node[last] = wrong_type(key)
    elif kind == "out of range":
        value = out_of_range(key)
        if value is None:
            pytest.skip(f"{dotted(key)}: the schema gives no range or choices")
        node[last] = value
    else:
        if is_open(key):
            pytest.skip(f"{dotted(key)}: the keys of {dotted(key[:-1])} are data (any name is valid)")
        items = list(node.items())
        node.clear()
        node.update((f"{name}x" if name == last else name, value) for name, value in items)
    return raw


def load_error(tmp_path: Path, raw: dict[str, Any]) -> tuple[Path, str]:
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    with pytest.raises(ParamsError) as info:
        config.load(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: "), message
    return path, message


def names_the_key(message: str, key: Key, kind: str) -> bool:
    """Whether the error names the key: its dotted form (or, for a profile's leaf, the key it overrides), or for a
    misspelt key the misspelt or the missing name (e.g. `profiles.smoke.data.n_points: overrides a key that does
    not exist` when the base `data.n_points` is misspelt)."""
    names = {dotted(key), dotted(resolved_key(key))}
    if any(f": {name}:" in message or f": {name}." in message for name in names):
        return True
    leaf = key[-1]
    return kind == "misspelt" and (f"'{leaf}x'" in message or f"'{leaf}'" in message
                                   or any(f".{name}:" in message or f": {name}x:" in message for name in names))


@pytest.mark.parametrize("kind", VARIANTS)
@pytest.mark.parametrize("key", KEYS, ids=dotted)
def test_a_broken_key_is_named(tmp_path, key, kind):
    _, message = load_error(tmp_path, variant(key, kind))
    assert names_the_key(message, key, kind), f"{kind} {dotted(key)}: the error does not name it: {message}"


def test_every_variant_is_valid_until_broken(tmp_path):
    """The fuzzing baseline: every live profile loads before a key is broken."""
    for name in sorted({live_profile(key) for key in KEYS}):
        raw = copy.deepcopy(RAW)
        raw["profile"] = name
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(raw, sort_keys=False))
        assert config.load(path).profile == name


#: The base keys that `config.Params` types: those of one variant's resolved params, such as a release stores.
TYPED_KEYS = [key for key in BASE_KEYS if key[0] in config.Params.__dataclass_fields__ and key != ("profile",)]


@pytest.mark.parametrize("key", TYPED_KEYS, ids=dotted)
def test_a_value_out_of_range_has_one_message_with_or_without_resolve(key):
    """The schema is the one source of every range and choice: resolved params built without `resolve` (a release's)
    report a bad value in the words `resolve` uses."""
    raw = variant(key, "out of range")
    with pytest.raises(ParamsError) as checked:
        config.resolve(raw)
    unchecked = config.resolve({**RAW, "profile": raw["profile"]})
    _parent(unchecked, key)[key[-1]] = _parent(raw, key)[key[-1]]
    with pytest.raises(ParamsError) as built:
        config.Params.from_resolved(unchecked)
    assert str(built.value) == str(checked.value)


@pytest.mark.parametrize("key", [("training", "lr"), ("profiles", "paper", "features", "r_f")], ids=dotted)
def test_masked_values_are_reported(tmp_path, key):
    raw = copy.deepcopy(RAW)
    assert live_profile(key) != raw["profile"]  # masked by the active profile, or in an inactive one
    _parent(raw, key)[key[-1]] = "text"
    _, message = load_error(tmp_path, raw)
    assert dotted(key) in message


# ------------------------------------------------------------------------------------------------------ the tools

#: A sample through the tools: (dotted key, kind, the line's beginning after `error: params.yaml: `).
TOOL_SAMPLES = [(("baselines", "pca_k"), "wrong type", "baselines.pca_k: 'text' is not of type 'integer'"),
                (("mfps", "eta"), "out of range", "mfps.eta: 'not_an_option' is not one of"),
                (("features", "hmp_k"), "misspelt", "features: ")]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    from scratch import smoke_copy

    return smoke_copy(tmp_path_factory.mktemp("params_fuzz"))


@pytest.mark.parametrize(("key", "kind", "line"), TOOL_SAMPLES, ids=[dotted(s[0]) for s in TOOL_SAMPLES])
def test_the_tools_stop_with_the_key(scratch, key, kind, line):
    from scratch import isolated

    original = (scratch / "params.yaml").read_text()
    raw = variant(key, kind)
    raw["profile"] = "smoke"
    (scratch / "params.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))
    try:
        commands = {"snakemake -n": [sys.executable, "-m", "snakemake", "-n"],
                    "bridge run baselines (each DVC stage's command)": [
                        sys.executable, "-m", "refinenet.pipeline.bridge", "run", "baselines"]}
        for name, command in commands.items():
            run = subprocess.run(command, cwd=scratch, env=isolated(scratch), capture_output=True, text=True,
                                 timeout=300)
            errors = [text for text in run.stderr.splitlines() if text.startswith("error: ")]
            assert run.returncode != 0, f"{name} accepted {kind} {dotted(key)}"
            assert "Traceback" not in run.stderr, f"{name}:\n{run.stderr}"
            assert len(errors) == 1 and errors[0].startswith(f"error: params.yaml: {line}"), f"{name}:\n{run.stderr}"
            if name.startswith("bridge"):
                assert run.returncode == 2 and run.stderr.strip() == errors[0], f"{name}:\n{run.stderr}"
    finally:
        (scratch / "params.yaml").write_text(original)
