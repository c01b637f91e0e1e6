"""The Snakefile through Slurm for real: a one-node loopback cluster on this machine (scripts/slurm_local.sh:
slurmctld, slurmd, munge) runs the tiny capture's whole DAG as `snakemake --profile profiles/slurm` submits it
through snakemake-executor-plugin-slurm: every stage a Slurm job that completes, but the report (a local rule).
About 90 s on 2 cores; skipped, saying why, where Slurm cannot be installed or started (not root, no apt-get, no
munge) or the plugin is not installed."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from helpers import ROOT, TINY_DAG, snakemake_command

SCRIPT = ROOT / "scripts" / "slurm_local.sh"
JOBS = ("decode", "poses", "masks", "train", "mesh", "export", "evaluate")  # the report runs here (localrules)
# The tiny jobs fit in less than the profile's defaults, and any machine's node
SMALL = ["--default-resources", "mem_mb=1000", "runtime=10",
         "--set-resources", "train:mem_mb=2000", "export:mem_mb=2000", "evaluate:mem_mb=2000"]


@pytest.fixture(scope="module")
def slurm() -> Path:
    """A running one-node cluster (started here, stopped after, unless it already ran); its state folder."""
    pytest.importorskip("snakemake_executor_plugin_slurm", reason="pip install -e .[cluster]")
    if shutil.which("slurmctld") is None and (os.geteuid() != 0 or shutil.which("apt-get") is None):
        pytest.skip("Slurm is not installed, and installing it needs root and apt-get: apt-get install slurm-wlm munge")
    state = Path(os.environ.get("ORCA_SLURM_DIR", "/tmp/orca-slurm"))
    start = subprocess.run(["bash", str(SCRIPT), "start"], capture_output=True, text=True, timeout=600, check=False)
    if start.returncode != 0:
        pytest.skip(f"scripts/slurm_local.sh start failed: {start.stderr.strip()[-1500:]}")
    yield state
    if start.stdout.strip() == "started":
        subprocess.run(["bash", str(SCRIPT), "stop"], capture_output=True, timeout=120, check=False)


@pytest.mark.slow(seconds=190)
def test_the_tiny_dag_runs_through_slurm(slurm, tiny_capture, tmp_path):
    capture = tmp_path / "captures" / "tiny"
    shutil.copytree(tiny_capture, capture)
    # known cameras and the user's masks, as in test_snakemake.py: 48x36 pixels are too few for SfM and the cues
    shutil.copy(tiny_capture / "ground_truth" / "cameras.json", capture / "cameras.json")
    shutil.copytree(tiny_capture / "ground_truth" / "masks", capture / "masks")
    cluster = ["--profile", str(ROOT / "profiles" / "slurm"), "--slurm-no-account",
               # no accounting database here, so no sacct: squeue knows a job for slurm.conf's MinJobAge after it ends
               "--slurm-status-command", "squeue", "--slurm-init-seconds-before-status-checks", "1",
               "--max-threads", str(os.cpu_count()), *SMALL]
    command = snakemake_command(tmp_path, TINY_DAG, *cluster)
    cores = command.index("--cores")
    del command[cores:cores + 2]  # a cluster run gives no --cores
    run = subprocess.run(command, capture_output=True, text=True, timeout=540, check=False)
    log = run.stdout + run.stderr
    assert run.returncode == 0, log[-4000:]
    submitted = dict(re.findall(r"submitted with SLURM jobid (\d+) \(log: \S*/rule_(\w+)/", log))
    assert sorted(submitted.values()) == sorted(JOBS), log[-4000:]
    assert "localrule report:" in log
    # each job's record in the cluster's job completion log (slurm.conf's JobCompLoc)
    records = (slurm / "jobcomp.log").read_text()
    for job_id, rule in submitted.items():
        states = re.findall(rf"^JobId={job_id} .*JobState=(\w+)", records, re.MULTILINE)
        assert states[-1:] == ["COMPLETED"], (rule, states)
    results = tmp_path / "results" / "tiny"
    for stage in (*JOBS, "report"):
        assert (results / stage / "manifest.json").is_file(), stage
        assert (results / "benchmarks" / f"{stage}.tsv").is_file(), stage
    assert (results / "report" / "report.html").is_file()
