"""Snakemake and DVC describe the same pipeline: generated dvc.yaml is current, rules and code match."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from refinenet.errors import ParamsError
from refinenet.pipeline import bridge, captions, catalogue, dvc, steps, variants, workflow
from refinenet.pipeline.methods import REFINENET, figure_name, refinenet

REPO = Path(__file__).resolve().parents[1]
PIPELINE = workflow.Pipeline(yaml.safe_load((REPO / "params.yaml").read_text()))
STEPS = PIPELINE.steps
#: The floors of the library, bottom to top: a module may import only from its own floor and those below.
#: The modules below every floor, which any module may import.
GROUND = ("config", "errors", "atomic", "interrupts", "threads", "allocator", "profiling")
FLOORS = ("config", "data", "geometry", "estimators", "features", "evaluation", "network", "pipeline", "cli")
PACKAGES = {"data", "geometry", "estimators", "features", "evaluation", "network", "pipeline", "cli"}


def test_local_runs_select_jobs_only_when_a_job_ends(tmp_path):
    """Snakemake's job-rate limiter adds a job-selection pass per timer on top of one per job end, and its timers pile
    up (on the full set Snakemake held 52% of a core); the workflow's onstart hook drops it. 8 one-second jobs on
    2 cores: with the hook at most one pass per job leaves jobs waiting, without it the timers add more."""
    jobs = ('rule all:\n    input: expand("out/{i}", i=range(8))\n'
            'rule wait:\n    output: "out/{i}"\n    shell: "sleep 1; touch {output}"\n')

    def passes(head: str) -> int:
        run = tmp_path / str(len(head))
        run.mkdir()
        (run / "Snakefile").write_text(head + jobs)
        log = subprocess.run([sys.executable, "-m", "snakemake", "-j2", "--verbose"], cwd=run,
                             capture_output=True, text=True, check=True)
        assert len(list((run / "out").iterdir())) == 8
        return (log.stdout + log.stderr).count("Ready jobs:")

    assert passes(f'include: "{REPO / "workflow/rules/scheduling.smk"}"\n') <= 8
    assert passes("") > 8


def test_dvc_yaml_is_generated_from_the_step_declarations():
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    assert (REPO / "dvc.yaml").read_text() == dvc.render_dvc_yaml(raw), "run python -m refinenet.pipeline.dvc"


def test_a_params_edit_that_drops_a_tracked_key_leaves_dvc_lock_alone_with_one_line(tmp_path, monkeypatch, capsys):
    """`variant_budget: {}` (the seed-spread recipe) removes keys dvc.yaml tracks: after Snakemake's run, the record
    step says how to regenerate dvc.yaml instead of DVC's traceback and a failed run; regenerated, it is current."""
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    assert raw["profiles"]["cpu"]["variant_budget"], "the cpu profile no longer has a variant budget to drop"
    raw["profiles"]["cpu"]["variant_budget"] = {}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(raw))
    (tmp_path / "dvc.yaml").write_text((REPO / "dvc.yaml").read_text())
    (tmp_path / ".dvc").mkdir()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(bridge.shutil, "which", lambda name: name)
    monkeypatch.setattr(bridge, "up_to_date_files", lambda: pytest.fail("recorded against a stale dvc.yaml"))
    assert bridge.main(["record"]) == 0
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "python -m refinenet.pipeline.dvc" in err
    assert not (tmp_path / "dvc.lock").exists()
    assert dvc.main(["--check"]) == 1
    assert dvc.main([]) == 0 and dvc.main(["--check"]) == 0
    assert "profiles.cpu.variant_budget.training" not in (tmp_path / "dvc.yaml").read_text()


def test_dvc_stages_list_profile_overrides_of_their_keys():
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    keys = steps.tracked_keys(raw, STEPS["clouds_test"])
    assert {"profile", "data", "profiles.smoke.data", "profiles.cpu.data"} <= set(keys)
    assert "profiles.smoke.data" not in steps.tracked_keys(raw, STEPS["baselines"])


