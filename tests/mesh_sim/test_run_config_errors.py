"""``skymesh run`` on bad settings: one clear line, exit code 2, no traceback, and no run folder left behind
(reliability audit: tracebacks for ``seed = "abc"`` and ``sensor = 5``; ``--seed -1`` hung live agents for
120 s; failed runs left empty run folders)."""

from __future__ import annotations

import pytest

from mesh_sim import cli
from mesh_sim.launcher import run_folder


@pytest.mark.parametrize("toml, args, message", [
    ('seed = "abc"', [], "seed must be an integer"),
    ("sensor = 5", [], "[sensor] must be a table"),
    ("tracking = [1]", [], "[tracking] must be a table"),
    ("agents = 2.5", [], "agents must be a positive integer"),
    ("", ["--seed", "-1"], "seed must be an integer in [0, 2**32), got -1"),
    ("", ["--lockstep", "--rerun", "spawn"], "--lockstep records with --rerun save or off"),
])
def test_a_bad_setting_is_one_line_exit_2_and_no_folder(tmp_path, capsys, toml, args, message):
    """Bad input: the scenario setting or option in the parameters."""
    scenario = tmp_path / "bad.toml"
    scenario.write_text(f'name = "bad"\nduration = 1.0\n{toml}\n')
    out = tmp_path / "runs"
    code = cli.main(["run", "--scenario", str(scenario), "--lockstep", "--rerun", "off", "--out", str(out), *args])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists() or not any(out.iterdir()), list(out.iterdir())


def test_a_run_folder_is_removed_when_the_run_raises_before_its_metrics(tmp_path):
    """A run that raises (here: a full disk, as an OSError) leaves nothing; one that wrote its metrics keeps them."""
    with pytest.raises(OSError):
        with run_folder(tmp_path, "doomed") as path:
            (path / "logs").mkdir()
            raise OSError(28, "No space left on device")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(KeyboardInterrupt):
        with run_folder(tmp_path, "kept") as path:
            (path / "metrics.json").write_text("{}")
            raise KeyboardInterrupt
    assert [p.name.startswith("kept-") for p in tmp_path.iterdir()] == [True]
