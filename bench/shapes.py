"""The method beyond the sphere: the randomized family's shapes trained with their ground-truth cameras and masks,
each scored against its ground truth (normals, combined / diffuse / specular PSNR, the mesh's Chamfer distance).

    python bench/shapes.py                                  # SCENES, the fast preset
    python bench/shapes.py --scenes random-27 --set train.iterations=3000 --work /tmp/shapes

Per scene: ``orca synth`` (full ground truth, the renderer's defaults), ``orca decode``, ``orca train
--ground-truth`` (the true cameras and masks: the method's own quality, not the front end's), ``orca mesh``,
``orca evaluate --no-environment`` (object views only: the shapes differ, the rooms are another benchmark), each
timed with its peak resident memory. Prints a table, appends a JSON line to bench/results/shapes.jsonl and copies
each mesh's picture to bench/results/shapes/.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from datetime import datetime
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch

from bench.blowtorch import ORCA, append_record, commit, machine, timed  # noqa: E402
from bench.demo_dag import object_figures  # noqa: E402
from pipeline.layout import MESH_FIGURE  # noqa: E402
from pipeline.synth.family import traits  # noqa: E402
from pipeline.synth.scenes import get_scene  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "shapes.jsonl"
PICTURES = Path(__file__).parent / "results" / "shapes"
# The family's seeds by shape (pipeline/synth/family.py): a sphere on a plain table (the reference), a torus on a
# poster floor (a hole), a mug on a plain floor (a handle, a concave inside), a vase on a table (a neck).
SCENES = ("random-32", "random-27", "random-4", "random-0")


def scene_figures(results: Path) -> dict[str, Any]:
    """The object's figures of merit from evaluate.json."""
    evaluate = json.loads((results / "evaluate" / "evaluate.json").read_text(encoding="utf-8"))
    mesh = evaluate.get("mesh") or {}
    return {**object_figures(evaluate), "fscores": {k: v for k, v in mesh.items() if k.startswith("fscore_")}}


def run_scene(scene: str, work: Path, preset: str, sets: list[str]) -> dict[str, Any]:
    capture, results = work / scene, work / f"{scene}_results"
    overrides = [a for s in sets for a in ("--set", s)]
    truth = capture / "ground_truth"
    steps = {
        "synth": ["synth", scene, str(capture)],  # refuses a folder it did not write
        "decode": ["decode", str(capture), "--out", str(results / "decode")],
        "train": ["train", "--ground-truth", str(truth), "--decode", str(results / "decode"), "--capture",
                  str(capture), "--preset", preset, "--out", str(results / "train"), *overrides],
        "mesh": ["mesh", str(results / "train"), "--cameras", str(truth / "cameras.json"), "--out",
                 str(results / "mesh"), "--preset", preset],
        "evaluate": ["evaluate", str(results / "train"), "--ground-truth", str(truth), "--cameras",
                     str(truth / "cameras.json"), "--mesh", str(results / "mesh" / "mesh.ply"), "--no-environment",
                     "--out", str(results / "evaluate")],
    }
    stages = {}
    for name, args in steps.items():
        if name == "synth" and (truth / "scene.json").is_file():
            continue  # rendered by an earlier run into the same --work
        log = work / f"{scene}_{name}.log"
        seconds, peak_mb, returncode = timed([str(ORCA), *args], log)
        stages[name] = {"seconds": round(seconds, 1), "peak_rss_mb": round(peak_mb)}
        if returncode:
            raise SystemExit(f"{scene}: orca {name} failed; see {log}")
    PICTURES.mkdir(parents=True, exist_ok=True)
    # train.losses.smoothness=1.0 -> _smoothness=1.0
    label = "".join(f"_{key.rsplit('.', 1)[-1]}={value}" for key, value in (o.split("=", 1) for o in sets))
    shutil.copyfile(results / "mesh" / MESH_FIGURE, PICTURES / f"{scene}{label}_mesh.png")
    described = traits(get_scene(scene)) if scene.startswith("random-") else None
    return {"scene": scene, "traits": described, "stages": stages, **scene_figures(results)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                        help="a training config override (repeatable)")
    parser.add_argument("--work", type=Path, default=None, help="keep captures and results here (default: temp)")
    parser.add_argument("--no-record", action="store_true")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="orca_shapes_"))
    work.mkdir(parents=True, exist_ok=True)
    code = commit()
    rows = []
    for scene in args.scenes:
        rows.append(run_scene(scene, work, args.preset, args.sets))
        r = rows[-1]
        print(f"{scene:<11} {(r['traits'] or {}).get('shape', '?'):<7} normals {r['normals_deg']:.2f} deg  "
              f"combined {r['psnr_combined_db']:.2f} dB  diffuse {r['psnr_diffuse_db']:.2f}  specular "
              f"{r['psnr_specular_db']:.2f}  Chamfer {r['chamfer_fraction']:.4f}  train "
              f"{r['stages']['train']['seconds']:.0f} s", flush=True)
    if not args.no_record:
        record = {"date": datetime.now().isoformat(timespec="seconds"), "machine": machine(), "commit": code,
                  "preset": args.preset, "sets": args.sets, "scenes": rows}
        append_record(RESULTS, record)
    print(f"work folder: {work}")


if __name__ == "__main__":
    main()
