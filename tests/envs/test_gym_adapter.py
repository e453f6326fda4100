"""GymDomain: FiniteMDPs from Gymnasium environments, against independent oracles.

Oracles: a dense policy iteration built straight from Gymnasium's ``P`` dict (with its
per-transition ``terminated`` flags, not our terminal mask); closed-form values of CliffWalking and
deterministic FrozenLake; the exact model for the sampled estimator.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Iterator

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces

from adpart.envs.gym_adapter import GymDomain
from adpart.envs.registry import get_domain
from adpart.errors import ModelError, TaskError, UnknownNameError
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.solvers import solve

GAMMA = 0.99


# ------------------------------------------------------------------ the dense oracle
def dense_from_p(env_id: str, **kwargs):
    """``T[s, a, s']`` (continuing mass only), ``R[s, a]`` and start states, read with loops."""
    env = gymnasium.make(env_id, **kwargs).unwrapped
    S, A = env.observation_space.n, env.action_space.n
    T = np.zeros((S, A, S))
    R = np.zeros((S, A))
    for s in range(S):
        for a in range(A):
            for p, s2, r, done in env.P[s][a]:
                R[s, a] += p * r
                if not done:
                    T[s, a, s2] += p
    return T, R, np.flatnonzero(env.initial_state_distrib > 0), env


def dense_policy_iteration(T: np.ndarray, R: np.ndarray, gamma: float) -> np.ndarray:
    """Howard's policy iteration with numpy.linalg.solve: exact V* of the dense model."""
    S = R.shape[0]
    policy = np.zeros(S, dtype=int)
    while True:
        T_pi = T[np.arange(S), policy]
        V = np.linalg.solve(np.eye(S) - gamma * T_pi, R[np.arange(S), policy])
        Q = R + gamma * T @ V
        best = Q.max(axis=1)
        improve = best > Q[np.arange(S), policy] + 1e-12
        if not improve.any():
            return V
        policy = np.where(improve, Q.argmax(axis=1), policy)


def reachable_from(env, starts) -> np.ndarray:
    """States an episode can occupy: BFS over non-terminating transitions (plain loops)."""
    seen = {int(s) for s in starts}
    queue = deque(seen)
    while queue:
        s = queue.popleft()
        for outcomes in env.P[s].values():
            for p, s2, _, done in outcomes:
                if p > 0 and not done and s2 not in seen:
                    seen.add(s2)
                    queue.append(s2)
    return np.array(sorted(seen))


def exact_values(domain: GymDomain) -> np.ndarray:
    mdp = domain.mdp()
    sol = solve(mdp, 1e-10)
    return policy_evaluation(mdp, sol.policy)


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        ("Taxi-v4", {}),
        ("FrozenLake-v1", {}),
        ("FrozenLake-v1", {"map_name": "8x8"}),
        ("CliffWalking-v1", {}),
        ("CliffWalking-v1", {"is_slippery": True}),
    ],
)
def test_vstar_equals_dense_solve_of_gymnasium_p(env_id, kwargs):
    domain = GymDomain(env_id, gamma=GAMMA, **kwargs)
    T, R, starts, env = dense_from_p(env_id, **kwargs)
    V_oracle = dense_policy_iteration(T, R, GAMMA)
    live = reachable_from(env, starts)
    V = exact_values(domain)
    np.testing.assert_allclose(V[live], V_oracle[live], atol=1e-8, rtol=0)
    np.testing.assert_array_equal(np.flatnonzero(domain.reachable), live)


def test_taxi_model_facts():
    domain = get_domain("gym:Taxi-v4")
    assert isinstance(domain, GymDomain)
    mdp = domain.mdp()
    assert (mdp.n_states, mdp.n_actions) == (500, 6)
    assert mdp.name == "gym:Taxi-v4/reward" and mdp.gamma == GAMMA
    assert mdp.action_names == ("south", "north", "east", "west", "pickup", "dropoff")
    # the four "passenger delivered" states: terminal, and also reached without termination,
    # but only by moves between post-delivery states, which no episode occupies
    env = domain.env.unwrapped
    delivered = sorted(env.encode(r, c, i, i) for i, (r, c) in enumerate(env.locs))
    assert np.flatnonzero(mdp.terminal).tolist() == delivered
    assert domain.done_conflicts.tolist() == delivered
    assert int(domain.reachable.sum()) == 400  # 300 waiting + 100 riding; 404 with deliveries
    assert not domain.estimated and domain.n_samples == 0 and domain.visits is None
    assert domain.initial_source == "env.unwrapped.initial_state_distrib"
    np.testing.assert_allclose(mdp.initial, env.initial_state_distrib)
    facts = domain.model_facts()
    assert facts["terminal_states"] == 4 and facts["estimated"] is False


