"""End to end: learned tasks in a real SQLite knowledge base -> stored hierarchy partitions."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest

from adpart.errors import TaskError
from adpart.hierarchy import discounted_occupancy, expected_time, option_values
from adpart.hierarchy.greedy import column_splits
from adpart.hierarchy.layers import expected_time_layer, stable_option_splits
from adpart.learning.smdp_q import option_set
from adpart.mdp.solvers import q_from_v, solve
from adpart.options import doorway_options, option_model
from adpart.partition import Partition, check_stability
from adpart.partition.partition import block_all
from adpart.store import KnowledgeBase
from adpart.workflows.hierarchy import build_hierarchy, load_inputs
from tests.hierarchy.conftest import store_domain


def test_option_values_agree_with_the_exact_option_model(four_rooms_kb):
    _, data = four_rooms_kb
    mdp = data["domain"].mdp("G2")
    V = solve(mdp).V
    options = doorway_options(data["domain"].mdp("G1"))
    got = option_values(mdp, options, V)
    for j, opt in enumerate(options):  # oracle: R_o + F_o V from the options module
        model = option_model(mdp, opt, duration=False)
        rows = model.admissible
        np.testing.assert_allclose(got[rows, j], (model.R + model.F @ V)[rows], atol=1e-9)
        assert np.all(got[opt.initiation & mdp.terminal, j] == -np.inf)
    assert np.all(got <= V[:, None] + 1e-9)  # no option beats the optimal value


def test_occupancy_agrees_with_power_iteration(four_rooms_kb):
    _, data = four_rooms_kb
    mdp = data["domain"].mdp("G1")
    pi = solve(mdp).policy
    d = discounted_occupancy(mdp, pi, starts="start")
    S = mdp.n_states
    P = mdp.P[pi * S + np.arange(S)].toarray()
    P[mdp.terminal] = 0.0
    mu = np.where(mdp.terminal, 0.0, mdp.initial)
    mu = mu / mu.sum()
    x, acc = mu.copy(), mu.copy()
    for _ in range(2000):  # sum_t gamma^t mu P^t, terminal states absorb nothing
        x = mdp.gamma * (x @ P)
        x[mdp.terminal] = 0.0
        acc += x
    np.testing.assert_allclose(d, acc / acc.sum(), atol=1e-9)


def test_reachable_occupancy_spreads_over_every_reachable_state(four_rooms_kb):
    from adpart.hierarchy.tasks import reachable_states

    _, data = four_rooms_kb
    mdp = data["domain"].mdp("G1")
    pi = solve(mdp).policy
    d = discounted_occupancy(mdp, pi)  # default: every reachable state is a start
    narrow = discounted_occupancy(mdp, pi, starts="start")
    reach = reachable_states(mdp, mdp.initial > 0)
    assert np.all(d[reach & ~mdp.terminal] > 0) and np.all(d[~reach | mdp.terminal] == 0)
    assert (d > 0).sum() >= (narrow > 0).sum()
    # oracle: mean of the per-start occupancies (unnormalised visit counts) over the starts
    starts = np.flatnonzero(reach & ~mdp.terminal)
    S = mdp.n_states
    P = mdp.P[pi * S + np.arange(S)].toarray()
    P[mdp.terminal] = 0.0
    P[:, mdp.terminal] = 0.0
    N = np.linalg.solve(np.eye(S) - mdp.gamma * P.T, np.eye(S)[:, starts]).sum(axis=1)
    N[mdp.terminal] = 0.0
    np.testing.assert_allclose(d, N / N.sum(), atol=1e-9)
    with pytest.raises(TaskError, match="starts"):
        discounted_occupancy(mdp, pi, starts="everywhere")


def test_expected_learning_time_layer_is_stored_with_lineage(four_rooms_kb, estimator_registry):
    kb, data = four_rooms_kb
    g1 = data["tasks"]["G1"]
    labels = np.arange(kb.get("environment", data["env"].id).n_states) % 3
    learned_on = kb.put_partition(data["env"], "learned", labels, task=g1,
                                  block_actions=np.ones((3, 4), dtype=bool), epsilon=0.0, delta=0.0)
    res = build_hierarchy(kb, "four-rooms")
    assert res.partition_id is not None
    rec = kb.get("partition", res.partition_id)
    assert rec.kind == "hierarchy" and rec.n_blocks == res.n_blocks
    assert learned_on.id in rec.parent_ids
    assert [p.id for p in kb.lineage(rec)] == [learned_on.id]
    assert list(rec.option_ids) == res.option_ids
    stored = Partition(kb.load(rec, "labels"), kb.load(rec, "block_actions").astype(bool))
    assert stored == res.partition
    # every block offers a column every state of it may start (what the learner checks)
    inputs = load_inputs(kb, "four-rooms")
    cols = list(range(4)) + [4 + inputs.option_ids.index(i) for i in res.option_ids]
    allowed = block_all(stored.labels, stored.n_blocks, inputs.admissible[:, cols])
    assert stored.admissible.any(axis=1).all()
    assert not (stored.admissible & ~allowed).any()
    trace = np.asarray(res.trace)
    assert np.all(np.diff(trace) < 0) and res.estimate <= trace[0]
    assert 1 < res.n_blocks < inputs.mdp.n_states
    assert res.summary()["partition"] == f"partition:{rec.id}"


def test_all_subgoals_layer_and_comparison(four_rooms_kb, estimator_registry):
    kb, _ = four_rooms_kb
    auto = build_hierarchy(kb, "four-rooms", store=False)
    subgoals = build_hierarchy(kb, "four-rooms", estimator="all-subgoals",
                               params={"delta": 0.3})
    assert auto.partition_id is None
    assert kb.get("partition", subgoals.partition_id).kind == "hierarchy"
    assert len(subgoals.option_ids) == 4  # every doorway option is offered somewhere
    assert subgoals.partition.admissible.any(axis=1).all()
    # Algorithm 3 is greedy over option splits (it cannot isolate a goal that is no subgoal),
    # so the heuristic layer may score better; both are compared with the flat MDP
    assert auto.flat_estimate == pytest.approx(104 * 104 * 4) and not auto.fallback
    assert auto.estimate < auto.flat_estimate and subgoals.estimate < auto.flat_estimate


def test_refined_with_an_option_means_its_own_delta_stable_partition(four_rooms_kb):
    kb, _ = four_rooms_kb
    inputs = load_inputs(kb, "four-rooms")
    A = inputs.mdp.n_actions
    _, smdp = option_set(inputs.mdp, inputs.options, include_primitives=True)
    splits = stable_option_splits(inputs.mdp, inputs.options, inputs.admissible,
                                  inputs.termination, delta=0.3)
    phase1 = column_splits(inputs.admissible, inputs.termination)
    for o in range(A, smdp.n_actions):
        own = Partition.from_labels(splits[o], smdp.admissible)
        only_o = np.zeros_like(own.admissible)
        only_o[:, [o]] = block_all(own.labels, own.n_blocks, smdp.admissible[:, [o]])
        report = check_stability(own.with_admissible(only_o), smdp, options=[o], delta=0.3)
        assert report.ok, report.violations[:3]
        # a refinement of phase 1's blocks: each own block lies in one phase-1 block
        assert all(len(np.unique(phase1[o][splits[o] == b])) == 1 for b in range(own.n_blocks))
    layer, _, steps, _ = expected_time_layer(inputs, delta=0.3, c=1.0)
    assert steps
    former, _, _, _ = expected_time_layer(inputs, delta=None, c=1.0)  # `--delta none`: phase 1
    for built, by in ((layer, splits), (former, phase1)):
        for b, row in enumerate(built.admissible):  # every offered option's split went through b
            members = built.labels == b
            for o in np.flatnonzero(row[A:]) + A:
                assert len(np.unique(by[o][members])) == 1


def test_task_selection_weights_and_errors(four_rooms_kb, estimator_registry):
    kb, data = four_rooms_kb
    one = load_inputs(kb, "four-rooms", tasks=["G1"])
    assert [t.name for t in one.tasks] == ["G1"]
    both = load_inputs(kb, "four-rooms", weights={"G1": 3.0})
    assert [t.weight for t in both.tasks] == [3.0, 1.0]
    res = build_hierarchy(kb, "four-rooms", tasks=["task:1"], store=False)
    assert res.task_ids == [data["tasks"]["G1"].id]
    assert res.estimate == pytest.approx(expected_time(one.tasks, _full(res, one),
                                                       n_primitives=4, c=1.0).total)
    with pytest.raises(TaskError, match="no learned task"):
        load_inputs(kb, "four-rooms", tasks=["nope"])
    with pytest.raises(TaskError, match="one per task"):
        load_inputs(kb, "four-rooms", weights=[1.0])


def _full(res, inputs) -> Partition:
    """The result's layer over all input columns (pruned option columns put back as False)."""
    A = inputs.mdp.n_actions
    adm = np.zeros((res.n_blocks, inputs.admissible.shape[1]), dtype=bool)
    adm[:, :A] = res.partition.admissible[:, :A]
    for k, oid in enumerate(res.option_ids):
        adm[:, A + inputs.option_ids.index(oid)] = res.partition.admissible[:, A + k]
    return Partition(res.partition.labels, adm)


