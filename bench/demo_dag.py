"""The demo through the whole DAG, stage by stage, with its quality figures, against a baseline commit.

    python bench/demo_dag.py                               # HEAD's DAG on the demo capture
    python bench/demo_dag.py --baseline 30a1e36            # + the baseline's training speed, same machine
    python bench/demo_dag.py --baseline 30a1e36 --baseline-dag   # + the baseline's whole DAG (about an hour)

Renders the demo capture into --work if it is not there (timed: set-up, not pipeline), runs `snakemake` on a
fresh results folder, and reads Snakemake's benchmark files (seconds and peak memory per stage) and
evaluate.json (normals, combined PSNR, environment views, props depth). The baseline runs from a `git worktree`
of its commit: this tree's `bench/train_speed.py` on its code (the fast preset's seconds per iteration, times its
iterations) and, with --baseline-dag, its own Snakefile on the same capture. The same benchmark runs on HEAD's
code beside it, so the training ratio compares two measurements taken minutes apart on one machine. Prints a
table and appends a JSON line to bench/results/demo_dag.jsonl.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch

from bench.blowtorch import ROOT, append_record, commit, machine  # noqa: E402
from bench.blowtorch_dag import STAGES, stage_costs  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "demo_dag.jsonl"
CAPTURE = "demo"
TRAIN_SPEED_STEPS = 10


def run(cmd: list[str], cwd: Path, log: Path, env: dict[str, str] | None = None) -> float:
    """Run ``cmd`` in ``cwd`` with its output in ``log``; seconds taken. Raises on failure, naming the log."""
    t0 = time.perf_counter()
    with open(log, "w", encoding="utf-8") as out:
        done = subprocess.run(cmd, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, env=env, check=False)
    if done.returncode:
        raise SystemExit(f"{' '.join(cmd[:4])} ... failed ({done.returncode}); see {log}")
    return time.perf_counter() - t0


def object_figures(evaluate: dict[str, Any]) -> dict[str, float | None]:
    """The object's figures of merit in an evaluate.json: normals, mask, PSNRs and the mesh's distances."""
    obj, mesh = evaluate["object"]["mean"], evaluate.get("mesh") or {}
    return {"normals_deg": obj.get("normal_mae_deg"), "mask_iou": obj.get("mask_iou"),
            "psnr_combined_db": obj.get("psnr_rgb"), "psnr_combined_srgb_db": obj.get("psnr_srgb_rgb"),
            "psnr_diffuse_db": obj.get("psnr_diffuse"), "psnr_specular_db": obj.get("psnr_specular"),
            "chamfer_fraction": mesh.get("chamfer_fraction"), "hausdorff_fraction": mesh.get("hausdorff_fraction")}


def quality(results: Path) -> dict[str, float | None]:
    """The demo's figures of merit from evaluate.json (the issue's quality bar)."""
    evaluate = json.loads((results / "evaluate" / "evaluate.json").read_text(encoding="utf-8"))
    env = evaluate["environment"]["mean"]
    return {**object_figures(evaluate), "env_psnr_db": env.get("psnr"),
            "env_depth_absrel_props": env.get("prop_depth_absrel")}


def dag(repo: Path, capture_dir: Path, results_dir: Path, cores: int, sets: list[str], log: Path) -> dict[str, Any]:
    """Snakemake's whole DAG of ``repo`` on ``capture_dir/demo`` into ``results_dir``."""
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(repo / "Snakefile"), "--directory", str(repo),
           "--cores", str(cores), "--config", f"captures_dir={capture_dir}", f"captures=['{CAPTURE}']",
           f"results_dir={results_dir}"]
    if sets:
        cmd.append("set=[" + ",".join(f"'{s}'" for s in sets) + "]")
    seconds = run(cmd, repo, log)
    results = results_dir / CAPTURE
    return {"seconds": seconds, "stages": stage_costs(results), "quality": quality(results)}