def test_every_step_is_one_snakemake_rule_of_the_same_name():
    listed = subprocess.run([sys.executable, "-m", "snakemake", "--list-rules"], cwd=REPO,
                            capture_output=True, text=True, check=True).stdout.split()
    assert set(listed) == {*STEPS, "all", "main"}
    for step in STEPS.values():
        assert step.family in step.name.split("_") or step.name.startswith(f"{step.family}_"), step.name


def test_the_slurm_profile_sizes_existing_rules_and_leaves_gpus_to_the_rules():
    """A renamed step must not leave the cluster profile sizing a rule that no longer exists; GPU requests follow
    the params' device in the rules (a static profile cannot)."""
    profile = yaml.safe_load((REPO / "workflow/profiles/slurm/config.yaml").read_text())
    assert profile["executor"] == "slurm"
    sized = profile["set-resources"]
    assert {"features", "training", "inference"} <= set(sized) <= set(STEPS)
    assert all({"mem_mb", "runtime"} == set(res) for res in sized.values()), sized
    assert (steps.gpus("cpu"), steps.gpus("auto"), steps.gpus("cuda")) == (0, 1, 1)


def test_steps_declare_every_library_module_their_script_imports():
    """A module missing from a step's code deps would let a code change go unnoticed by both tools."""
    for step in {step.family: step for step in STEPS.values()}.values():
        module = f"stages.{step.family}"
        probe = (f"import importlib, json, sys; importlib.import_module('{module}'); "
                 "print(json.dumps(sorted(m for m in sys.modules if m.startswith('refinenet.'))))")
        out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True)
        imported = {m.removeprefix("refinenet.") for m in json.loads(out.stdout)} - PACKAGES
        assert imported <= set(step.modules), f"{step.name}: undeclared {imported - set(step.modules)}"
        for path in step.code:
            assert (REPO / path).is_file(), path


def test_snakemake_lint_is_clean():
    lint = subprocess.run([sys.executable, "-m", "snakemake", "--lint"], cwd=REPO, capture_output=True, text=True)
    assert lint.returncode == 0 and "Congratulations" in lint.stdout + lint.stderr, lint.stderr[-3000:]


def floor(module: str) -> int:
    top = module.split(".")[0]
    return 0 if top in GROUND else FLOORS.index(top)


def test_no_module_imports_a_higher_floor():
    """Data flows one way: e.g. the estimators never import the network, the network never the pipeline."""
    pattern = re.compile(r"^\s*from refinenet\.([\w.]+) import|^\s*import refinenet\.([\w.]+)", re.M)
    for path in (REPO / "src/refinenet").rglob("*.py"):
        module = ".".join(path.relative_to(REPO / "src/refinenet").with_suffix("").parts)
        if module == "__init__" or module.endswith("__init__"):
            continue
        for match in pattern.finditer(path.read_text()):
            imported = match.group(1) or match.group(2)
            assert floor(imported) <= floor(module), f"{module} imports the higher floor {imported}"


def test_each_job_command_names_its_own_method_and_table(tmp_path):
    """Rules defined in a loop format their command when the job runs: a loop variable used there would name the
    last method or table for every job. Checked on the dry run's printed commands."""
    dry = subprocess.run([sys.executable, "-m", "snakemake", "-n", "-p", "--forceall"], cwd=REPO, capture_output=True,
                         text=True, check=True).stdout
    commands = [line for line in dry.splitlines() if "python -m stages." in line]
    normals = re.compile(r"--method (\w+) .*--out results/normals/(\w+)/")
    tables = re.compile(r"stages\.table --table (\w+)")
    methods = [normals.search(c).groups() for c in commands if "--method" in c]
    assert {m for m, _ in methods} == {"pca", "jet"}
    assert all(method == folder for method, folder in methods)
    mfps = re.compile(r"--cloud results/clouds/(\S+)\.npz --out results/normals/mfps/(\S+)\.npy"
                      r"(?: --simple-out results/normals/simple_mfps/(\S+)\.npy)? ")
    outs = [mfps.search(c).groups() for c in commands if "stages.mfps" in c]
    assert len(outs) == len(PIPELINE.keys())
    assert all(cloud == out and (simple == cloud if cloud.startswith("test/") else simple is None)
               for cloud, out, simple in outs)
    assert sorted(tables.search(c).group(1) for c in commands if "stages.table" in c) == sorted(catalogue.TABLES)