def test_taxi_features_decode_the_state():
    domain = GymDomain("Taxi-v4")
    feats = domain.dynamics().features
    env = domain.env.unwrapped
    for s in (0, 77, 123, 499):
        assert (
            feats["row"][s],
            feats["col"][s],
            feats["passenger"][s],
            feats["destination"][s],
        ) == env.decode(s)
    np.testing.assert_array_equal(feats["x"], feats["col"])
    # a goal spec over decoded features works on the adapted domain
    task = domain.task("goal:row=0,col=0")
    assert task.terminal.sum() == 20


def test_expected_rewards_merge_duplicate_successors():
    """Slippery FrozenLake lists the same successor twice at walls; P and R must merge them."""
    domain = GymDomain("FrozenLake-v1")
    mdp = domain.mdp()
    env = domain.env.unwrapped
    for s, a in [(0, 0), (0, 3), (14, 2), (6, 1)]:
        dense = np.zeros(16)
        for p, s2, _, _ in env.P[s][a]:
            dense[s2] += p
        cols, probs = mdp.transition_row(s, a)
        assert len(set(cols.tolist())) == cols.size
        np.testing.assert_allclose(np.bincount(cols, probs, minlength=16), dense)
        assert mdp.R[s, a] == pytest.approx(sum(p * r for p, _, r, _ in env.P[s][a]))


def test_closed_form_values():
    """CliffWalking: 13 steps of -1 along the cliff; FrozenLake (not slippery): 6 steps, +1."""
    cliff = GymDomain("CliffWalking-v1", gamma=GAMMA)
    V = exact_values(cliff)
    assert V[36] == pytest.approx(-(1 - GAMMA**13) / (1 - GAMMA), abs=1e-9)
    lake = GymDomain("FrozenLake-v1", is_slippery=False, gamma=0.9)
    assert exact_values(lake)[0] == pytest.approx(0.9**5, abs=1e-9)
    assert lake.name == "gym:FrozenLake-v1[is_slippery=False]"
    assert set(lake.dynamics().features) == {"state", "row", "col", "x", "y"}


# ------------------------------------------------------------------ sampled estimator
def _p_errors(estimated: GymDomain, exact: GymDomain) -> tuple[np.ndarray, np.ndarray]:
    """Per-pair max |P_hat - P| and visit counts over the pairs an episode can meet."""
    live = estimated.reachable & ~estimated.mdp().terminal
    diff = (estimated.mdp().P - exact.mdp().P).toarray().reshape(4, 16, 16)
    return np.abs(diff[:, live]).max(axis=2).T, estimated.visits[live]


def test_sampled_model_approaches_the_exact_one():
    exact = GymDomain("FrozenLake-v1")
    few = GymDomain("FrozenLake-v1", model="sampled", samples=2_000, seed=1)
    many = GymDomain("FrozenLake-v1", model="sampled", samples=40_000, seed=1)
    assert many.estimated and many.n_samples == 40_000
    assert int(many.visits.sum()) == 40_000
    live = many.reachable & ~many.mdp().terminal
    assert not many.unvisited[live].any()  # every pair an episode can meet was sampled
    assert many.unvisited[many.mdp().terminal].all()  # episodes end there: placeholders
    err, visits = _p_errors(many, exact)
    # Hoeffding + union bound over the 16 successors of all 44 pairs, failure prob 1e-3
    assert np.all(err <= np.sqrt(np.log(2 * 16 * 44 / 1e-3) / (2 * visits)))
    assert err[visits >= 1000].max() < 0.05  # well-visited pairs are close
    assert err.max() < _p_errors(few, exact)[0].max()  # more samples, smaller worst error
    np.testing.assert_array_equal(many.mdp().terminal, exact.mdp().terminal)
    r_err = np.abs(many.mdp().R[live] - exact.mdp().R[live])  # rewards lie in [0, 1]
    assert np.all(r_err <= np.sqrt(np.log(2 * 44 / 1e-3) / (2 * visits)))
    np.testing.assert_array_equal(many.mdp().initial, exact.mdp().initial)
    assert many.model_facts()["unvisited_reachable_pairs"] == 0


def test_sampling_is_seeded():
    a = GymDomain("FrozenLake-v1", model="sampled", samples=3_000, seed=4)
    b = GymDomain("FrozenLake-v1", model="sampled", samples=3_000, seed=4)
    c = GymDomain("FrozenLake-v1", model="sampled", samples=3_000, seed=5)
    assert a.mdp().content_hash == b.mdp().content_hash != c.mdp().content_hash


