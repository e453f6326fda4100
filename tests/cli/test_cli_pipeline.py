"""`adpart pipeline` and `adpart transfer`: end to end, reuse on a rerun, resume after SIGKILL."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.store import KnowledgeBase
from adpart.workflows.resolve import resolve_domain

PIPELINE = [
    "pipeline",
    "two-rooms",
    "--no-fallback",
    "--tasks",
    "reach-goal,goal:x=9,y=5",
    "--runs",
    "3",
    "--episodes",
    "200",
    "--first-episodes",
    "500",
    "--reward-epsilon",
    "1",
    "--flat-opt",
    "alpha=1",
    "--flat-opt",
    "epsilon=0.5",
    "--hier-opt",
    "alpha=1",
    "--hier-opt",
    "epsilon=0.3",
]


def counts(kb_dir):
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        return kb.counts()
    finally:
        kb.close()


def test_pipeline_runs_stores_everything_and_a_second_run_recomputes_nothing(tmp_path):
    kb_dir, out = tmp_path / "kb", tmp_path / "out"
    first = CliRunner().invoke(cli, [*PIPELINE, "--kb", str(kb_dir), "--out", str(out), "--json"])
    assert first.exit_code == 0, first.output
    summary = json.loads(first.output)
    stages = [s["stage"] for s in summary["stages"]]
    assert stages == [
        "learn-flat",
        "estimate",
        "judge",
        "discover",
        "options",
        "partition",
        "learn-hierarchical",
        "learn-flat",
        "learn-estimated-dynamics",
    ]
    # the default regime: every off-line step on the model the first task's runs estimate
    model_env = summary["stages"][1]["result"]
    assert model_env.startswith("two-rooms@experience:run:")
    assert summary["stages"][1]["detail"]["steps"] > 0
    # the first task judged on the agent's own model: each run's gap there, and the verdict
    judged = summary["stages"][2]["detail"]
    assert judged["runs"] == 3 and len(judged["gap_fraction"]) == 3
    assert judged["learned_runs"] == sum(g <= 0.05 for g in judged["gap_fraction"])
    assert summary["stages"][3]["detail"]["subgoals"] == [23]  # the doorway
    assert not any(s["reused"] for s in summary["stages"])
    rows = {(r["task"], r["learner"]): r for r in summary["tasks"]}
    hier = rows[("goal:x=9,y=5", "hierarchical")]
    # the default chain (4.3.3): the learner starts on the layer step 4 stored (phases 1-2, no
    # phase 3), and says what it knew: the estimated dynamics, the rewards only as observed
    layer = next(s for s in summary["stages"] if s["stage"] == "partition")
    assert hier["mode"] == "inconsistency" and hier["partition"] == layer["result"]
    assert hier["initial_blocks"] >= layer["detail"]["final_blocks"]
    assert hier["knowledge"].startswith("dynamics estimated, rewards observed")
    assert "phase-3" not in hier["knowledge"] and "V*" not in hier["knowledge"]
    assert rows[("goal:x=9,y=5", "flat")]["knowledge"] == "dynamics none, rewards observed"
    # the flat model-based learner with the same counts: the knowledge-matched baseline
    model = rows[("goal:x=9,y=5", "estimated-dynamics")]
    assert model["knowledge"].startswith("dynamics estimated, rewards observed")
    assert "run:1 and its own steps" in model["knowledge"]
    assert hier["model_based"] == "estimated-dynamics" and "ratio_to_model_based" in hier
    planner = rows[("goal:x=9,y=5", "planner")]
    assert planner["episodes_to_bound_median"] == 0 and planner["compute_seconds"] > 0
    kb = KnowledgeBase.open(str(kb_dir))
    try:  # the run is linked to the layer it started on and to the layers its runs ended on
        run = kb.get("run", int(summary["stages"][6]["result"].split(":")[1]))
        assert f"partition:{run.partition_id}" == layer["result"]
        finals = [kb.get("partition", p) for p in run.metrics["final_partitions"]]
        assert len(finals) == 3 and all(p.kind == "learned" for p in finals)
        assert all(p.parent_ids == (run.partition_id,) for p in finals)
        start = kb.get("partition", run.partition_id)  # built on the estimated model
        assert kb.get("environment", start.environment_id).name == model_env
        assert start.task_id is None  # for no task: phases 1-2 read no task's rewards
        first_run = kb.get("run", int(model_env.rsplit(":", 1)[1]))
        assert kb.load(first_run, "experience").num_rows > 0  # stored with the run
    finally:
        kb.close()
    assert (out / "summary.json").exists() and (out / "goal-x-9-y-5.png").exists()
    # the subgoal map of the first task and the layer of the second, beside the curves
    drawn = {Path(f).name for f in summary["figures"]}
    assert {"subgoals_reach-goal.png", "layer_goal-x-9-y-5.png", "goal-x-9-y-5.png"} <= drawn
    for name in drawn:
        assert (out / name).read_bytes()[:4] == b"\x89PNG"
    before = counts(kb_dir)

    again = CliRunner().invoke(cli, [*PIPELINE, "--kb", str(kb_dir), "--out", str(out)])
    assert again.exit_code == 0, again.output
    assert again.output.count("reused") == 7
    assert "episodes" in again.output and "hierarchical" in again.output  # the final table
    assert counts(kb_dir) == before  # nothing stored twice


def test_the_true_model_regime_builds_the_layer_on_the_new_tasks_model(tmp_path):
    run = CliRunner().invoke(cli, [*PIPELINE, "--regime", "true-model",
                                   "--kb", str(tmp_path / "kb"), "--out", str(tmp_path / "o"),
                                   "--json"])
    assert run.exit_code == 0, run.output
    summary = json.loads(run.output)
    assert "estimate" not in [s["stage"] for s in summary["stages"]]
    hier = next(r for r in summary["tasks"] if r["learner"] == "hierarchical")
    assert "dynamics true-model, rewards known" in hier["knowledge"]
    assert "phase-3 split by the task's rewards" in hier["knowledge"]
    assert "threshold L from V*" in hier["knowledge"]
    assert hier["model_based"] == "known-dynamics"


@pytest.mark.processes
def test_killed_pipeline_resumes_from_the_knowledge_base(tmp_path):
    kb_dir = tmp_path / "kb"
    # a long transfer step to kill it in; the flat baseline of the last task is not needed to
    # check the resume (test_pipeline_runs_stores_everything... covers it)
    slow = [*PIPELINE[:-2], "--episodes", "4000", "--no-baseline"]
    env = {**os.environ, "ADPART_KB": str(kb_dir)}
    log = tmp_path / "stderr.txt"
    with log.open("wb") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "adpart.cli", *slow, "--out", str(tmp_path / "o"), "-q"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=err,
        )
    deadline = time.time() + 120
    try:
        while time.time() < deadline:
            if (kb_dir / "kb.sqlite").exists() and counts(kb_dir).get("option", 0) >= 1:
                break
            if proc.poll() is not None:
                raise AssertionError(f"pipeline ended before it could be killed: {log.read_text()}")
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    resumed = CliRunner().invoke(
        cli, [*slow, "--kb", str(kb_dir), "--out", str(tmp_path / "o"), "--json"]
    )
    assert resumed.exit_code == 0, resumed.output
    # the estimate and the judgement are rebuilt from the stored run; the rest is looked up
    stages = json.loads(resumed.output)["stages"]
    reused = {s["stage"]: s["reused"] for s in stages[:5]
              if s["stage"] not in ("estimate", "judge")}
    assert reused == {"learn-flat": True, "discover": True, "options": True}
    assert counts(kb_dir)["subgoal-set"] == 1 and counts(kb_dir)["option"] == 1


def test_inconsistency_mode_learns_on_the_stored_partition(tmp_path):
    kb_dir = tmp_path / "kb"
    args = [*PIPELINE, "--kb", str(kb_dir), "--out", str(tmp_path / "p"), "--no-baseline"]
    run = CliRunner().invoke(cli, [*args, "--json", "--hier-opt", "mode=inconsistency"])
    assert run.exit_code == 0, run.output
    summary = json.loads(run.output)
    partition = next(s["result"] for s in summary["stages"] if s["stage"] == "partition")
    hier = next(r for r in summary["tasks"] if r["learner"] == "hierarchical")
    assert hier["mode"] == "inconsistency" and hier["partition"] == partition


def test_transfer_runs_the_last_step_alone(tmp_path):
    kb_dir = tmp_path / "kb"
    first = CliRunner().invoke(
        cli,
        [*PIPELINE, "--kb", str(kb_dir), "--out", str(tmp_path / "p"), "--json", "--no-baseline"],
    )
    assert first.exit_code == 0, first.output
    partition = next(
        s["result"] for s in json.loads(first.output)["stages"] if s["stage"] == "partition"
    )
    result = CliRunner().invoke(
        cli,
        [
            "transfer",
            "two-rooms",
            "--task",
            "goal:x=9,y=5",
            "--partition",
            partition,
            "--runs",
            "2",
            "--episodes",
            "50",
            "--baseline",
            "--kb",
            str(kb_dir),
            "--out",
            str(tmp_path / "t"),
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert {r["learner"] for r in summary["rows"]} == {"hierarchical", "flat"}
    assert (tmp_path / "t" / "transfer.png").exists()
    bad = CliRunner().invoke(
        cli,
        [
            "transfer",
            "two-rooms",
            "--task",
            "reach-goal",
            "--partition",
            "partition:999",
            "--kb",
            str(kb_dir),
        ],
    )
    assert bad.exit_code == 2 and "partition:999" in bad.output


@pytest.mark.slow
def test_no_subgoals_is_a_reported_outcome_and_the_flat_learner_is_a_choice(tmp_path):
    """Taxi's learned policy has no subgoal for count-exhaustive: instead of failing, the pipeline
    says so and learns the later task on the layer of its reward-state options alone (the
    true-model regime's reward-variation mode) or, in the default inconsistency mode, which
    needs subgoal options, flat; the Gymnasium keyword arguments are stored."""
    args = ["pipeline", "gym:Taxi-v4[is_rainy=false]", "--tasks", "reward,reward", "--runs",
            "10", "--episodes", "20", "--first-episodes", "500", "--kb", str(tmp_path / "kb"),
            "--out", str(tmp_path / "o")]
    res = CliRunner().invoke(cli, [*args, "--json", "--regime", "true-model", "--hier-opt",
                                   "mode=reward-variation+inconsistency"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    stage = next(s for s in summary["stages"] if s["stage"] == "no-subgoals")
    assert "reward-state options alone" in stage["detail"]["reason"]
    assert [r["learner"] for r in summary["tasks"]] == [
        "flat", "hierarchical", "flat", "known-dynamics", "planner"]
    assert summary["tasks"][1]["initial_blocks"] > 1 and summary["tasks"][1]["partition"] is None
    res = CliRunner().invoke(cli, [*args, "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    stage = next(s for s in summary["stages"] if s["stage"] == "no-subgoals")
    assert "no options to build a layer from" in stage["detail"]["reason"]
    assert [r["learner"] for r in summary["tasks"]] == ["flat", "flat-fallback", "flat"]
    kb = KnowledgeBase.open(str(tmp_path / "kb"))
    try:
        env = kb.find_environment("gym:Taxi-v4[is_rainy=false]")
        assert env.spec["make_kwargs"] == {"is_rainy": False}
    finally:
        kb.close()
    bad = CliRunner().invoke(cli, [*args, "--flat-learner", "nope"])
    assert bad.exit_code == 2 and "--flat-learner" in bad.output


@pytest.mark.extended
def test_without_a_learned_first_task_only_the_reward_variation_modes_use_the_layer(tmp_path):
    """One episode does not learn two-rooms' first task, so the knowledge base holds no values to
    predict from: in the default inconsistency mode the later task is learned flat (stage
    ``fallback``); a reward-variation mode builds its layer from the later task's own rewards and
    learns on it (stage ``predict`` says why), and its row says the rewards were known.
    Betweenness finds the doorway without a learned policy."""
    args = ["pipeline", "two-rooms", "--tasks", "reach-goal,goal:x=9,y=5", "--detector",
            "betweenness", "--runs", "3", "--episodes", "30", "--first-episodes", "1",
            "--eval-every", "10", "--no-baseline", "--kb", str(tmp_path / "kb"), "--out",
            str(tmp_path / "o"), "--json"]
    variation = json.loads(CliRunner().invoke(cli, [
        *args, "--hier-opt", "mode=reward-variation+inconsistency", "--regime",
        "true-model"]).output)
    assert variation["tasks"][0]["runs_within_bound"] == 0  # the first task is not learned
    stage = next(s for s in variation["stages"] if s["task"] == "goal:x=9,y=5")
    assert stage["stage"] == "predict" and "holds no values to predict from" in (
        stage["detail"]["reason"])
    assert variation["tasks"][1]["learner"] == "hierarchical"
    assert "options to the task's reward states, solved on the true model" in (
        variation["tasks"][1]["knowledge"])
    assert "rewards known" in variation["tasks"][1]["knowledge"]
    default = json.loads(CliRunner().invoke(cli, [*args, "--regime", "true-model"]).output)
    stage = next(s for s in default["stages"] if s["task"] == "goal:x=9,y=5")
    assert stage["stage"] == "fallback" and "is learned flat" in stage["detail"]["reason"]
    assert default["tasks"][1]["learner"] == "flat-fallback"
    # the learned-model regime decides from what the agent saw, not from V*: its one episode
    # found the goal, so the layer built from that experience is tried
    learned = json.loads(CliRunner().invoke(cli, args).output)
    stage = next(s for s in learned["stages"] if s["task"] == "goal:x=9,y=5")
    assert stage["stage"] == "predict"
    assert stage["detail"]["episodes_ending_in_a_terminal"] == 3  # one per run
    assert learned["tasks"][1]["learner"] == "hierarchical"


@pytest.mark.extended
def test_directed_exploration_is_a_learner_option_and_a_bad_count_is_refused(tmp_path):
    """``--hier-opt explore=r-max`` turns on R-max exploration (docs/hierarchical-learning.md);
    a count below one is refused before the knowledge base is opened."""
    kb_dir = tmp_path / "kb"
    rmax = [*PIPELINE, "--hier-opt", "mode=inconsistency", "--kb", str(kb_dir), "--out",
            str(tmp_path / "o"), "--json", "--regime", "true-model"]
    bad = CliRunner().invoke(cli, [*rmax, "--hier-opt", "explore=r-max",
                                   "--hier-opt", "known-after=0"])
    assert bad.exit_code == 2
    assert bad.output.strip() == ("Error: --hier-opt: learner 'hierarchical': --known-after "
                                  "must be >= 1; got 0")
    assert not kb_dir.exists()
    unplanned = CliRunner().invoke(cli, [*rmax, "--hier-opt", "layer-values=planned"])
    assert unplanned.exit_code == 2 and not kb_dir.exists()
    assert "--layer-values planned" in unplanned.output and "--explore r-max" in unplanned.output
    unsplit = CliRunner().invoke(cli, [*rmax, "--hier-opt", "split-offered=true"])
    assert unsplit.exit_code == 2 and not kb_dir.exists()
    assert "--split-offered" in unsplit.output and "--reference policy" in unsplit.output
    res = CliRunner().invoke(cli, [*rmax, "--hier-opt", "explore=r-max"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    assert summary["config"]["hierarchical_params"]["explore"] == "r-max"
    layer = next(r for r in summary["tasks"] if r["learner"] == "hierarchical")
    assert layer["runs_within_bound"] == layer["runs"] == 3
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        stage = next(s for s in summary["stages"] if s["stage"] == "learn-hierarchical")
        run = kb.get("run", int(stage["result"].split(":")[1]))
        assert run.provenance.parameters["explore"] == "r-max"
        assert run.provenance.parameters["known_after"] == 1
    finally:
        kb.close()
    planned = json.loads(CliRunner().invoke(cli, [*rmax, "--hier-opt", "explore=r-max",
                                                  "--hier-opt", "layer-values=planned"]).output)
    layer = next(r for r in planned["tasks"] if r["learner"] == "hierarchical")
    assert layer["runs_within_bound"] == layer["runs"] == 3
    split = json.loads(CliRunner().invoke(cli, [
        *rmax, "--hier-opt", "explore=r-max", "--hier-opt", "layer-values=planned",
        "--hier-opt", "reference=policy", "--hier-opt", "split-offered=true"]).output)
    layer = next(r for r in split["tasks"] if r["learner"] == "hierarchical")
    assert layer["runs_within_bound"] == layer["runs"] == 3
    assert split["config"]["hierarchical_params"]["split-offered"] == "true"


def test_r_max_in_the_learned_model_regime_plans_unknown_pairs_at_the_first_tasks_ceiling(
        tmp_path):
    """In the learned-model regime the layer explores by R-max unless ``--hier-opt explore=``
    names another rule (``regime.LEARNED_EXPLORATION``); the pipeline gives R-max the ceiling of
    the rewards its first task paid (the new task's own is not read), and the run records both;
    planned layer values, which plan on the true model's transition table, are refused before
    any work."""
    kb_dir = tmp_path / "kb"
    base = [*PIPELINE, "--kb", str(kb_dir)]
    planned = CliRunner().invoke(cli, [*base, "--hier-opt", "layer-values=planned",
                                       "--out", str(tmp_path / "p")])
    assert planned.exit_code == 2 and not kb_dir.exists()
    assert "--layer-values learned" in planned.output
    res = CliRunner().invoke(cli, [*base, "--out", str(tmp_path / "o"), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    layer = next(r for r in summary["tasks"] if r["learner"] == "hierarchical")
    assert "R-max on the counts" in layer["knowledge"]
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        stage = next(s for s in summary["stages"] if s["stage"] == "learn-hierarchical")
        run = kb.get("run", int(stage["result"].split(":")[1]))
        first = resolve_domain("two-rooms").mdp("reach-goal")
        gamma = resolve_domain("two-rooms").mdp(summary["config"]["tasks"][1]).gamma
        paid = float(first.R[first.admissible & ~first.terminal[:, None]].max())
        # two-rooms' moves are sure, so the goal's reward is paid only on a pair that surely
        # arrives: collected once, it is the ceiling (not paid / (1 - gamma), at every step)
        assert paid > 0 and gamma < 1
        assert run.provenance.parameters["value_ceiling"] == pytest.approx(paid)
        assert run.provenance.parameters["explore"] == "r-max"
    finally:
        kb.close()
    chosen = CliRunner().invoke(cli, [*base, "--hier-opt", "explore=optimistic-flat", "--out",
                                      str(tmp_path / "f"), "--json"])
    assert chosen.exit_code == 0, chosen.output
    summary = json.loads(chosen.output)
    layer = next(r for r in summary["tasks"] if r["learner"] == "hierarchical")
    assert "R-max on the counts" not in layer["knowledge"]


@pytest.mark.parametrize(("tasks", "message"), [
    ("reach-goal,no-such-task", "--tasks: environment 'two-rooms' has no task 'no-such-task'"),
    ("reach-goal,goal:x=99", "--tasks: no state matches the goal"),
])
def test_a_bad_later_task_is_refused_before_anything_is_learned_or_stored(tasks, message,
                                                                          tmp_path):
    kb_dir = tmp_path / "kb"
    result = CliRunner().invoke(cli, ["pipeline", "two-rooms", "--tasks", tasks, "--kb",
                                      str(kb_dir), "-q"])
    assert result.exit_code == 2, result.output
    assert result.output.strip().startswith(f"Error: {message}")
    assert not kb_dir.exists()  # nothing was learned, nothing stored


def test_an_estimate_equal_to_the_true_model_serves_the_layer_and_says_it_was_estimated(
        tmp_path):
    """A deterministic first task that tries every pair estimates the true model exactly; the
    knowledge base keys environments by their model's hash, so the estimate and the environment
    share one record. The options built on it still serve the estimate's partition (this once
    stopped the pipeline: 'option:1 belongs to environment ...'), and the layer learner's record
    says the options and the layer came from the estimate."""
    env = "gym:FrozenLake-v1[map_name=4x4,is_slippery=false]"
    res = CliRunner().invoke(cli, ["pipeline", env, "--tasks", "reward,goal:row=0,col=3",
                                   "--runs", "3", "--no-fallback", "--kb", str(tmp_path / "kb"),
                                   "--out", str(tmp_path / "o"), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    kb = KnowledgeBase.open(str(tmp_path / "kb"))
    try:  # the estimate is the true model: one environment record serves both names
        assert len(kb.records("environment")) == 1
    finally:
        kb.close()
    layer = next(r for r in summary["tasks"] if r["learner"] == "hierarchical")
    assert layer["knowledge"].startswith("dynamics estimated")
    assert "option policies solved on the model estimated from run:1" in layer["knowledge"]


def test_a_layer_is_built_over_the_options_left_when_a_subgoal_is_dropped(tmp_path):
    """On the slippery 4x4 lake the eigenoptions' sink 11 (a hole) has no option: it is dropped
    and reported, and the layer is partitioned over the options that exist (it used to ask the
    subgoal set for an option per subgoal and stop)."""
    res = CliRunner().invoke(cli, [
        "pipeline", "gym:FrozenLake-v1[map_name=4x4]", "--tasks", "reward,move-goal:row=0,col=3",
        "--runs", "3", "--episodes", "30", "--first-episodes", "200", "--eval-every", "5",
        "--detector", "eigenoptions", "--no-fallback", "--kb", str(tmp_path / "kb"), "--out",
        str(tmp_path / "o"), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    options = next(s for s in summary["stages"] if s["stage"] == "options")
    dropped = [d["subgoal"] for d in options["detail"]["dropped"]]
    assert 11 in dropped
    kept = options["result"].split(",")
    kb = KnowledgeBase.open(str(tmp_path / "kb"))
    try:
        partition = next(s for s in summary["stages"] if s["stage"] == "partition")
        record = kb.get("partition", int(partition["result"].split(":")[1]))
        assert [f"option:{i}" for i in record.option_ids] == kept
        states = {kb.get("option", i).provenance.parameters["subgoal_state"]
                  for i in record.option_ids}
        assert states and not states & set(dropped)
    finally:
        kb.close()
    assert [r["learner"] for r in summary["tasks"]][:2] == ["flat", "hierarchical"]