#: What Snakemake fills a shell command with when a job runs; any other name is the Snakefile's global, read then.
JOB_NAMES = {"input", "output", "params", "wildcards", "threads", "resources", "log", "benchmark"}
SHELL_LINE = re.compile(r'^\s*(f?)"(.*)"\s*$')


def shell_placeholders(text: str) -> list[str] | None:
    """The names a rule file's shell commands are formatted with at job time (`{name}` in a plain string, `{{name}}`
    in an f-string), or None when a `shell:` is not followed by string literals this check can read."""
    lines, names = text.splitlines(), []
    for i, line in enumerate(lines):
        if not re.match(r"^\s*shell:\s*$", line):
            continue
        literals = [SHELL_LINE.match(rest) for rest in lines[i + 1:]]
        literals = [m.groups() for m in literals[:next((k for k, m in enumerate(literals) if not m), None)]]
        if not literals:
            return None
        for is_f, body in literals:
            names += re.findall(r"\{\{(\w+)", body) if is_f else re.findall(r"(?<!\{)\{(\w+)", body)
    return names


def test_shell_commands_name_only_what_a_job_fills_in():
    """A rule defined in a loop formats its shell command when its job runs, after the loop has ended: a loop variable
    named there gives every job the last value (the mfps rule's --simple-out once did, and the dry run printed the
    right command, so the test above could not see it). What differs between a loop's rules reaches the command as a
    param, so a command may name only the job's own attributes."""
    assert shell_placeholders('    shell:\n        "stages.mfps {input.cloud} {simple_out} {{x}}"\n') == [
        "input", "simple_out"]
    for path in [REPO / "workflow/Snakefile", *(REPO / "workflow/rules").glob("*.smk")]:
        names = shell_placeholders(path.read_text())
        assert names is not None, f"{path.name}: a shell command this test cannot read"
        assert set(names) <= JOB_NAMES, f"{path.name}: shell command names {set(names) - JOB_NAMES}"


def test_a_variant_recomputes_only_the_steps_its_overrides_reach():
    """l1 changes the loss: its own networks and normals, full's features and clusters. kc2 changes Kc: its own
    clusters too. A variant of the features owns every step."""
    assert PIPELINE.owners["l1"] == {"features": "full", "clustering": "full", "training": "l1", "inference": "l1"}
    assert PIPELINE.owners["kc2"] == {"features": "full", "clustering": "kc2", "training": "kc2", "inference": "kc2"}
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    raw["variants"]["wide"] = {"features": {"r_f": 0.05}}
    assert set(variants.owners(raw, "wide").values()) == {"wide"}
    assert "features_wide" in workflow.Pipeline(raw).steps
    assert {"training_l1", "inference_l1"} <= set(STEPS) and not {"features_l1", "clustering_l1"} & set(STEPS)
    assert STEPS["training_l1"].deps == ("results/clouds/train", "results/features/full/train",
                                         "results/clusters/full")
    assert "variants.l1.training" in steps.tracked_keys(raw, STEPS["training_l1"])
    assert not any(k.startswith("variants") for k in steps.tracked_keys(raw, STEPS["training"]))


