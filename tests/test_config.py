"""params.yaml: profiles resolve as documented, and every invalid value is reported by its key."""

import copy
import dataclasses
import typing
from pathlib import Path

import pytest
import yaml

from refinenet import config
from refinenet.errors import ParamsError

REPO = Path(__file__).resolve().parents[1]
RAW = yaml.safe_load((REPO / "params.yaml").read_text())


def resolve(raw):
    return config.resolve(raw)


def with_value(dotted, value):
    raw = copy.deepcopy(RAW)
    *parents, last = dotted.split(".")
    node = raw
    for p in parents:
        node = node[p]
    node[last] = value
    return raw


def test_profiles_override_only_their_keys():
    for name in ("smoke", "cpu", "release", "paper"):
        p = resolve(with_value("profile", name))
        assert p["profile"] == name
        assert p["baselines"] == RAW["baselines"]
    assert resolve(with_value("profile", "paper"))["data"]["n_points"] == 100000
    release, paper = resolve(with_value("profile", "release"))["mfps"], resolve(with_value("profile", "paper"))["mfps"]
    assert (release["scales"], release["theta_t"], release["eta"]) == ([50, 100], 45, "code")
    assert (paper["scales"], paper["theta_t"], paper["eta"]) == ([50, 100, 150], 60, "paper")
    assert resolve(with_value("profile", "smoke"))["data"]["max_shapes"] == 1


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("profile", "fast", "profile: 'fast' is not one of the profiles"),
        ("baselines.pca_k", -3, "baselines.pca_k: -3 is less than the minimum"),
        ("baselines.jet_k", "many", "baselines.jet_k: 'many' is not of type 'integer'"),
        ("data.source", "web", "data.source: 'web' is not one of"),
        ("noise.train", [], "noise.train: [] should be non-empty"),
        ("evaluation.protocol", "mine", "evaluation.protocol"),
        ("profiles.smoke", {"data": {"n_pointz": 5}}, "profiles.smoke.data.n_pointz: overrides a key that does not"),
    ],
)
def test_invalid_values_name_their_key(key, value, message):
    with pytest.raises(ParamsError) as info:
        resolve(with_value(key, value))
    text = str(info.value)
    assert text.startswith("params.yaml: ") and message in text and "\n" not in text


def test_inactive_profile_is_validated_too():
    raw = with_value("profiles.paper", {"baselines": {"pca_kk": 1}})
    with pytest.raises(ParamsError, match="profiles.paper.baselines.pca_kk"):
        resolve(raw)


def test_unreadable_file(tmp_path):
    bad = tmp_path / "params.yaml"
    bad.write_text("profile: [unclosed\n")
    with pytest.raises(ParamsError, match="cannot be read as YAML"):
        config.load(bad)


def test_params_load_into_typed_blocks_from_any_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    params = config.load(REPO / "params.yaml")
    assert params.profile == RAW["profile"]
    assert params.mfps.scales == tuple(RAW["mfps"]["scales"])
    features = params.features
    assert features.n_normals == 9 + (features.pca_k is not None) + (features.jet_k is not None)
    assert params.noise.levels("test", "BigNoise") == RAW["noise"]["test"]["BigNoise"]


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("features.hmp_size", 6, "features.hmp_size: must be odd (a centre bin), got 6"),
        ("mfps.scales", [100, 50], "mfps.scales: must be increasing, got [100, 50]"),
        ("mfps.scales", [50, 50], "mfps.scales: must be increasing, got [50, 50]"),
        ("features.initial", "pcpnet", "features.initial: 'pcpnet' is neither one of ('mfps', 'pca', 'jet') nor an "
                                       "existing folder"),
    ],
)
def test_values_the_schema_cannot_judge_name_their_key(key, value, message):
    with pytest.raises(ParamsError) as info:
        config.Params.from_resolved(resolve(with_value(key, value)))
    assert str(info.value) == f"params.yaml: {message}"


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("training.batch_size", 1, "training.batch_size: 1 is less than the minimum of 2"),
        ("features.hmp_size", 3, "features.hmp_size: 3 is less than the minimum of 5"),
        ("features.r_f", 0, "features.r_f: 0 is less than or equal to the minimum of 0"),
        ("mfps.theta_t", 95, "mfps.theta_t: 95 is greater than the maximum of 90"),
        ("patches.mode", "grid", "patches.mode: 'grid' is not one of ['knn', 'ball']"),
        ("figures.scan_points", 199, "figures.scan_points: 199 is less than the minimum of 200"),
    ],
)
def test_a_bound_has_one_source_and_one_message(key, value, message):
    """The schema holds every range and choice: params that skip `resolve` (a release's) get its message too."""
    with pytest.raises(ParamsError) as checked:
        resolve(with_value(key, value))
    unchecked = resolve(RAW)
    block, field = key.split(".")
    unchecked[block][field] = value
    with pytest.raises(ParamsError) as built:
        config.Params.from_resolved(unchecked)
    assert str(checked.value) == str(built.value) == f"params.yaml: {message}"


