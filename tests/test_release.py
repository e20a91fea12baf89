"""A release's format: an export writes the present one with every setting, an older one loads through the explicit
mappings of what it lacks (`release.FORMAT_1`, `FORMAT_2`), and one this version cannot read is a one-line error."""

import json

import pytest
import torch

from refinenet.errors import InputError, ParamsError
from refinenet.network.release import FORMAT, FORMAT_1, FORMAT_2, SHIPPED, export, load_release


@pytest.fixture(scope="module")
def shipped():
    """The shipped bundle with the networks of one cluster (enough to build one), and its model card."""
    bundle = torch.load(SHIPPED / "networks.pt", weights_only=True)
    bundle["networks"] = dict(list(bundle["networks"].items())[:1])
    return bundle, json.loads((SHIPPED / "model_card.json").read_text())


def write(folder, bundle, card):
    folder.mkdir(exist_ok=True)
    torch.save(bundle, folder / "networks.pt")
    (folder / "model_card.json").write_text(json.dumps(card))
    return folder


def without(bundle, settings):
    """`bundle` whose params (and network description, for `network`) lack the given settings."""
    params, network = json.loads(bundle["params"]), json.loads(bundle["network"])
    for block, keys in settings.items():
        for key in keys:
            params[block].pop(key, None)
        if not params[block]:
            del params[block]
    for key in settings.get("network", ()):
        network.pop(key, None)
    return {**bundle, "params": json.dumps(params), "network": json.dumps(network, sort_keys=True)}


def test_the_shipped_release_is_of_format_1_and_keeps_its_own_settings(shipped):
    """FORMAT_1 fills only what a release lacks: the shipped one stores every setting, some unlike FORMAT_1's."""
    bundle, _ = shipped
    assert bundle["format"] == 1
    release = load_release(with_networks=False)
    stored = json.loads(bundle["params"])
    assert (release.params.network.output, release.params.features.smooth_jet) == (stored["network"]["output"],
                                                                                   stored["features"]["smooth_jet"])
    assert (release.params.network.output, release.params.features.smooth_jet) != ("normal", None)


def test_a_format_1_release_loads_the_settings_it_lacks_with_their_format_1_values(tmp_path, shipped):
    bundle, card = shipped
    folder = write(tmp_path / "old", without(bundle, FORMAT_1), card)
    release = load_release(folder)
    for block, values in FORMAT_1.items():
        typed = getattr(release.params, block)
        assert {key: getattr(typed, key) for key in values} == {k: tuple(v) if isinstance(v, list) else v
                                                                for k, v in values.items()}, block
    assert [net.config.output for net in release.networks.values()] == ["normal"]


def test_a_format_2_release_loads_without_training_meshes(tmp_path, shipped):
    bundle, card = shipped
    folder = write(tmp_path / "old", {**without(bundle, FORMAT_2), "format": 2}, card)
    assert load_release(folder, with_networks=False).params.data.train_meshes is None


def test_an_export_writes_the_present_format_with_every_setting(tmp_path, shipped):
    bundle, card = shipped
    release = load_release(with_networks=False)
    params = json.loads(bundle["params"])
    params["data"] |= FORMAT_2["data"]
    export(tmp_path, params, release.cluster_model, {0: bundle["networks"]["0"]}, bundle["network"], card)
    written = torch.load(tmp_path / "networks.pt", weights_only=True)
    assert written["format"] == FORMAT == 3
    assert load_release(tmp_path, with_networks=False).params == release.params
    # From format 3 nothing is filled in: a setting missing from such a release is an error naming it.
    write(tmp_path, without(written, {"training": ["precision"]}), card)
    with pytest.raises(ParamsError) as info:
        load_release(tmp_path, with_networks=False)
    assert str(info.value) == f"{tmp_path / 'networks.pt'}: training: 'precision' is a required property"


@pytest.mark.parametrize(("format_", "problem"), [
    (FORMAT + 1, f"a release of format {FORMAT + 1}, newer than this refinenet reads (1 to {FORMAT})"),
    (None, "not a Refine-Net release (it has no format)"),
    (0, "not a Refine-Net release (it has no format)"),
])
def test_a_format_this_version_cannot_read_is_one_line(tmp_path, shipped, format_, problem):
    bundle, card = shipped
    folder = write(tmp_path, {**bundle, "format": format_}, card)
    with pytest.raises(InputError) as info:
        load_release(folder)
    assert str(info.value) == f"{folder / 'networks.pt'}: {problem}"
