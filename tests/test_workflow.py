"""Snakemake and DVC describe the same pipeline: generated dvc.yaml is current, rules and code match."""

import json
import subprocess
import sys
from pathlib import Path

import yaml

from refinenet import workflow

REPO = Path(__file__).resolve().parents[1]


def test_dvc_yaml_is_generated_from_the_step_declarations():
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    assert (REPO / "dvc.yaml").read_text() == workflow.render_dvc_yaml(raw), "run `python -m refinenet.workflow`"


def test_dvc_stages_list_profile_overrides_of_their_keys():
    raw = yaml.safe_load((REPO / "params.yaml").read_text())
    keys = workflow.tracked_keys(raw, workflow.STEPS["test_clouds"])
    assert {"profile", "data", "profiles.smoke.data", "profiles.cpu.data"} <= set(keys)
    assert "profiles.smoke.data" not in workflow.tracked_keys(raw, workflow.STEPS["baselines"])


def test_every_step_has_a_snakemake_rule():
    listed = subprocess.run([sys.executable, "-m", "snakemake", "--list-rules"], cwd=REPO,
                            capture_output=True, text=True, check=True).stdout.split()
    assert {s.rule for s in workflow.STEPS.values()} <= set(listed)


def test_steps_declare_every_library_module_their_script_imports():
    """A module missing from a step's code deps would let a code change go unnoticed by both tools."""
    for step in workflow.STEPS.values():
        module = step.script.removesuffix(".py").replace("/", ".")
        probe = (f"import importlib, json, sys; importlib.import_module('{module}'); "
                 "print(json.dumps(sorted(m for m in sys.modules if m.startswith('refinenet.'))))")
        out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True)
        imported = {m.removeprefix("refinenet.") for m in json.loads(out.stdout)}
        assert imported <= set(step.modules), f"{step.stage}: undeclared {imported - set(step.modules)}"
        for path in step.code:
            assert (REPO / path).is_file(), path


def test_snakemake_lint_is_clean():
    lint = subprocess.run([sys.executable, "-m", "snakemake", "--lint"], cwd=REPO, capture_output=True, text=True)
    assert lint.returncode == 0 and "Congratulations" in lint.stdout + lint.stderr, lint.stderr[-3000:]