def test_the_tables_of_variants_compare_them_with_full_under_the_same_budget():
    """The cpu profile's budget (2 epochs, 2,500 scored points) makes reference, full's settings under it, a trained
    variant of its own: the Refine-Net row of every table of variants (table_loss's rows are both variants, L1 and
    L2, whichever loss full has), scored like them on one subset, which the main tables are not. With no budget
    written anywhere, reference is full and trains nothing."""
    assert PIPELINE.owners["reference"] == {"features": "full", "clustering": "full", "training": "reference",
                                            "inference": "reference"}
    assert catalogue.TABLES["table_loss"].methods == (refinenet("l1"), refinenet("l2"))
    for name in ("table_ablation", "table_loss", "table_initial", "table_clusters", "table_seeds"):
        table = catalogue.TABLES[name]
        assert name == "table_loss" or refinenet("reference") in table.methods, name
        assert REFINENET not in table.methods, name
        assert PIPELINE.scored_subset(table.methods) == 2500, name
        caption = captions.caption(PIPELINE, table)
        assert "Every row scored on the same seeded 2500 points" in caption, name
        # The rows were trained as reference is, 2 epochs, not full's 6, whether or not reference is a row.
        assert "<= 2 epochs" in caption and "under the variant budget: training.max_epochs = 2" in caption, name
    loss = captions.caption(PIPELINE, catalogue.TABLES["table_loss"])
    assert "l1: nothing (the settings above); l2: training.loss = mse." in loss
    assert PIPELINE.scored_subset(catalogue.TABLES["table_synthetic"].methods) is None
    for step in ("training_l1", "training_reference", "training_kc2"):
        assert "profiles.cpu.variant_budget.training" in steps.tracked_keys(PIPELINE.raw, STEPS[step]), step
    assert "profiles.smoke.variant_budget.inference" in steps.tracked_keys(PIPELINE.raw, STEPS["inference_l1"])
    assert not any("variant_budget" in k for k in steps.tracked_keys(PIPELINE.raw, STEPS["training"]))
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    for block in raw["profiles"].values():
        block.pop("variant_budget", None)
    unbudgeted = workflow.Pipeline(raw)
    assert set(unbudgeted.owners["reference"].values()) == {"full"} and "training_reference" not in unbudgeted.steps
    assert unbudgeted.normals_path(refinenet("reference"), "test/a") == unbudgeted.normals_path("refinenet",
                                                                                                        "test/a")
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    raw["variants"]["l1"]["inference"] = {"points": 100}  # against l2's 2,500
    with pytest.raises(ParamsError, match=r"table_loss: its Refine-Net variants refine subsets of different sizes"):
        workflow.Pipeline(raw)


def test_a_wide_pca_input_is_a_variant_of_the_features_on_mfps_normals():
    """pca_input adds a K = 100 PCA normal to MFPS's inputs: every per-variant step its own, full's MFPS normals
    read, one more normal per point for its networks (X = 10 over the paper's 9, 11 with the profile's K = 50 jet)."""
    assert set(PIPELINE.owners["pca_input"].values()) == {"pca_input"}
    assert STEPS["features_pca_input"].deps == STEPS["features"].deps
    for features in (PIPELINE.params["pca_input"].features, PIPELINE.full.features):
        assert features.n_normals == 9 + (features.pca_k is not None) + (features.jet_k is not None)
    assert PIPELINE.params["pca_input"].features.pca_k == 100