class NoModelChain(gymnasium.Env):
    """A 4-state stochastic chain without ``P``: 'right' advances w.p. 0.5; state 3 ends."""

    def __init__(self, conflict: bool = False):
        self.observation_space = spaces.Discrete(4)
        self.action_space = spaces.Discrete(2)
        self.conflict = conflict
        self.s = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.s = 0
        return self.s, {}

    def step(self, action):
        # with conflict=True, 'left' in state 0 jumps to 2 and play goes on, but arriving in 2
        # from 1 ends the episode: termination depends on the path
        if self.conflict and self.s == 0 and action == 0:
            self.s = 2
            return self.s, -1.0, False, False, {}
        moved = action == 1 and self.np_random.random() < 0.5
        self.s = min(self.s + 1, 3) if moved else self.s
        done = self.s == 3 or (self.conflict and moved and self.s == 2)
        return self.s, -1.0, bool(done), False, {}


class BadP(gymnasium.Env):
    """A model whose state 1 is reached both with and without termination, from start state 0."""

    def __init__(self):
        self.observation_space = spaces.Discrete(2)
        self.action_space = spaces.Discrete(2)
        self.P = {
            0: {0: [(1.0, 1, 0.0, True)], 1: [(1.0, 1, 0.0, False)]},
            1: {0: [(1.0, 1, 0.0, True)], 1: [(1.0, 1, 0.0, True)]},
        }
        self.initial_state_distrib = np.array([1.0, 0.0])

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        return 1, 0.0, True, False, {}


class BoxActions(NoModelChain):
    """Discrete observations, continuous actions."""

    def __init__(self):
        super().__init__()
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,))


@pytest.fixture
def test_envs() -> Iterator[None]:
    ids = {
        "adpart-test/NoModel-v0": NoModelChain,
        "adpart-test/BadP-v0": BadP,
        "adpart-test/BoxActions-v0": BoxActions,
    }
    for gid, cls in ids.items():
        gymnasium.register(id=gid, entry_point=cls, max_episode_steps=50)
    try:
        yield
    finally:
        for gid in ids:
            del gymnasium.registry[gid]


def test_env_without_p_is_estimated_and_unvisited_pairs_flagged(test_envs):
    domain = GymDomain("adpart-test/NoModel-v0", samples=4_000, seed=0)
    mdp = domain.mdp()
    assert domain.estimated and "estimated from 4000" in domain.description
    assert mdp.terminal.tolist() == [False, False, False, True]
    np.testing.assert_allclose(mdp.transition_row(1, 1)[1], [0.5, 0.5], atol=0.06)
    assert domain.unvisited[3].all() and not domain.unvisited[:3].any()
    assert mdp.transition_row(3, 0)[0].tolist() == [3]  # placeholder self-loop
    assert domain.model_facts()["n_samples"] == 4_000
    assert solve(mdp).converged


def test_exact_model_required_but_missing(test_envs):
    with pytest.raises(ModelError, match=r"no env\.unwrapped\.P"):
        GymDomain("adpart-test/NoModel-v0", model="exact")


def test_termination_that_depends_on_the_path_is_an_error(test_envs):
    with pytest.raises(ModelError, match=r"state 1 is reached with terminated=True"):
        GymDomain("adpart-test/BadP-v0").mdp()
    with pytest.raises(ModelError, match=r"state 2 is reached with terminated=True"):
        GymDomain("adpart-test/NoModel-v0", conflict=True, samples=2_000).mdp()


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize(
    ("env_id", "hint"),
    [
        ("Taxi-v99", "Taxi-v4"),
        ("Taxy-v4", "Taxi-v4"),
        ("NoSuchEnv-v0", None),
        ("no_such_module:Env-v0", None),
    ],
)
def test_unknown_ids_raise_unknown_name(env_id, hint):
    with pytest.raises(UnknownNameError, match="Gymnasium has no environment") as info:
        get_domain(f"gym:{env_id}")
    if hint:
        assert f"Did you mean gym:{hint}?" in str(info.value)


def test_non_discrete_spaces_raise_model_error_naming_the_space(test_envs):
    with pytest.raises(ModelError, match=r"observation space Box\(.*Discrete observation"):
        GymDomain("CartPole-v1")
    with pytest.raises(ModelError, match=r"action space Box\("):
        GymDomain("adpart-test/BoxActions-v0")


