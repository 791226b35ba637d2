"""What the `mavtune` command says: plain help (square brackets kept), --version, one-line usage errors,
lazily loaded commands that match their own docstrings, counted nouns, labelled per-round lines."""

from __future__ import annotations

import contextlib
import io
import math

import pytest

from mavtune.cli import LAZY, load_command, run_app


def cli(*args: str) -> tuple[int, str, str]:
    """`mavtune ARGS` in this process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = run_app(list(args))
    return code, " ".join(out.getvalue().split()), err.getvalue()  # help wraps lines at the terminal's width


def test_help_keeps_square_brackets():
    code, out, _ = cli("tune", "--help")
    assert code == 0 and "([tuning], [flight], [sim], [fleet], ...)" in out
    assert "[2000]" in out  # --max-rounds names its default


def test_version():
    import mavtune

    code, out, _ = cli("--version")
    assert code == 0 and out.strip() == f"mavtune {mavtune.__version__}"


@pytest.mark.parametrize("name", sorted(LAZY))
def test_a_lazy_command_is_listed_with_its_own_first_docstring_line(name):
    _, _, summary = LAZY[name]
    assert load_command(name).help.strip().splitlines()[0] == summary
    code, out, _ = cli("--help")
    assert code == 0 and name in out


def test_agent_takes_c_for_its_config_like_the_readme():
    code, out, _ = cli("agent", "--help")
    assert code == 0 and "-c, --config" in out


@pytest.mark.parametrize("args, says", [
    (["tune", "-n", "abc"], "'--vehicles'"),
    (["tune", "--no-such-flag"], "--no-such-flag"),
    (["plan", "--epsilon", "x"], "'--epsilon'"),
    (["nonsense"], "nonsense"),
    (["tune", "--bootstraps", "two"], "--bootstraps must be a whole number"),
    (["tune", "--stage-rounds", "0", "--out", "/nonexistent/never"], "--stage-rounds must be at least 1"),
    (["tune", "--mavlink", "udpin:127.0.0.1:9", "--out", "/nonexistent/never"], "--mavlink applies to --fleet"),
    (["tune", "--fleet", "mavlink", "--payload", "0.9", "--mavlink", "udpin:127.0.0.1:9",
      "--out", "/nonexistent/never"], "--payload applies to --fleet sim"),
    (["tune", "--keep-tuned", "--out", "/nonexistent/never"], "--keep-tuned applies to --fleet mavlink"),
    (["tune", "--listen", "tcp/127.0.0.1:7447", "--out", "/nonexistent/never"], "--listen applies to --fleet zenoh"),
    (["plan", "--bootstraps", "1000000"], "tuning.bootstraps"),
    (["plan", "--battery-s", "1"], "shorter than one round"),
    (["plan", "--battery-s", "inf"], "flight.battery_s: must be a finite number"),
    (["plan", "--epsilon", "1e-9"], "tuning.epsilon"),
    (["plan", "-n", "1000000"], "tuning.vehicles"),
    (["plan", "--epsilon", "0.001", "--budget", "none", "--preset", "passes"], "at least 4013 rounds"),  # 4004 of
    # the line searches (2 passes), 9 of the design
])
def test_bad_input_is_one_line_with_status_2(args, says):
    code, _, err = cli(*args)
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, err


def test_a_long_plan_flies_only_when_the_cap_is_raised():
    code, out, _ = cli("plan", "--epsilon", "0.004", "--no-adaptive", "--max-rounds", "5000", "--budget", "none",
                       "--preset", "passes")  # (the rounds of 2 passes' line searches)
    assert code == 0 and "rounds 1013" in out  # 1004 of the line searches, 9 of the design


def test_ignored_settings_are_warned_and_recorded(tmp_path):
    import json

    cfg = tmp_path / "c.toml"
    cfg.write_text("[tuning]\nreplicates = 2\nbootstraps = 1\n[swarm]\nsession = \"x\"\n")
    code, out, _ = cli("tune", "-q", "-c", str(cfg), "--out", str(tmp_path / "run:rocket:"))
    assert code == 0
    assert "warning: tuning.replicates = 2 is ignored" in out and "warning: the [swarm] table is ignored" in out
    assert "run:rocket:" in out  # a name is printed as it is, never turned into an emoji
    warnings = json.loads((tmp_path / "run:rocket:" / "result.json").read_text())["warnings"]
    assert len(warnings) == 2


def test_one_vehicle_is_one_vehicle():
    code, out, _ = cli("plan", "-n", "1", "--epsilon", "0.125", "--no-adaptive", "--budget", "none")
    assert code == 0 and "1 sim vehicle ·" in out and "(1 vehicle × 69 rounds" in out  # 18 + 2 at the edges
    # (1 pass) + 49 of the designs (the map's 13 points once, then 9 points flown twice each, as two vehicles fly them)


def test_the_round_line_labels_each_vehicle_and_gives_the_mean():
    from mavtune.fleet import Flight, Status
    from mavtune.run import round_line
    from mavtune.tuner import Round

    flights = [Flight("v0", {"kp": 0.25}, 4.0), Flight("v1", {"kp": 0.75}, 6.0),
               Flight("v2", {"kp": 0.75}, math.nan, Status.LOST)]
    rnd = Round(7, 1, "kp", (0.0, 1.0), [{"kp": 0.25}, {"kp": 0.75}, {"kp": 0.75}], flights, 0.0, 9.0)
    line = round_line(rnd)
    assert line.startswith("[dim]round   7[/]")  # rounds from 0, as in the journal, result.json and report.md
    assert "kp per vehicle 0.25 0.75 0.75" in line and "cost per vehicle 4 6 [yellow]lost[/]" in line
    assert line.endswith("mean 5")
    many = Round(3, 1, "kp", (0.0, 1.0), [{"kp": 0.5}] * 20, [Flight(f"v{i}", {"kp": 0.5}, 2.0) for i in range(20)],
                 0.0, 9.0)
    assert "1 point of kp in [0.5, 0.5] on 20 vehicles" in round_line(many) and round_line(many).endswith("mean 2")


def test_each_round_and_the_run_folder_are_one_line_in_a_log(tmp_path):
    """Output to a file or pipe (80 columns) keeps a design's round on one line, however long, so a log greps; and the
    run folder's path whole and as it is (markup-like brackets too), so it can be copied."""
    folder = tmp_path / ("a-run-folder-whose-path-is-longer-than-a-log-line-of-eighty-columns-" * 2 + "[v2]")
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert run_app(["tune", "--out", str(folder)]) == 0
    lines = out.getvalue().splitlines()
    rounds = [line for line in lines if line.startswith("round ")]
    assert len(rounds) == 42 and max(map(len, rounds)) > 80
    assert all(" mean " in line for line in rounds)
    assert f"run folder: {folder}" in lines