def test_refining_another_estimator_trains_on_its_normals(tmp_path):
    """pca_init refines PCA's normals: its features start from them (so every per-variant step is its own), and PCA
    runs on the training clouds too, a step of its own that exists only while some variant needs it. A folder of
    normals from any estimator stands in for the estimator; a missing one is reported under the variant's key."""
    assert set(PIPELINE.owners["pca_init"].values()) == {"pca_init"}
    assert STEPS["features_pca_init"].deps == ("results/clouds/train", "results/clouds/test",
                                               "results/normals/pca/train", "results/normals/pca/test")
    assert STEPS["features"].deps[2:] == ("results/normals/mfps/train", "results/normals/mfps/test")
    assert (STEPS["baselines"].split, STEPS["baselines_train"].split) == ("test", "train")
    assert STEPS["baselines_train"].outs == ("results/normals/pca/train", "results/normals/jet/train")
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    del raw["variants"]["pca_init"], raw["variants"]["jet_init"]
    raw["variants"]["mine"] = {"features": {"initial": str(tmp_path)}}
    with pytest.raises(ParamsError, match="table_initial needs the variant 'pca_init'"):
        workflow.Pipeline(raw)
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(catalogue.TABLES, "table_initial", catalogue.Table((refinenet("mine"),), ("mean",), "mine"))
        pipeline = workflow.Pipeline(raw)
        assert "baselines_train" not in pipeline.steps
        assert pipeline.initial_path("mine", "test/SharpFeature/a") == f"{tmp_path}/test/SharpFeature/a.normals"
        assert pipeline.steps["features_mine"].deps[2:] == (f"{tmp_path}/train", f"{tmp_path}/test")
        raw["variants"]["mine"]["features"]["initial"] = str(tmp_path / "absent")
        with pytest.raises(ParamsError, match=r"variants\.mine\.features\.initial: '.*absent' is neither one of"):
            workflow.Pipeline(raw)


def test_the_pipeline_is_the_same_whichever_profile_is_active():
    """Which files a variant owns follows the keys it overrides, not their values: dvc.yaml needs no regeneration
    when a user switches profile (in smoke kc2 equals full's Kc and is still a step of its own)."""
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    for profile in ("smoke", "paper"):
        assert dvc.render_dvc_yaml({**raw, "profile": profile}) == dvc.render_dvc_yaml(raw)


def test_a_table_needs_its_variants():
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    del raw["variants"]["l1"]
    with pytest.raises(ParamsError, match="table_loss needs the variant 'l1'"):
        workflow.Pipeline(raw)


def test_a_variant_only_a_figure_shows_gets_the_steps_that_figure_needs():
    """x8 (X = 8) serves the scans alone (fig_real, table_scans): its features of the training clouds, clusters
    and networks, no test-cloud features or inference. A variant asked for in the normals figure gets its
    test-cloud normals and a column; an unknown one is reported under `figures.variants`. fig_real shows the
    simulated scans, or the folder `figures.scans` names."""
    assert {"features_x8", "clustering_x8", "training_x8"} <= set(STEPS) and "inference_x8" not in STEPS
    assert STEPS["features_x8"].outs == ("results/features/x8/train",) and STEPS["features_x8"].split == "train"
    assert all(t.startswith("results/features/x8/train/") for t in STEPS["features_x8"].targets())
    assert STEPS["fig_real"].deps == ("results/scans", "results/clouds/train", "results/clusters/x8",
                                      "results/models/x8")
    assert STEPS["table_scans"].deps == ("results/scans", "results/release", "results/clouds/train",
                                         "results/clusters/x8", "results/models/x8")
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    raw["figures"]["variants"] = ["x8", "l1"]
    pipeline = workflow.Pipeline(raw)
    assert "inference_x8" in pipeline.steps
    assert pipeline.figure_methods()[-2:] == ("refinenet/x8", "refinenet/l1")
    fig = pipeline.steps["fig_normals"]
    assert {"results/normals/refinenet/x8/test", "results/normals/refinenet/l1/test"} <= set(fig.deps)
    assert {"figures.variants", "variants.x8", "variants.l1"} <= set(steps.tracked_keys(raw, fig))
    assert figure_name("refinenet/l1") == "Refine-Net l1"
    raw["figures"]["variants"] = ["nope"]
    with pytest.raises(ParamsError, match="figures.variants.*'nope' is not a variant"):
        workflow.Pipeline(raw)
    raw["figures"].update(variants=[], scans="my/scans")
    pipeline = workflow.Pipeline(raw)
    assert pipeline.steps["fig_real"].deps[0] == "my/scans" and pipeline.steps["table_scans"].deps[0] == "results/scans"
    raw["scanner"]["shapes"] = ["teapot"]
    with pytest.raises(ParamsError, match="scanner.shapes: 'teapot' is not a shape of the catalogue"):
        workflow.Pipeline(raw)
