"""Resuming a generalist run: its own settings, not today's defaults; a new budget stretches
nothing of the schedule; flags that would change the run are refused."""

from __future__ import annotations

import dataclasses
import json

import pytest

from policies.config import SETTINGS_BEFORE_THEY_EXISTED, GeneralistConfig, resumed_config


def stored(cfg: GeneralistConfig) -> dict:
    """``cfg`` as a run's config.json holds it (through JSON: tuples come back as lists)."""
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


def test_a_resumed_run_keeps_its_stored_settings_not_todays_defaults():
    run = GeneralistConfig(
        teacher="none",
        seed=3,
        minutes=45,
        family_weights=(("swarms-*", 2.0),),
        hidden=32,
        real_error_tau_s=(10.0, 120.0),
        real_track_filter=True,
        teacher_truth=True,
    )
    assert run != GeneralistConfig(seed=3)  # the defaults moved on since it started
    assert resumed_config(stored(run)) == run


def test_a_run_from_before_a_setting_existed_resumes_as_it_ran():
    old = stored(GeneralistConfig(seed=2))
    for name in SETTINGS_BEFORE_THEY_EXISTED:
        del old[name]
    del old["pooling"]  # a setting whose default is what the code did before it
    cfg = resumed_config(old)
    assert (cfg.teacher, cfg.learner, cfg.dagger_fraction) == ("none", "td3", 0.0)
    assert (cfg.sensing_range_m, cfg.sensing_aperture_deg) == (0.0, 0.0)  # the scenarios' sensing
    assert cfg.teacher_horizon_s == 10.0  # ORCA's own horizon
    assert cfg.pooling == GeneralistConfig().pooling and cfg.seed == 2


def test_a_setting_this_version_does_not_know_is_refused():
    with pytest.raises(ValueError, match="warp_drive: not a setting of this version"):
        resumed_config({**stored(GeneralistConfig()), "warp_drive": 1})


def test_a_new_budget_keeps_the_schedule_of_the_first():
    run = GeneralistConfig(minutes=60, dagger_fraction=0.5, bc_fraction=0.75)
    longer = resumed_config(stored(run), minutes=120)
    assert (longer.minutes, longer.schedule_minutes) == (120, 60)
    for minute in (0, 15, 29.9, 30, 45, 59):  # DAgger, the fade: where they were
        assert longer.fraction_of(60 * minute) == pytest.approx(run.fraction_of(60 * minute))
    assert longer.fraction_of(60 * 90) == 1.0  # after the schedule: every phase over
    again = resumed_config(stored(longer), minutes=180)
    assert (again.minutes, again.schedule_minutes) == (180, 60)
    assert resumed_config(stored(run), minutes=60) == run  # the same budget: nothing moves
    assert resumed_config(stored(run), device="cpu").device == "cpu"


@pytest.fixture
def fake_train(monkeypatch):
    import policies.generalist_train as generalist_train

    seen = []

    def train(cfg, out, resume=False, progress=None):
        seen.append((cfg, resume))
        return {"transitions": 0, "elapsed_s": 0.0, "best_success": 0.0}

    monkeypatch.setattr(generalist_train, "train_generalist", train)
    return seen


def a_run(tmp_path, cfg: GeneralistConfig):
    """A run folder as train --generalist leaves it (the checkpoint's bytes are not read)."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.json").write_text(json.dumps({"generalist": stored(cfg)}))
    (out / "last.safetensors").write_bytes(b"checkpoint")
    return out


def test_resume_from_the_command_line_takes_the_runs_settings(tmp_path, fake_train):
    from remarl_fc.cli import main

    run = GeneralistConfig(teacher="none", seed=5, minutes=60)
    out = a_run(tmp_path, run)
    assert main(["train", "--generalist", "--json", "--resume", "--out", str(out)]) == 0
    assert fake_train[-1] == (run, True)  # not today's default teacher
    argv = ["train", "--generalist", "--json", "--resume", "--out", str(out)]
    assert main([*argv, "--minutes", "90", "--seed", "5", "--teacher", "none"]) == 0
    cfg, _ = fake_train[-1]
    assert (cfg.minutes, cfg.schedule_minutes, cfg.teacher) == (90, 60, "none")


@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--teacher", "orca-shield"], "teacher 'orca-shield' (the run's: 'none')"),
        (["--seed", "4"], "seed 4 (the run's: 5)"),
        (["--separation-weight", "0"], "separation_weight 0.0 (the run's: 0.5)"),
        (["--family-weight", "dense-*=2"], "family_weights"),
    ],
)
def test_a_flag_that_would_change_a_resumed_run_is_refused(
    tmp_path, capsys, fake_train, flags, named
):
    from remarl_fc.cli import main

    out = a_run(tmp_path, GeneralistConfig(teacher="none", seed=5))
    assert main(["train", "--generalist", "--resume", "--out", str(out), *flags]) == 2
    err = capsys.readouterr().err
    assert "keeps the settings it started with" in err and named in err
    assert "Traceback" not in err and not fake_train


def test_nothing_to_resume_or_no_settings_is_a_clear_error(tmp_path, capsys, fake_train):
    from remarl_fc.cli import main

    empty = tmp_path / "typo"
    assert main(["train", "--generalist", "--resume", "--out", str(empty)]) == 2
    assert "holds no checkpoint" in capsys.readouterr().err and not empty.exists()
    out = a_run(tmp_path, GeneralistConfig())
    (out / "config.json").write_text("{not json")
    assert main(["train", "--generalist", "--resume", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "config.json is missing or unreadable" in err and "Traceback" not in err
    (out / "config.json").write_text(json.dumps({"generalist": {"warp_drive": 1}}))
    assert main(["train", "--generalist", "--resume", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "warp_drive: not a setting of this version" in err and "Traceback" not in err
    (out / "config.json").write_text(json.dumps({"generalist": {"minutes": -1}}))
    assert main(["train", "--generalist", "--resume", "--out", str(out)]) == 2
    assert "minutes: must be >= 0" in capsys.readouterr().err
    assert not fake_train
