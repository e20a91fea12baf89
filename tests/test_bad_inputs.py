"""Every malformed, hostile or degenerate input of `bad_inputs.corpus()` through every entry point that reads its
kind of file: the readers and data sources in-process, and the stage scripts as subprocesses.

An error case must end, everywhere, in one line naming the offending file (`error: PATH: PROBLEM`, exit status 2
for a stage script, no traceback), with no output and nothing new in the input or output folders (no temporary
`.NAME.*.tmp*` file either). A valid but degenerate case must give finite unit normals. No pickle is ever loaded.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from bad_inputs import (
    CLI,
    ERROR,
    LIST_FILE,
    N_POINTS,
    UNPICKLED,
    VALID,
    Case,
    corpus,
    entry_points,
    expected,
    good_cloud_text,
    good_normals_text,
)

from refinenet import config
from refinenet.data.clouds import CloudSpec, list_clouds, make_cloud
from refinenet.data.io import read_cloud, read_normals
from refinenet.data.meshes import read_mesh
from refinenet.errors import RefineNetError

REPO = Path(__file__).resolve().parents[1]
#: The active profile of params.yaml: what the stage scripts run with.
PARAMS = config.load(REPO / "params.yaml")
#: The smallest neighbourhood a stage needs: the readers are given it as `min_points`, as the stages do.
K = PARAMS.baselines.pca_k
CASES = corpus()
#: Folder names with a space and a non-ASCII letter, so every path given is a hostile one.
INPUTS, OUTPUTS = "input folder", "out put ü"


def _runs(in_process: bool) -> list:
    return [pytest.param(case, entry, id=f"{case.kind}:{case.name}@{entry}".encode("ascii", "replace").decode())
            for case in CASES for entry in entry_points(case) if entry.startswith(("stages.", CLI)) != in_process]


def _root_skipped(case: Case) -> bool:
    return case.root_skip and hasattr(os, "geteuid") and os.geteuid() == 0


def _skip_if_root(case: Case) -> None:
    if _root_skipped(case):
        pytest.skip(f"{case.name}: running as root, which reads files whatever their permissions")


def _listing(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()} if folder.is_dir() else set()


def assert_unit(normals: np.ndarray, what: str) -> None:
    normals = np.asarray(normals, dtype=np.float64)
    assert np.isfinite(normals).all(), f"{what}: NaN or inf normals"
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1, atol=1e-5, err_msg=f"{what}: not unit length")


def assert_cloud(cloud, what: str) -> None:
    assert np.isfinite(cloud.points).all(), f"{what}: NaN or inf points"
    if cloud.normals is not None:
        assert_unit(cloud.normals, what)


# ------------------------------------------------------------------------------------------------------- in-process


def _data(source: str, root: Path, **changes):
    return replace(PARAMS.data, source=source, path=str(root), split_folders={"train": "train", "test": "test"},
                   max_shapes=None, **changes)


def _pcpnet_data(root: Path, list_name: str):
    return _data("pcpnet", root, pcpnet={"train_list": None, "test_lists": {"None": list_name}})


def _made(data, origin: Path | None = None) -> list:
    """The clouds a source makes (only the one from `origin` when given)."""
    specs = list_clouds(data, PARAMS.noise)
    if origin is not None:
        specs = [s for s in specs if s.origin == str(origin)]
        assert specs, f"the source does not list {origin}"
    return [make_cloud(spec, 500, seed=1) for spec in specs]


def _companion(folder: Path, case: Case) -> Path:
    """The cloud a normals case belongs to: STEM.xyz beside it."""
    cloud = folder / f"{Path(case.name).stem}.xyz"
    cloud.write_text(good_cloud_text())
    return cloud


def reader_folder(entry: str, tmp: Path) -> Path:
    """Where `entry` looks for the case: a category folder of a folder source, else the input folder."""
    if entry == "points source":
        return tmp / INPUTS / "test" / "smooth"
    if entry == "meshes source":
        return tmp / INPUTS / "test" / "sharp"
    return tmp / INPUTS


def read_in_process(case: Case, entry: str, folder: Path) -> list:
    """Write the case into `folder` and call `entry` on it; what it returns, as a list."""
    path = case.write(folder)
    if entry == "io.read_cloud":
        return [read_cloud(path, min_points=K)]
    if entry == "points source":
        return _made(_data("points", folder.parents[1]), path)
    if entry == "meshes source":
        return _made(_data("meshes", folder.parents[1]), path)
    if entry == "pcpnet source" and case.kind == "pcpnet":
        return _made(_pcpnet_data(folder, case.name))
    if entry == "pcpnet source":  # a cloud or a normals file named by a list
        if case.kind == "normals":
            _companion(folder, case)
        (folder / LIST_FILE).write_text(Path(case.name).stem + "\n")
        return _made(_pcpnet_data(folder, LIST_FILE))
    if entry == "io.read_normals":
        return [read_normals(path, N_POINTS)]
    if entry == "io.read_cloud (sibling)":
        return [read_cloud(_companion(folder, case), sibling_normals=True)]
    if entry == "meshes.read_mesh":
        return [read_mesh(path)]
    if entry == "config.load":
        return [config.load(path)]
    raise AssertionError(f"unknown entry point {entry}")


def check_result(case: Case, entry: str, results: list) -> None:
    for result in results:
        if entry == "io.read_normals":
            assert_unit(result, case.name)
        elif entry == "meshes.read_mesh":
            vertices, faces = result
            assert np.isfinite(vertices).all() and len(faces) and faces.max() < len(vertices)
        elif entry == "config.load":
            assert isinstance(result, config.Params)
        else:
            assert_cloud(result, case.name)
            if entry.endswith("source"):
                assert result.normals is not None and len(result.normals) == len(result.points)


@pytest.mark.parametrize(("case", "entry"), _runs(in_process=True))
def test_reader(case: Case, entry: str, tmp_path: Path) -> None:
    _skip_if_root(case)
    outcome = expected(case, entry)
    folder = reader_folder(entry, tmp_path)
    try:
        results = read_in_process(case, entry, folder)
    except RefineNetError as err:
        message = str(err)
        assert outcome == ERROR, f"{case.name} should be read at {entry}, but: {message}"
        assert "\n" not in message, f"more than one line: {message!r}"
        assert str(folder / case.offender) in message, f"the error does not name {case.offender}: {message}"
        assert case.problem in message, f"expected {case.problem!r} in {message!r}"
    else:
        assert outcome == VALID, f"{case.name} should be refused at {entry}, but it was read"
        check_result(case, entry, results)
    finally:
        assert not (folder / UNPICKLED).exists(), "a pickle was loaded"


# ----------------------------------------------------------------------------------------------------- subprocesses


def stage(module: str, *args: str | Path) -> subprocess.CompletedProcess:
    command = ["refinenet.cli.main", "normals"] if module == "cli" else [f"stages.{module}"]
    return subprocess.run([sys.executable, "-m", *command, *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, encoding="utf-8", errors="replace", timeout=300)


def _sources_params(tmp: Path, data: dict) -> Path:
    """A params file of the active profile, with the `data` block changed and small sampled clouds."""
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    raw["data"].update(data)
    profile = raw["profiles"][raw["profile"]]
    profile.setdefault("data", {})["n_points"] = 500
    path = tmp / "params.yaml"
    path.write_text(yaml.safe_dump(raw, allow_unicode=True, sort_keys=False))
    return path


def _clouds_job(case: Case, tmp: Path) -> tuple[Path, Path, list]:
    """stages.clouds on a meshes or pcpnet source holding the case: (input folder, path, arguments before --out)."""
    if case.kind == "mesh":
        root = tmp / INPUTS
        folder = root / "test" / "sharp"
        path = case.write(folder)
        params = _sources_params(tmp, {"source": "meshes", "path": str(root)})
        level = PARAMS.noise.levels("test", "SharpFeature")[0]
        key = CloudSpec("test", "SharpFeature", f"{_safe(Path(case.name).stem)}_n{level:.2f}", "", 1.0).key
        return folder, path, ["--params", params, "--cloud", key]
    folder = tmp / INPUTS
    path = case.write(folder)
    params = _sources_params(tmp, {"source": "pcpnet", "path": str(folder),
                                   "pcpnet": {"train_list": None, "test_lists": {"None": case.name}}})
    key = f"test/None/{_safe(Path(case.offender).stem)}"
    if not case.culprit:  # the list itself, or a valid list: its first shape
        names = [n.strip() for n in path.read_text(encoding="utf-8-sig").splitlines() if n.strip()] \
            if path.is_file() and case.expect == VALID else ["shape"]
        key = f"test/None/{_safe(names[0])}"
    return folder, path, ["--params", params, "--cloud", key]


def _safe(name: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9_.+-]", "_", name)


def _stage_job(case: Case, entry: str, tmp: Path) -> tuple[Path, Path, str, list]:
    """(input folder, path of the case, stage module, arguments before --out)."""
    if entry == "stages.clouds":
        folder, path, args = _clouds_job(case, tmp)
        return folder, path, "clouds", args
    folder = tmp / INPUTS
    path = case.write(folder)
    spare = tmp / "spare"
    spare.mkdir()
    good_cloud, good_normals = spare / "good.xyz", spare / "good.normals"
    good_cloud.write_text(good_cloud_text())
    good_normals.write_text(good_normals_text())
    if case.kind == "params":
        return folder, path, "baselines", ["--params", path, "--method", "pca", "--cloud", good_cloud]
    if entry == CLI and case.kind == "normals":  # Refine-Net on a good cloud, refining the case's normals
        return folder, path, "cli", [good_cloud, "--initial", path, "--orient", "none"]
    if entry == CLI:
        return folder, path, "cli", [path, "--method", "pca", "--orient", "none"]
    if entry == "stages.baselines":
        return folder, path, "baselines", ["--method", "pca", "--cloud", path]
    if entry == "stages.mfps":
        return folder, path, "mfps", ["--cloud", path]
    if case.kind == "normals":
        return folder, path, "features", ["--cloud", good_cloud, "--initial", path]
    return folder, path, "features", ["--cloud", path, "--initial", good_normals]


OUT_NAMES = {"baselines": "result.normals", "mfps": "result.npy", "features": "result.npz", "clouds": "result.npz",
             "cli": "result.ply"}


def check_output(module: str, out: Path) -> None:
    if module == "baselines":
        assert_unit(np.loadtxt(out, ndmin=2), str(out))
    elif module == "mfps":
        assert_unit(np.load(out, allow_pickle=False), str(out))
    elif module == "cli":
        assert_cloud(read_cloud(out), str(out))
    else:
        with np.load(out, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files if key != "meta"}
        for key, array in arrays.items():
            assert np.isfinite(array.astype(np.float64)).all(), f"{out}: NaN or inf in {key}"
        if module == "features":
            assert_unit(arrays["nf"].reshape(len(arrays["nf"]), -1, 3), f"{out} nf")
        else:
            assert_unit(arrays["normals"], f"{out} normals")


@dataclass
class StageRun:
    """A stage script started on a case: what it was given, the folders' contents before, and its process."""

    folder: Path
    path: Path
    module: str
    out: Path
    inputs: set[str]
    outputs: set[str]
    process: Future


