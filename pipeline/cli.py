"""The ``orca`` command: one subcommand per stage, each a thin wrapper over that stage's function.

Stage modules expose ``register(subparsers)``; heavy imports (mitsuba, torch, pycolmap) stay inside the
stage functions so ``orca --help`` is instant.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
import threading

# LibRaw (rawpy) and torch each bring an OpenMP runtime; spin-waiting threads of one starve the other when
# a process loads both. Set before either library is imported.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from . import __version__
from .errors import OrcaError
from .log import setup_logging
from .signals import stop_on_sigterm, stopped_by

# (subcommand, module defining register()) in DAG order.
COMMANDS: list[tuple[str, str]] = [
    ("synth", "pipeline.synth.cli"),
    ("frames", "pipeline.video_cli"),
    ("decode", "pipeline.stages.decode"),
    ("poses", "pipeline.stages.poses"),
    ("masks", "pipeline.stages.masks"),
    ("calibrate", "calibration.cli"),  # also registers `orca board`
    ("train", "pipeline.stages.train"),
    ("mesh", "pipeline.stages.mesh"),
    ("export", "pipeline.stages.export"),
    ("render", "pipeline.stages.render"),
    ("evaluate", "pipeline.stages.evaluate"),
    ("report", "pipeline.stages.report"),
]

log = logging.getLogger("orca")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="orca",
        description="ORCa: glossy objects as radiance-field cameras. Each subcommand runs one stage of the "
        "pipeline (the Snakefile runs them all); `orca <command> --help` shows its options and examples.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"orca {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="<command>", required=True)
    for _, module in COMMANDS:
        importlib.import_module(module).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    setup_logging(verbose=args.verbose)
    if threading.current_thread() is threading.main_thread():
        stop_on_sigterm()
    try:
        args.func(args)
    except OrcaError as e:
        log.error("%s", e)
        return 2
    except KeyboardInterrupt as e:
        signum = stopped_by(e)
        log.error("stopped by %s; nothing half-written was left behind", signum.name)
        return 128 + signum
    return 0


if __name__ == "__main__":
    sys.exit(main())
