"""Progress inside a long stage: a bar with ETA on a terminal, nothing when piped.

The stages report through :mod:`adpart.workflows.progress`; the commands install
:func:`adpart.cli.common.stage_bars` (click's bar, drawn only when stderr is a terminal). The
bar is read back from a pseudo-terminal; what a stage reports is read back from a recording
factory.
"""

from __future__ import annotations

import json
import os
import pty
import re
import subprocess
import sys

from click.testing import CliRunner

from adpart.cli import cli
from adpart.workflows import LearnRequest, run_learning
from adpart.workflows.progress import progress_bars, stage_progress


def _on_a_terminal(code: str) -> str:
    """What ``code`` writes to stderr when stderr is a pseudo-terminal."""
    leader, follower = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-c", code], stderr=follower,
                            stdout=subprocess.DEVNULL)
    os.close(follower)
    chunks = []
    while True:
        try:
            data = os.read(leader, 4096)
        except OSError:  # the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    assert proc.wait(timeout=60) == 0
    os.close(leader)
    return b"".join(chunks).decode()


STAGE = """
import time
from adpart.cli.common import stage_bars
from adpart.workflows.progress import progress_bars, stage_progress
with progress_bars(stage_bars({enabled})):
    with stage_progress(5, "learning reach-goal") as update:
        for done in range(1, 6):
            time.sleep(0.3)
            if update is not None:  # None: no bar installed
                update(done, 5)
"""


def test_a_stage_draws_a_bar_with_eta_on_a_terminal():
    screen = _on_a_terminal(STAGE.format(enabled=True))
    assert "learning reach-goal" in screen and "100%" in screen
    assert re.search(r"\b\d\d:\d\d:\d\d\b", screen), screen  # click's ETA, after 1 s


def test_quiet_draws_nothing_even_on_a_terminal():
    assert _on_a_terminal(STAGE.format(enabled=False)) == ""


def test_piped_draws_nothing():
    out = subprocess.run([sys.executable, "-c", STAGE.format(enabled=True)],
                         capture_output=True, text=True, check=True)
    assert out.stderr == "" and out.stdout == ""


def _recording():
    seen: list[tuple[str, int, list[tuple[int, int]]]] = []

    def factory(total, label):
        calls: list[tuple[int, int]] = []
        seen.append((label, total, calls))
        return (lambda done, total: calls.append((done, total))), (lambda: None)

    return seen, factory


def test_learning_reports_its_episodes_to_the_installed_bar():
    seen, factory = _recording()
    request = LearnRequest(env="two-rooms", learner="q-learning", runs=2, episodes=6, seed=1,
                           eval_every=2)
    with progress_bars(factory):
        run_learning(request)
    [(label, total, calls)] = seen
    assert label == "q-learning on two-rooms/reach-goal" and total == 6
    assert calls and calls[-1] == (6, 6)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_batches_learned_one_after_another_count_runs():
    seen, factory = _recording()
    request = LearnRequest(env="two-rooms", learner="q-learning", runs=3, episodes=4, seed=1,
                           eval_every=2, runs_per_batch=1)
    with progress_bars(factory):
        run_learning(request)
    [(label, total, calls)] = seen
    assert label.endswith("(runs)") and total == 3 and calls == [(1, 3), (2, 3), (3, 3)]


def test_without_an_installed_bar_a_stage_is_silent():
    with stage_progress(10, "nothing") as update:
        assert update is None


def test_the_pipeline_learns_every_stage_under_a_bar(monkeypatch, tmp_path):
    """``adpart pipeline`` installs the bars; each learning stage it computes (the first task
    flat, the layer learner, the baselines) opens one bar over its episodes, run to the end."""
    seen, factory = _recording()
    monkeypatch.setattr("adpart.cli.pipeline_cmd.stage_bars", lambda enabled: factory)
    out = CliRunner().invoke(cli, [
        "pipeline", "two-rooms", "--no-fallback", "--tasks", "reach-goal,goal:x=9,y=5",
        "--runs", "2", "--first-episodes", "300", "--episodes", "40", "--eval-every", "10",
        "--flat-opt", "alpha=1", "--flat-opt", "epsilon=0.5", "--kb", str(tmp_path / "kb"),
        "--out", str(tmp_path / "out"), "--json"])
    assert out.exit_code == 0, out.output
    learned = [s for s in json.loads(out.output)["stages"]
               if s["stage"].startswith("learn-") and not s["reused"]]
    assert len(seen) == len(learned) >= 3
    assert seen[0][:2] == ("q-learning on two-rooms/reach-goal", 300)
    assert all(calls and calls[-1] == (total, total) for _, total, calls in seen)


def test_an_experiment_that_calls_the_learners_itself_draws_a_bar_per_learner(monkeypatch,
                                                                           tmp_path):
    """``adpart experiment`` installs the bars; an experiment that calls the learning cores
    itself (subgoals-two-rooms: Q-learning, not the pipeline) opens a bar over the episodes of
    each learner call (``learning_progress``), run to the end."""
    seen, factory = _recording()
    monkeypatch.setattr("adpart.cli.experiment.stage_bars", lambda enabled: factory)
    out = CliRunner().invoke(cli, ["experiment", "subgoals-two-rooms", "--quick", "--runs", "2",
                                   "--out", str(tmp_path / "out")])
    assert out.exit_code == 0, out.output
    [(label, total, calls)] = seen
    assert label == "Q-learning two-rooms" and total > 0
    assert calls and calls[-1] == (total, total)


def test_a_learner_given_its_own_progress_hook_keeps_it():
    """``learning_progress`` leaves a run that already reports alone and opens no bar."""
    from adpart.learning.settings import Run
    from adpart.workflows.progress import learning_progress

    seen, factory = _recording()
    own = Run(progress=lambda done, total: None)
    with progress_bars(factory), learning_progress(own, "x") as run:
        assert run is own
    with progress_bars(factory), learning_progress(Run(episodes=7), "y") as run:
        assert run.progress is not None and run.episodes == 7
    assert [(label, total) for label, total, _ in seen] == [("y", 7)]