def test_two_rooms_and_an_empty_environment(tmp_path, estimator_registry):
    kb = KnowledgeBase.open(tmp_path / "kb")
    try:
        store_domain(kb, "two-rooms", ["reach-goal"])
        res = build_hierarchy(kb, "two-rooms")
        assert res.n_blocks >= 1
        # two-rooms' one doorway option does not fit the task anywhere (its goal is no
        # subgoal): no option split pays, and refining the one block costs more than learning
        # the 55 states flat, so the estimator falls back (flat: 55 * 55 * 8)
        assert res.flat_estimate == pytest.approx(55 * 55 * 8)
        assert res.fallback and res.flat_estimate <= min(res.trace[-1], res.estimate)
        from adpart.envs.registry import get_domain

        dyn = get_domain("four-rooms").dynamics()
        kb.put_environment("four-rooms", model_hash=dyn.content_hash, n_states=dyn.n_states,
                           n_actions=dyn.n_actions)
        with pytest.raises(TaskError, match="no learned task"):
            build_hierarchy(kb, "four-rooms")
    finally:
        kb.close()


def test_q_from_stored_policy_is_used(four_rooms_kb):
    kb, data = four_rooms_kb
    mdp = data["domain"].mdp("G1")
    inputs = load_inputs(kb, "four-rooms", tasks=["G1"])
    Q = q_from_v(mdp, solve(mdp).V)
    live = ~mdp.terminal
    np.testing.assert_allclose(inputs.tasks[0].Q[live, :4], np.where(
        mdp.admissible, Q, -np.inf)[live])