def _start(case: Case, entry: str, tmp: Path, pool: ThreadPoolExecutor) -> StageRun:
    folder, path, module, args = _stage_job(case, entry, tmp)
    out_dir = tmp / OUTPUTS
    out_dir.mkdir()
    (out_dir / "keep.txt").write_text("an earlier output\n")
    out = out_dir / OUT_NAMES[module]
    inputs, outputs = _listing(folder), _listing(out_dir)
    flag = "-o" if module == "cli" else "--out"
    return StageRun(folder, path, module, out, inputs, outputs, pool.submit(stage, module, *args, flag, out))


@pytest.fixture(scope="module")
def stage_runs(request, tmp_path_factory) -> Iterator[dict[tuple[str, str, str], StageRun]]:
    """Every selected stage run, started ahead of its test and two at a time: a script spends its 1-2 s mostly
    importing, so the file takes half the time on two cores."""
    pool = ThreadPoolExecutor(max_workers=2)
    runs = {}
    for item in request.session.items:
        if getattr(item, "originalname", "") == "test_stage":
            case, entry = item.callspec.params["case"], item.callspec.params["entry"]
            if not _root_skipped(case):
                runs[case.kind, case.name, entry] = _start(case, entry, tmp_path_factory.mktemp("stage"), pool)
    yield runs
    pool.shutdown(cancel_futures=True)