def train_speed(repo: Path, work: Path) -> dict[str, float]:
    """The fast preset's training speed of ``repo``'s code and preset, measured by this tree's
    bench/train_speed.py (one benchmark for both trees: it draws object, background and sparse-depth rays as
    `orca train` does)."""
    out = work / f"train_speed_{repo.name}.json"
    run([sys.executable, str(Path(__file__).parent / "train_speed.py"), "--device", "cpu", "--presets", "fast",
         "--steps", str(TRAIN_SPEED_STEPS), "--out", str(out)], repo, work / f"train_speed_{repo.name}.log",
        env={**os.environ, "PYTHONPATH": str(repo)})
    row = json.loads(out.read_text(encoding="utf-8"))["results"][0]
    return {"seconds_per_iteration": row["seconds_per_iteration"], "iterations": row["iterations"],
            "training_minutes": row["seconds_per_iteration"] * row["iterations"] / 60}


def worktree(rev: str, work: Path) -> Path:
    path = work / f"baseline-{rev}"
    if not path.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(path), rev], cwd=ROOT, check=True,
                       capture_output=True)
    return path


def ensure_capture(capture_dir: Path, log: Path) -> float | None:
    """Render the demo capture once (``orca synth sphere``, as scripts/demo.sh does); seconds, or None if it
    was there."""
    if (capture_dir / CAPTURE / "ground_truth" / "scene.json").is_file():
        return None
    return run([sys.executable, "-m", "pipeline.cli", "synth", "sphere", str(capture_dir / CAPTURE)], ROOT, log)


def print_table(label: str, figures: dict[str, Any]) -> None:
    stages = figures["stages"]
    print(f"{label}: whole DAG {figures['seconds'] / 60:.1f} min")
    for stage in STAGES:
        if stage in stages:
            print(f"  {stage:9s} {stages[stage]['seconds']:8.1f} s  {stages[stage]['peak_rss_mb']:7.0f} MB")
    print("  " + "  ".join(f"{k} {v:.3g}" for k, v in figures["quality"].items() if v is not None))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "orca_demo_dag",
                        help="where the capture, the results and the baseline's worktree go")
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="a config override for HEAD's DAG, as `orca <stage> --set` (repeatable)")
    parser.add_argument("--baseline", default=None, help="a commit to compare with (e.g. 30a1e36)")
    parser.add_argument("--baseline-dag", action="store_true", help="also run the baseline's whole DAG")
    parser.add_argument("--label", default="", help="what this run was")
    args = parser.parse_args()
    work = args.work.resolve()
    work.mkdir(parents=True, exist_ok=True)
    captures = work / "captures"
    record: dict[str, Any] = {"machine": machine(), "commit": commit(), "label": args.label, "sets": args.sets,
                              "render_seconds": ensure_capture(captures, work / "synth.log")}
    stamp = time.strftime("%Y%m%d_%H%M%S")
    record["head"] = dag(ROOT, captures, work / f"head_{stamp}", args.cores, args.sets, work / "head_dag.log")
    print_table(f"HEAD {record['commit']}", record["head"])
    if args.baseline:
        base = worktree(args.baseline, work)
        record["baseline"] = {"commit": args.baseline, "train_speed": train_speed(base, work)}
        record["head"]["train_speed"] = train_speed(ROOT, work)
        if args.baseline_dag:
            record["baseline"].update(dag(base, captures, work / f"baseline_{stamp}", args.cores, [],
                                          work / "baseline_dag.log"))
            print_table(f"baseline {args.baseline}", record["baseline"])
        head_train = record["head"]["stages"]["train"]["seconds"] / 60
        base_train = record["baseline"].get("stages", {}).get("train", {}).get("seconds")
        base_train = base_train / 60 if base_train else record["baseline"]["train_speed"]["training_minutes"]
        record["training_ratio"] = base_train / head_train
        for who in ("baseline", "head"):
            speed = record[who]["train_speed"]
            print(f"{who:9s} train_speed: {speed['seconds_per_iteration']:.3f} s/it x {speed['iterations']} it. = "
                  f"{speed['training_minutes']:.1f} min")
        print(f"training: baseline {base_train:.1f} min / HEAD's train stage {head_train:.1f} min = "
              f"{record['training_ratio']:.2f}x")
    append_record(RESULTS, record)
    print(f"appended to {RESULTS}")


if __name__ == "__main__":
    main()