def test_blocks_the_estimate_calls_consistent_lose_nothing(four_rooms_kb, estimator_registry):
    """Oracle: the exact SMDP of the built layer, with the blocks the estimate says will be
    refined opened to the task's resolution (per state, primitives added) and the other blocks
    held to one column each. The committed policy (the estimator's column per block, the greedy
    primitive per refined state), evaluated exactly, is within L of V* at the start."""
    from adpart.hierarchy.estimator import expected_time as estimate
    from adpart.learning.curves import start_distribution
    from adpart.learning.smdp_q import option_set
    from adpart.mdp.evaluation import policy_evaluation

    kb, data = four_rooms_kb
    res = build_hierarchy(kb, "four-rooms", store=False)
    inputs = load_inputs(kb, "four-rooms")
    layer = _full(res, inputs)
    A = inputs.mdp.n_actions
    for task in inputs.tasks:
        mdp = data["domain"].mdp(task.name)
        est = estimate([task], layer, n_primitives=A, c=1.0)
        _, smdp = option_set(mdp, inputs.options, include_primitives=True)
        V = solve(mdp, 1e-10).V
        Q = smdp.R + (smdp.F @ V).reshape(smdp.n_actions, -1).T
        refined = est.p_refine[0][layer.labels] > 0
        col = est.committed[0][layer.labels]
        prim = np.argmax(np.where(mdp.admissible, Q[:, :A], -np.inf), axis=1)
        pol = np.where(refined | (col < 0), prim, col)
        v = start_distribution(mdp) @ policy_evaluation(smdp, pol)
        assert v >= start_distribution(mdp) @ V - max(task.threshold, 1e-9) - 1e-9


class _OneBlock:
    """A third-party estimator: one block offering every option all its states may start."""

    name = "one-block"
    description = "one block (test plugin)"
    params = ()
    seen: ClassVar[list] = []

    def build(self, inputs):
        from adpart.hierarchy.layers import fill_empty_blocks, layer_result

        _OneBlock.seen.append(inputs)
        S = inputs.mdp.n_states
        layer = fill_empty_blocks(Partition(np.zeros(S, dtype=np.int64),
                                            inputs.admissible.all(axis=0, keepdims=True)),
                                  inputs.admissible, inputs.mdp.n_actions)
        return layer_result(inputs, layer, estimator=self.name, trace=[1.0], steps=[],
                            estimate=1.0, parameters={}, seconds={"construction": 0.0})


class _OldContract(_OneBlock):
    name = "old-contract"

    def build(self, knowledge_base, environment, *, tasks=None, store=True):
        raise AssertionError("never called")


def test_the_workflow_loads_calls_and_stores_a_third_party_estimator(four_rooms_kb,
                                                                     estimator_registry):
    from adpart.errors import PluginError
    from adpart.plugins.registry import PluginSpec

    kb, data = four_rooms_kb
    for cls in (_OneBlock, _OldContract):
        estimator_registry.add(PluginSpec("hierarchy-estimator", cls.name, cls, "test", "0"))
    res = build_hierarchy(kb, "four-rooms", estimator="one-block", tasks=["G2"])
    (inputs,) = _OneBlock.seen  # what the workflow loaded, nothing else
    assert inputs.task_ids == [data["tasks"]["G2"].id]
    assert inputs.option_ids == [r.id for r in data["options"]]
    rec = kb.get("partition", res.partition_id)
    assert rec.kind == "hierarchy" and rec.provenance.plugin == "one-block"
    assert rec.n_blocks == 1 and list(rec.option_ids) == res.option_ids
    assert rec.provenance.parameters["tasks"] == res.task_ids
    assert list(res.seconds) == ["inputs", "construction", "store"]
    with pytest.raises(PluginError, match=r"'old-contract' \(test\) has build\(knowledge_base"):
        build_hierarchy(kb, "four-rooms", estimator="old-contract")