@pytest.mark.parametrize(("case", "entry"), _runs(in_process=False))
def test_stage(case: Case, entry: str, stage_runs) -> None:
    _skip_if_root(case)
    job = stage_runs[case.kind, case.name, entry]
    folder, module, out = job.folder, job.module, job.out
    run = job.process.result()
    assert not (folder / UNPICKLED).exists(), "a pickle was loaded"
    assert _listing(folder) == job.inputs, f"the input folder changed: {_listing(folder) ^ job.inputs}"
    if expected(case, entry) == VALID:
        assert run.returncode == 0, f"{case.name} should work in {module}:\n{run.stderr}"
        assert _listing(out.parent) == job.outputs | {out.name}
        check_output(module, out)
        return
    lines = run.stderr.splitlines()
    assert "Traceback" not in run.stderr, run.stderr
    assert run.returncode == 2, f"exit status {run.returncode}:\n{run.stderr}"
    assert len(lines) == 1 and lines[0].startswith("error: "), f"not one error line:\n{run.stderr}"
    offender = job.path if case.kind == "params" else folder / case.offender
    assert str(offender) in lines[0], f"the error does not name {offender}: {lines[0]}"
    assert case.problem in lines[0], f"expected {case.problem!r} in {lines[0]!r}"
    assert not out.exists(), f"{out} was written"
    assert _listing(out.parent) == job.outputs, f"the output folder changed: {_listing(out.parent)}"
    assert run.stdout == "", f"output on stdout besides the error:\n{run.stdout}"
