"""The Snakefile's configuration: config/config.yaml is exactly the defaults of its schema
(config/schema/config.schema.yaml, which the Snakefile checks with snakemake.utils.validate), the schema's presets
are the stages' (pipeline/presets/), bad values are refused, and a plan for the Slurm profile (no --cores) gives
train the GPUs a config file asks for."""

from __future__ import annotations

import copy
import shutil
import subprocess
import sys

import pytest
import yaml
from helpers import ROOT

from pipeline import layout
from pipeline.config import PRESETS, load_config

SCHEMA = ROOT / "config" / "schema" / "config.schema.yaml"
CONFIG = ROOT / "config" / "config.yaml"


def validated(config: dict) -> dict:
    """``config`` with the schema's defaults filled in (a copy); raises WorkflowError when the schema refuses it."""
    from snakemake.utils import validate

    filled = copy.deepcopy(config)
    validate(filled, str(SCHEMA))
    return filled


def test_config_yaml_is_the_schemas_defaults():
    config = yaml.safe_load(CONFIG.read_text())
    assert validated({}) == config  # a --configfile of a few keys runs as config.yaml would for the rest
    assert validated(config) == config
    assert config["results_dir"] == str(layout.RESULTS)
    # a partial resources section keeps the other defaults
    partial = validated({"resources": {"train": {"gpu": 1}}})["resources"]
    assert partial["train"] == {**config["resources"]["train"], "gpu": 1}
    assert partial["export"] == config["resources"]["export"]


def test_the_schemas_presets_are_the_stages_presets():
    schema = yaml.safe_load(SCHEMA.read_text())
    assert sorted(schema["properties"]["preset"]["enum"]) == sorted(PRESETS)
    for preset in PRESETS:
        load_config(preset=preset)
    # what the schema takes as `set` the stages' configuration reads
    load_config(preset="fast", overrides=validated({"set": ["train.iterations=500", "masks.rounds=2"]})["set"])


@pytest.mark.parametrize("config", [
    {"capture": ["demo"]},                               # not a key
    {"preset": "turbo"},                                 # not a preset
    {"set": ["train.iterations"]},                       # an override without a value
    {"captures": []},
    {"resources": {"train": {"gpu": -1}}},
    {"resources": {"train": {"gpus": 1}}},               # the plugin's resource is `gpu`
    {"resources": {"mesh": {"mem_mb": 1000}}},           # only train, export and evaluate ask for more
], ids=str)
def test_the_schema_refuses(config):
    from snakemake_interface_common.exceptions import WorkflowError

    with pytest.raises(WorkflowError, match="Error validating config"):
        validated(config)


def test_a_slurm_plan_without_cores_gives_train_its_gpu(tiny_capture, tmp_path):
    """`threads: workflow.cores` raised without --cores, which a cluster run does not give."""
    pytest.importorskip("snakemake_executor_plugin_slurm", reason="pip install -e .[cluster]")
    capture = tmp_path / "captures" / "tiny"
    capture.mkdir(parents=True)
    for dng in tiny_capture.glob("*.dng"):
        shutil.copy(dng, capture)
    gpu = tmp_path / "gpu.yaml"
    gpu.write_text("resources:\n  train: {gpu: 1}\n")
    plan = subprocess.run(
        [sys.executable, "-m", "snakemake", "-n", "--profile", str(ROOT / "profiles" / "slurm"), "--slurm-no-account",
         "--snakefile", str(ROOT / "Snakefile"), "--directory", str(tmp_path), "--configfile", str(gpu),
         "--config", 'captures=["tiny"]'],
        capture_output=True, text=True, timeout=300, check=False)
    out = plan.stdout + plan.stderr
    assert plan.returncode == 0, out[-3000:]
    rules = {block.split(":", 1)[0]: block for block in out.split("\nrule ")[1:]}
    assert {"decode", "poses", "masks", "train", "mesh", "export", "report"} <= set(rules), out[-3000:]
    assert "gpu=1" in rules["train"] and "runtime=240" in rules["train"], rules["train"]
    assert "gpu=0" in rules["export"] and "gpu=" not in rules["mesh"]