def test_bad_arguments_raise_clear_errors():
    with pytest.raises(ModelError, match="rejected the arguments"):
        GymDomain("Taxi-v4", no_such_option=True)
    with pytest.raises(ModelError, match="fickle_passenger"):
        GymDomain("Taxi-v4", fickle_passenger=True)
    with pytest.raises(TaskError, match="model="):
        GymDomain("Taxi-v4", model="guess")
    with pytest.raises(TaskError, match="gamma"):
        GymDomain("Taxi-v4", gamma=1.5)
    with pytest.raises(UnknownNameError, match="has no task"):
        GymDomain("Taxi-v4").task("deliver")


def test_gym_names_carry_keyword_arguments_and_round_trip():
    from adpart.envs.registry import get_domain, parse_gym_name
    from adpart.errors import UnknownNameError

    env_id, kw = parse_gym_name("gym:FrozenLake-v1[map_name=8x8,is_slippery=true]")
    assert env_id == "FrozenLake-v1" and kw == {"map_name": "8x8", "is_slippery": True}
    assert parse_gym_name("gym:Taxi-v4") == ("Taxi-v4", {})
    dom = get_domain("gym:FrozenLake-v1[map_name=8x8,is_slippery=False]")
    assert dom.dynamics().n_states == 64 and dom.make_kwargs["is_slippery"] is False
    # the domain's own name reads back to the same environment
    again = get_domain(dom.name)
    assert again.dynamics().content_hash == dom.dynamics().content_hash
    with pytest.raises(UnknownNameError, match="key=value"):
        parse_gym_name("gym:FrozenLake-v1[map_name]")
    with pytest.raises(UnknownNameError, match=r"gym:ID\[key=value"):
        parse_gym_name("gym:FrozenLake-v1[map_name=8x8")


def test_a_map_is_given_as_json_or_from_a_file_and_named_back_alike(tmp_path):
    """``desc`` as a JSON list of strings in the name (its commas do not split the bracket), or
    ``@FILE`` (one row a line): both give the map Gymnasium builds from that ``desc``, and the
    domain's name writes the value as JSON, which the parser reads back to the same model."""
    from adpart.envs.registry import get_domain, parse_gym_name

    rows = ["SFFF", "FHFH", "FFFH", "HFFG"]
    name = 'gym:FrozenLake-v1[desc=["SFFF","FHFH","FFFH","HFFG"],is_slippery=false]'
    assert parse_gym_name(name) == ("FrozenLake-v1", {"desc": rows, "is_slippery": False})
    (tmp_path / "map.txt").write_text("\n".join(rows) + "\n\n")
    from_file = get_domain(f"gym:FrozenLake-v1[desc=@{tmp_path / 'map.txt'},is_slippery=false]")
    inline = get_domain(name)
    assert inline.dynamics().content_hash == from_file.dynamics().content_hash
    assert get_domain(inline.name).dynamics().content_hash == inline.dynamics().content_hash
    four = get_domain("gym:FrozenLake-v1[map_name=4x4,is_slippery=false]")
    assert four.dynamics().content_hash == inline.dynamics().content_hash  # the 4x4 map itself


@pytest.mark.parametrize(("name", "message"), [
    ("gym:FrozenLake-v1[map_name=none]", "gives another model on every construction"),
    ("gym:tabular/CliffWalking-v0", "needs a package that is not installed"),
    ('gym:FrozenLake-v1[desc=["SFFF",]', "cannot read"),
    ("gym:FrozenLake-v1[desc=@/no/such/map.txt]", "cannot read desc=@/no/such/map.txt"),
    ("gym:Taxi-v4[random_map=8]", "draws a FrozenLake map"),
    ("gym:FrozenLake-v1[map_seed=3]", "give both"),
])
def test_an_environment_that_names_no_single_mdp_is_one_clear_error(name, message):
    """Each is refused with an adpart error naming the fix (the CLI prints it as one line):
    an unseeded random map, a module that is not installed, malformed JSON, a missing file,
    a random map on another environment, a map seed without a size."""
    from adpart.envs.registry import get_domain
    from adpart.errors import AdpartError

    with pytest.raises(AdpartError, match=re.escape(message)):
        get_domain(name)


def test_a_seeded_random_map_is_the_same_map_every_time():
    """``random_map=SIZE,map_seed=N`` draws Gymnasium's random map with that seed: the same
    model on every construction, another for another seed."""
    from adpart.envs.registry import get_domain

    a, b = (get_domain("gym:FrozenLake-v1[random_map=6,map_seed=3]") for _ in range(2))
    other = get_domain("gym:FrozenLake-v1[random_map=6,map_seed=4]")
    assert a.n_states == 36
    assert a.dynamics().content_hash == b.dynamics().content_hash
    assert a.dynamics().content_hash != other.dynamics().content_hash