def test_a_missing_block_is_named():
    params = resolve(RAW)
    del params["denoise"]
    with pytest.raises(ParamsError, match="^release: denoise: is missing$"):
        config.Params.from_resolved(params, "release")


def test_only_method_constants_and_per_job_values_have_defaults():
    """params.yaml holds every value: a field with a default is a constant of MFPS or set per job (seeds, threads)."""
    blocks = [t for t in typing.get_type_hints(config.Params).values() if dataclasses.is_dataclass(t)]
    with_defaults = {(block.__name__, field.name) for block in blocks for field in dataclasses.fields(block)
                     if field.default is not dataclasses.MISSING}
    constants = ("beta", "hist_bins", "tv_lambda", "flat_tol", "drop_tol", "seed")
    assert with_defaults == {("MFPSConfig", name) for name in constants} | {("TrainConfig", "seed"),
                                                                              ("TrainConfig", "threads")}


def test_a_variant_overrides_the_profile_and_only_its_own_keys():
    smoke = with_value("profile", "smoke")
    full, kc8 = config.resolve(smoke), config.resolve(smoke, variant="kc8")
    assert (full["clustering"]["n_clusters"], kc8["clustering"]["n_clusters"]) == (2, 8)
    reference = config.resolve(smoke, variant="reference")
    assert kc8["training"] == reference["training"]  # the smoke profile's training applies to the variant too
    assert config.resolve(smoke, variant="l1")["training"]["loss"] == "l1"
    assert "variants" not in full and "variant_budget" not in full


def test_the_variant_budget_reaches_every_variant_and_reference_but_not_full():
    """The smoke profile's budget (1 epoch, 500 scored points) applies under each variant's own overrides; with no
    budget, reference is full as written."""
    smoke = with_value("profile", "smoke")
    every = config.resolve_variants(smoke)
    assert (every["full"]["training"]["max_epochs"], every["full"]["inference"]["points"]) == (2, None)
    for name in ("reference", "l1", "kc8", "seed2023"):
        assert (every[name]["training"]["max_epochs"], every[name]["inference"]["points"]) == (1, 500), name
    smoke["variants"]["l1"] = {"training": {"loss": "l1", "max_epochs": 3}}
    assert config.resolve(smoke, variant="l1")["training"]["max_epochs"] == 3  # a variant's own override wins
    smoke["profiles"]["smoke"]["variant_budget"] = {}
    assert config.resolve(smoke, variant="reference") == config.resolve(smoke)


def test_a_bad_variant_budget_or_a_variant_named_reference_is_reported_by_its_key():
    for budget, message in [({"data": {"n_points": 10}}, "variant_budget.data: a variant may override only"),
                            ({"inference": {"points": 0}}, "variant_budget.inference.points: 0 is less than")]:
        raw = copy.deepcopy(RAW)
        raw["variant_budget"] = budget
        with pytest.raises(ParamsError, match=message):
            config.resolve(raw)
    raw = copy.deepcopy(RAW)
    raw["variants"]["reference"] = {}
    with pytest.raises(ParamsError, match="variants.reference: is reserved"):
        config.resolve(raw)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"data": {"n_points": 10}}, "params.yaml: variants.bad.data: a variant may override only seed, features,"),
        ({"training": {"los": "l1"}}, "params.yaml: variants.bad.training.los: overrides a key that does not exist"),
        ({"training": {"loss": "l3"}}, "params.yaml: variants.bad.training.loss: 'l3' is not one of ['mse', 'l1']"),
    ],
)
def test_a_bad_variant_is_reported_by_its_key(overrides, message):
    raw = copy.deepcopy(RAW)
    raw["variants"]["bad"] = overrides
    with pytest.raises(ParamsError) as err:
        config.resolve(raw)
    assert str(err.value).startswith(message), str(err.value)


def test_a_variant_name_is_checked():
    for name in ("full", "Kc-2"):
        raw = copy.deepcopy(RAW)
        raw["variants"][name] = {}
        with pytest.raises(ParamsError, match="variants"):
            config.resolve(raw)
    with pytest.raises(ParamsError, match="no variant 'nope'"):
        config.resolve(RAW, variant="nope")
