"""Checkpoints (pipeline.checkpoints): what makes a checkpoint another run's, damaged files and weights of another
network version named with the fix."""

from __future__ import annotations

import pytest
from helpers import TINY_TRAIN

from pipeline.checkpoints import identity_changes, load_checkpoint, load_weights
from pipeline.config import MOVED, dotted, load_config
from pipeline.errors import InputError


def _cfg(*extra):
    return load_config(preset="fast", overrides=[*TINY_TRAIN, *extra]).train


def test_a_checkpoints_identity_compares_the_config_but_its_resume_neutral_keys():
    """Also across versions: an identity of the flat train keys (and without the neutral ones) resumes under
    the same values."""
    cfg = load_config(preset="fast").train
    current = {"config": cfg.model_dump(mode="json"), "data": "d"}
    old_name = {new: old for old, new in MOVED["train"].items()}
    flat = {old_name.get(k, k): v for k, v in dotted(cfg.model_dump(mode="json")).items()
            if not k.startswith(("losses.", "environment.hash_grid.levels", "environment.hash_grid.max_res",
                                 "sdf.init", "sdf.hull_", "sdf.reflectance"))}  # keys the flat versions did not have
    neutral = {"iterations", "checkpoint_every", "preview_every", "preview_downscale", "log_every",
               "keep_checkpoints", "device", "env_fine_render", "env_depth_quantile"}
    earlier = {"config": {**{k: v for k, v in flat.items() if k not in neutral},
                          "losses": cfg.losses.model_dump(mode="json")}, "data": "d"}
    assert identity_changes(earlier, current) == []
    for change, why in (("train.logging.log_every=7", []), ("train.render.depth_quantile=0.4", []),
                        ("train.iterations=9", []),
                        ("train.sdf.hidden=32", ["train.sdf.hidden changed"]),
                        ("train.losses.eikonal=0.2", ["train.losses.eikonal changed"])):
        now = {"config": load_config(preset="fast", overrides=[change]).train.model_dump(mode="json"), "data": "d"}
        assert identity_changes(earlier, now) == why, change
        assert identity_changes(current, now) == why, change
    assert identity_changes(current, {**current, "data": "e"}) == ["the images, masks or cameras changed"]


def test_damaged_checkpoint_names_the_file(tmp_path):
    bad = tmp_path / "step_0000002.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="step_0000002.pt"):
        load_checkpoint(bad)


def test_weights_of_another_network_version_are_a_clear_error(tmp_path):
    from orca.model import OrcaModel
    from pipeline.model_io import model_spec

    model = OrcaModel(model_spec(_cfg()))
    state = {"model": {k: v for k, v in model.state_dict().items() if "level_weights" not in k}}
    with pytest.raises(InputError, match="--restart"):
        load_weights(model, state, tmp_path / "model.pt")


def test_optimizer_groups_split_only_for_their_options():
    """One group by default (what earlier checkpoints' optimizer states hold, so they still resume); the
    environment field gets its own at train.environment_lr; every parameter is in exactly one group."""
    from orca.model import OrcaModel
    from pipeline.model_io import model_spec
    from pipeline.training import parameter_groups

    fast = load_config(preset="fast").train
    cfg = fast.model_copy(update={"environment_lr": None})
    model = OrcaModel(model_spec(cfg))
    default = parameter_groups(model, cfg)
    assert len(default) == 1 and len(default[0]["params"]) == len(list(model.parameters()))
    assert [g.get("lr") for g in parameter_groups(model, fast)] == [None, fast.environment_lr]
    split = parameter_groups(model, cfg.model_copy(update={"environment_lr": 0.02}))
    assert [g.get("lr") for g in split] == [None, 0.02]
    assert {id(p) for p in split[1]["params"]} == {id(p) for p in model.env_field.parameters()}
    assert sorted(id(p) for g in split for p in g["params"]) == sorted(id(p) for p in model.parameters())
