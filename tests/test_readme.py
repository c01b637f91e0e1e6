"""The README and docs say what is true now: every command in their ```bash blocks parses with the real
parsers (``orca`` subcommands with the CLI's argparse, their ``--set`` keys with the config, ``snakemake`` flags
with Snakemake's own parser), scripts exist, config keys named in the text exist, ```yaml blocks are valid
configs, links resolve; and the text holds no project history (session numbers, commit hashes, "tried" lists)."""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from importlib.metadata import metadata
from pathlib import Path

import pytest
import yaml
from helpers import ROOT
from pydantic import BaseModel

from pipeline.cli import build_parser, main
from pipeline.config import PRESETS, PipelineConfig, load_config, stage_config

DOCS = [ROOT / "README.md", ROOT / "captures" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^[ \t]*```(\w*)\n(.*?)^[ \t]*```", re.MULTILINE | re.DOTALL)
ENV_ASSIGNMENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*=")
FILE_SUFFIXES = {"ply", "png", "jpg", "json", "jsonl", "exr", "yaml", "html", "mp4", "pt", "md", "py"}


def _blocks(path: Path, language: str) -> list[str]:
    return [body for lang, body in FENCE.findall(path.read_text(encoding="utf-8")) if lang == language]


def _commands() -> list[tuple[str, list[str]]]:
    """(where, argv) for every command line of every ```bash block, continuation lines joined, comments and
    leading VAR=value assignments dropped."""
    found = []
    for path in DOCS:
        for block in _blocks(path, "bash"):
            for line in block.replace("\\\n", " ").splitlines():
                argv = shlex.split(line, comments=True)
                while argv and ENV_ASSIGNMENT.match(argv[0]):
                    argv = argv[1:]
                if argv:
                    found.append((f"{path.relative_to(ROOT)}: {shlex.join(argv)}", argv))
    return found


COMMANDS = _commands()


def _ids(commands):
    return [where[:80] for where, _ in commands]


def test_the_readme_has_commands_of_each_kind():
    programs = {argv[0] for where, argv in COMMANDS if where.startswith("README.md")}
    assert {"orca", "snakemake", "bash"} <= programs


@pytest.fixture(scope="module")
def orca_parser():
    return build_parser()


def _parse(parser, argv: list[str], where: str):
    try:
        return parser.parse_args(argv)
    except SystemExit as e:
        pytest.fail(f"{where}: argparse rejects it (exit {e.code})")


ORCA = [(w, a) for w, a in COMMANDS if a[0] == "orca"]


@pytest.mark.parametrize(("where", "argv"), ORCA, ids=_ids(ORCA))
def test_orca_command_parses(where, argv, orca_parser, capsys):
    args = argv[1:]
    if "--help" in args or "-h" in args:
        with pytest.raises(SystemExit) as stop:
            main(args)
        assert stop.value.code == 0, where
        return
    sub = args[0]
    with pytest.raises(SystemExit) as stop:
        main([sub, "--help"])
    assert stop.value.code == 0, where
    namespace = _parse(orca_parser, args, where)
    # --preset and --set go through the configuration the stage would build (file paths need not exist)
    if sub in PipelineConfig.model_fields and hasattr(namespace, "overrides"):
        stage_config(sub, namespace.preset, None, namespace.overrides)


SNAKEMAKE = [(w, a) for w, a in COMMANDS if a[0] == "snakemake"]


@pytest.mark.parametrize(("where", "argv"), SNAKEMAKE, ids=_ids(SNAKEMAKE))
def test_snakemake_command_parses(where, argv):
    from snakemake.cli import get_argument_parser

    namespace = _parse(get_argument_parser(), argv[1:], where)
    known = set(yaml.safe_load((ROOT / "config" / "schema" / "config.schema.yaml").read_text())["properties"])
    config = dict(item.split("=", 1) for item in namespace.config or [])
    assert set(config) <= known, f"{where}: unknown Snakemake config keys {set(config) - known}"
    preset = config.get("preset", "fast")
    assert preset in PRESETS, where
    overrides = yaml.safe_load(config["set"]) if "set" in config else []
    load_config(preset=preset, overrides=overrides)
    if "captures" in config:
        assert isinstance(yaml.safe_load(config["captures"]), list), where


OTHERS = [(w, a) for w, a in COMMANDS if a[0] not in ("orca", "snakemake")]


@pytest.mark.parametrize(("where", "argv"), OTHERS, ids=_ids(OTHERS))
def test_other_command_is_real(where, argv):
    program, *args = argv
    if program == "bash":
        script = ROOT / args[0]
        assert script.is_file(), where
        subprocess.run(["bash", "-n", str(script)], check=True)
    elif program == "source":
        assert args == [".venv/bin/activate"], where
    elif program == "python":
        assert args[0] == "-c", f"{where}: only `python -c` is checked"
        proc = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, f"{where}:\n{proc.stderr[-2000:]}"
    elif program == "pip":
        if args[1:2] == ["-c"]:  # a constraints file of the repository, which pins what is installed
            constraints = (ROOT / args[2]).read_text()
            args = args[:1] + args[3:]
            if args[1:3] == ["--force-reinstall", "--no-deps"]:
                assert re.search(rf"^{re.escape(args[3])}==", constraints, re.MULTILINE), where
                return
        assert args[:2] == ["install", "-e"], f"{where}: only `pip install -e .[extras]` is checked"
        extras = re.fullmatch(r"\.\[([\w,]+)\]", args[2])
        declared = metadata("orca-capture").get_all("Provides-Extra")
        assert extras and set(extras[1].split(",")) <= set(declared), where
    elif program == "jupyter":
        assert args[0] == "lab" and all((ROOT / a).is_file() for a in args[1:]), where
    elif program == "tensorboard":
        assert shutil.which(program, path=str(Path(sys.executable).parent)) or shutil.which(program), where
    else:
        pytest.fail(f"{where}: no check for {program!r}; add one to tests/test_readme.py")


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_history_in_the_docs(path):
    text = path.read_text(encoding="utf-8")
    assert not re.findall(r"\bsessions?\s+\d+", text, re.IGNORECASE), "session numbers"
    hashes = re.findall(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b", text)
    assert not hashes, f"commit hashes {hashes}"
    assert not re.findall(r"\b(?:un)?tried\b|\bnot kept\b", text, re.IGNORECASE), "a 'tried' list"


def _config_key_exists(dotted: str) -> bool:
    model: type[BaseModel] = PipelineConfig
    for part in dotted.split("."):
        if model is None or part not in model.model_fields:
            return False
        annotation = model.model_fields[part].annotation
        model = annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None
    return True


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_config_keys_named_in_the_docs_exist(path):
    sections = "|".join(k for k, f in PipelineConfig.model_fields.items()
                        if isinstance(f.annotation, type) and issubclass(f.annotation, BaseModel))
    named = re.findall(rf"`((?:{sections})\.[a-z_][a-z0-9_.]*)(?:\s*[=:][^`]*)?`", path.read_text(encoding="utf-8"))
    keys = [k for k in named if k.rsplit(".", 1)[-1] not in FILE_SUFFIXES]
    assert [k for k in keys if not _config_key_exists(k)] == []


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_yaml_blocks_are_valid_configs(path, tmp_path):
    for i, block in enumerate(_blocks(path, "yaml")):
        file = tmp_path / f"block{i}.yaml"
        file.write_text(block, encoding="utf-8")
        load_config(file)


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(path):
    text = path.read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    missing = [t for t in targets if not t.startswith(("http://", "https://")) and not (path.parent / t).exists()]
    assert missing == []
