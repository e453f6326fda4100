"""A peer's option generators on adpart's MDPs: the ``simpleoptions`` package as a detector.

``simpleoptions`` (J. Evans, University of Bath; PyPI, pinned to 0.11.0 by the optional extra
``pip install 'adpart[simpleoptions]'``) implements, on its own environment interface
(``simpleoptions.BaseEnvironment``), three option-discovery methods whose subgoals adpart can
learn options to:

* **betweenness** (Şimşek & Barto 2008, "Skill Characterization Based on Betweenness"):
  ``nx.betweenness_centrality(stg, normalized=True, endpoints=True)`` of the state-transition
  graph ``stg`` (``nx.betweenness_centrality_subset`` towards the goal states with ``goals``), and
  the states more central than each of their neighbours (``_is_local_maxima``; on a directed
  graph networkx's neighbours are the successors);
* **eigenoptions** (Machado, Bellemare & Bowling 2017, "A Laplacian Framework for Option
  Discovery in Reinforcement Learning", section 3): the eigenvectors ("proto-value functions",
  PVFs) of the normalised Laplacian of the undirected graph, from a dense ``scipy.linalg.eigh``,
  each with both signs, and an option per PVF trained by policy iteration on the eigenpurpose
  ``e(s') - e(s)`` with a terminate action (discount ``gamma``); its **sinks** are the states where
  the trained policy terminates;
* **diffusion options** (the diffusion-distance score of the random walk's polar decomposition,
  ``DiffusionOptionGenerator.compute_f`` at a time scale ``t``): subgoals are the local maxima of
  the score.

This module is the bridge: :func:`mdp_environment` presents a :class:`~adpart.mdp.FiniteMDP` as a
``BaseEnvironment`` (states and actions are adpart's integer ids), the three functions
:func:`so_betweenness`, :func:`so_eigenoptions` and :func:`so_diffusion` run the package's code on
it, and :func:`detect_simpleoptions` turns the result into a
:class:`~adpart.subgoals.result.SubgoalResult` (the ``simpleoptions`` subgoal detector). The
package is imported only when one of them runs (:func:`import_simpleoptions`).

**The environment.** ``get_successors(s, actions)`` lists ``((s', R(s, a)), p)`` for every
admissible action given (all by default) and every outcome of positive probability, ``p`` being
``P(s' | s, a)`` divided by the number of actions (the uniformly random action's transition
probabilities, which is what the package's weighted graph sums), outcomes of an action by
decreasing probability, then by state id. The initial states are the support of ``mdp.initial``;
the state space is what the package's own graph search reaches from them. By default no state is
terminal (``terminals=False``): the graph is the environment's, a task's goal being a cell of
another task, as in adpart's own detectors
(:func:`~adpart.subgoals.literature.transition_graph`); ``terminals=True`` presents the task's
terminal states as terminal (the search does not pass them, eigenoptions never enter them).
A move that stays in place (a bump into a wall) is an outcome of its action, but by default not an
edge of the state-transition graph (``self_loops=False``): neither Şimşek & Barto's graph nor
Machado et al.'s has self-loops, and a self-loop changes a state's degree in the normalised
Laplacian. ``reset`` and ``step`` sample with the environment's own ``random.Random(0)``, never the
global generator.

**Where the bridge does more than call ``generate_options``** (each checked by
``tests/subgoals/test_simpleoptions_bridge.py``):

* ``BetweennessOptionGenerator.generate_options`` builds each option's initiation set from
  ``nx.single_target_shortest_path_length``, which returns a dict since networkx 3.5; 0.11.0 reads
  it as ``(node, distance)`` pairs and fails with a ``TypeError`` after the subgoals are chosen. The
  bridge runs the subgoal part of the method, the same calls: the package's
  ``generate_interaction_graph``, networkx's centrality as the package calls it, its
  ``_is_local_maxima`` and its order (most central first, ``top`` of them).
* ``EigenoptionGenerator.train_option`` reads ``get_successors(s, [a])[0]`` as the next state
  itself, not the ``((s', r), p)`` its ``BaseEnvironment`` documents (and its own graph search
  unpacks); it plans on one outcome per action. The bridge trains each option on a view of the
  environment that answers with the outcomes' states, most likely first, so on a stochastic MDP
  the package plans on the most likely outcome of each action (adpart's
  :func:`~adpart.subgoals.spectral.eigenpurpose_values` takes the expectation). Its ``Eigenoption``
  also reads ``env.options``, which the adapter provides.
* The package's PVF ``0`` is the eigenvector of eigenvalue 0 (``D^{1/2} 1``, the stationary
  distribution's square root, not a constant); Machado et al. skip it. ``k`` counts the
  non-constant PVFs, as adpart's ``eigenoptions`` detector does: the package is asked for
  ``k + 1`` and the options ``0`` and ``-0`` are dropped.
* Option policies are not learnt (betweenness and diffusion options by Q-learning with
  ``max_steps = 0``): adpart learns its own options to the subgoals.
* The package's progress bars (``tqdm``, which 0.11.0 imports without declaring it) are silenced.

The settings are :class:`SimpleOptionsSettings`. The comparison with adpart's own detectors on
two-rooms, four-rooms and three-floor is in docs/subgoals.md ("A peer's implementations").
"""

from __future__ import annotations

import contextlib
import functools
import io
import random
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from adpart.errors import AdpartError, TaskError
from adpart.params import setting, settings, settings_dict
from adpart.subgoals.settings import SINK_RULES, given

if TYPE_CHECKING:
    import numpy as np

    from adpart.mdp.model import FiniteMDP
    from adpart.subgoals.result import SubgoalResult

# numpy, scipy and adpart's MDP code are imported where used: the settings class is read by the
# plugin's --help, which imports no numerical module (tests/cli/test_cli_help_imports.py).

__all__ = [
    "INSTALL_HINT",
    "METHODS",
    "SO_VERSION",
    "SimpleOptionsEigenoption",
    "SimpleOptionsMissingError",
    "SimpleOptionsSettings",
    "detect_simpleoptions",
    "import_simpleoptions",
    "mdp_environment",
    "so_betweenness",
    "so_diffusion",
    "so_eigenoptions",
]

#: The release the bridge is written against (the extra pins it).
SO_VERSION = "0.11.0"
INSTALL_HINT = "pip install 'adpart[simpleoptions]'"
#: The package's generators the detector runs.
METHODS = ("betweenness", "eigenoptions", "diffusion")
#: A PVF's entries within this times its range of its largest sink value are tied extremes
#: (as :data:`adpart.subgoals.spectral.TIE_RTOL`).
TIE_RTOL = 1e-8
#: The package's terminate action in an eigenoption's policy.
_TERMINATE = "EIG_TERMINATE"


class SimpleOptionsMissingError(AdpartError, ImportError):
    """The optional package ``simpleoptions`` (or a module it imports) is not installed."""


def import_simpleoptions() -> Any:
    """``simpleoptions.implementations`` (the generators), or an error naming the extra.

    0.11.0's generators import ``tqdm`` and ``scipy``, which it does not declare; the extra
    installs ``tqdm`` too, and a missing one is named in the message.
    """
    try:
        import simpleoptions.implementations as impl
    except ImportError as exc:
        missing = getattr(exc, "name", None) or "simpleoptions"
        raise SimpleOptionsMissingError(
            f"the simpleoptions detector needs the optional package 'simpleoptions' "
            f"({SO_VERSION}), which could not be imported (missing module {missing!r}); install "
            f"the extra with {INSTALL_HINT}"
        ) from None
    return impl


def _discount(gamma: float) -> None:
    if not 0.0 < gamma < 1.0:
        raise TaskError("the eigenoptions' discount must be in (0, 1), e.g. 0.9 (simpleoptions' "
                        "policy iteration stops when a sweep changes values by < 1e-8)")


@settings
class SimpleOptionsSettings:
    """simpleoptions' betweenness, eigenoptions or diffusion options as subgoals (one method)."""

    generator: str = setting("betweenness", choices=METHODS)
    """generator: betweenness (Simsek & Barto 2008), eigenoptions (Machado et al. 2017) or
    diffusion (diffusion options)."""

    top: int = setting(0, min=0)
    """betweenness and diffusion: keep the top local maxima by score (the package's
    num_options); 0 = all of them."""

    directed_graph: bool = setting(True)
    """betweenness: on the directed state-transition graph (true) or the undirected one."""

    goal_paths: bool = setting(False)
    """betweenness: count only shortest paths ending at the task's terminal states (the
    package's goal_states, networkx's betweenness_centrality_subset)."""

    k: int = setting(4, min=1)
    """eigenoptions: non-constant PVFs used, each with both signs (the package is asked for
    k + 1; its PVF 0, of eigenvalue 0, is dropped)."""

    discount: float = setting(0.9, min=0.0, max=1.0, check=_discount)
    """eigenoptions: discount of the package's policy iteration, in (0, 1)."""

    sinks: str = setting("extreme", choices=SINK_RULES)
    """eigenoptions: subgoals of an option: extreme (its sinks of largest PVF value) or all
    (every state where its policy terminates)."""

    time_scale: int = setting(8, min=1)
    """diffusion: the time scale t of the diffusion score (the package's example: 8)."""

    terminals: bool = setting(False)
    """present the task's terminal states as terminal (false: the environment's graph, as
    adpart's own detectors take it)."""

    self_loops: bool = setting(False)
    """keep moves that stay in place as self-loop edges of the state-transition graph (false:
    the papers' graphs)."""


# --------------------------------------------------------------------------- the environment


def _successor_lists(mdp: FiniteMDP) -> list[list[list[tuple[tuple[int, float], float]]]]:
    """``out[s][a]``: ``[((s', R(s, a)), P(s'|s, a)), ...]`` by decreasing probability, then id;
    empty for an inadmissible pair. One lexsort of the nonzeros, then plain lists."""
    import numpy as np
    import scipy.sparse as sp

    S, A = mdp.n_states, mdp.n_actions
    P = sp.coo_array(mdp.P)
    keep = P.data > 0
    row, col, p = P.row[keep].astype(np.int64), P.col[keep].astype(np.int64), P.data[keep]
    s, a = row % S, row // S
    live = mdp.admissible[s, a]
    row, col, p, s, a = row[live], col[live], p[live], s[live], a[live]
    order = np.lexsort((col, -p, a, s))
    row, col, p, s, a = row[order], col[order], p[order], s[order], a[order]
    r = mdp.R[s, a]
    out: list[list[list[tuple[tuple[int, float], float]]]] = [[[] for _ in range(A)]
                                                              for _ in range(S)]
    for si, ai, ci, ri, pi in zip(s.tolist(), a.tolist(), col.tolist(), r.tolist(), p.tolist(),
                                  strict=True):
        out[si][ai].append(((ci, ri), pi))
    return out


def _searched_states(mdp: FiniteMDP, terminals: bool) -> np.ndarray:
    """The states the package's graph search reaches: from the start states along the edges of
    :func:`~adpart.subgoals.literature.transition_graph`, not leaving a terminal state when
    ``terminals``."""
    import numpy as np
    import scipy.sparse as sp
    from scipy.sparse import csgraph

    from adpart.subgoals.literature import transition_graph

    S = mdp.n_states
    g = sp.coo_array(transition_graph(mdp))
    keep = ~mdp.terminal[g.row] if terminals else np.ones(g.row.size, dtype=bool)
    starts = np.flatnonzero(mdp.initial > 0)
    rows = np.concatenate([g.row[keep], np.full(starts.size, S)])
    cols = np.concatenate([g.col[keep], starts])
    G = sp.csr_array((np.ones(rows.size), (rows, cols)), shape=(S + 1, S + 1))
    order = csgraph.breadth_first_order(G, S, directed=True, return_predecessors=False)
    return np.sort(order[order < S]).astype(np.int64)


@functools.cache
def _environment_class() -> type:
    """The adapter class, defined on first use so that ``simpleoptions`` is imported lazily."""
    import_simpleoptions()
    import networkx as nx
    import numpy as np
    from simpleoptions import BaseEnvironment

    class MDPEnvironment(BaseEnvironment):
        """An adpart FiniteMDP as a ``simpleoptions.BaseEnvironment`` (module docstring)."""

        def __init__(self, mdp: FiniteMDP, *, terminals: bool,
                     self_loops: bool) -> None:
            super().__init__()
            self.mdp = mdp
            self.terminals = bool(terminals)
            self.self_loops = bool(self_loops)
            self._succ = _successor_lists(mdp)
            self._actions = [np.flatnonzero(row).tolist() for row in mdp.admissible]
            self._initial = np.flatnonzero(mdp.initial > 0).tolist()
            self._weights = mdp.initial[self._initial].tolist()
            self._terminal = mdp.terminal.tolist()
            self._states = set(_searched_states(mdp, self.terminals).tolist())
            self._random = random.Random(0)

        @property
        def options(self) -> set:
            """The options set by ``set_options`` (the package's ``Eigenoption`` reads it)."""
            return self._options

        def reset(self, state: int | None = None) -> int:
            if state is None:
                state = self._random.choices(self._initial, self._weights)[0]
            self.current_state = int(state)
            return self.current_state

        def step(self, action: int, state: int | None = None) -> tuple[int, float, bool, dict]:
            s = self.current_state if state is None else state
            outcomes = self._succ[s][action]
            (nxt, reward), _ = self._random.choices(outcomes, [p for _, p in outcomes])[0]
            self.current_state = nxt
            return nxt, reward, self.is_state_terminal(nxt), {}

        def render(self, *args: Any, **kwargs: Any) -> None:
            return None

        def close(self) -> None:
            return None

        def get_state_space(self) -> set[int]:
            return set(self._states)

        def get_action_space(self) -> set[int]:
            return set(range(self.mdp.n_actions))

        def get_available_actions(self, state: int | None = None) -> list[int]:
            return list(self._actions[self.current_state if state is None else state])

        def is_state_terminal(self, state: int | None = None) -> bool:
            s = self.current_state if state is None else state
            return self.terminals and self._terminal[s]

        def get_initial_states(self) -> list[int]:
            return list(self._initial)

        def get_successors(self, state: int | None = None,
                           actions: list[int] | None = None) -> list[tuple[tuple[int, float],
                                                                            float]]:
            s = self.current_state if state is None else state
            acts = self._actions[s] if actions is None else list(actions)
            n = len(acts)
            return [(out, p / n) for a in acts for out, p in self._succ[s][a]]

        def generate_interaction_graph(self, directed: bool = True,
                                       weighted: bool = False) -> nx.Graph:
            """The package's graph (``BaseEnvironment``'s search), without its self-loops
            unless ``self_loops``."""
            stg = super().generate_interaction_graph(directed=directed, weighted=weighted)
            if not self.self_loops:
                stg.remove_edges_from(list(nx.selfloop_edges(stg)))
            return stg

    return MDPEnvironment


def mdp_environment(mdp: FiniteMDP, settings: SimpleOptionsSettings | None = None) -> Any:
    """``mdp`` as a ``simpleoptions.BaseEnvironment`` (module docstring: "The environment")."""
    from adpart.subgoals.policy import check_mdp

    s = given(SimpleOptionsSettings, settings)
    return _environment_class()(check_mdp(mdp), terminals=s.terminals, self_loops=s.self_loops)


class _OutcomeStates:
    """The environment as ``EigenoptionGenerator.train_option`` reads it: ``get_successors(s,
    [a])`` gives the outcomes' states, most likely first (module docstring)."""

    def __init__(self, env: Any) -> None:
        self.env = env

    def get_successors(self, state: int | None = None,
                       actions: list[int] | None = None) -> list[int]:
        return [nxt for (nxt, _), _ in self.env.get_successors(state, actions)]

    def __getattr__(self, name: str) -> Any:
        return getattr(self.env, name)


@contextlib.contextmanager
def _quiet() -> Any:
    """Silence the package's progress bars (``tqdm`` writes to ``sys.stderr``)."""
    with contextlib.redirect_stderr(io.StringIO()):
        yield


def _as_vector(values: dict[int, float], S: int) -> np.ndarray:
    import numpy as np

    out = np.zeros(S)
    if values:
        keys = np.fromiter(values.keys(), dtype=np.int64, count=len(values))
        out[keys] = np.fromiter(values.values(), dtype=np.float64, count=len(values))
    return out


def _ranked(subgoals: list[int], scores: dict[int, float], top: int) -> list[int]:
    """The package's order: by score, most first (stable), the first ``top`` (0: all)."""
    ranked = sorted(subgoals, key=lambda x: scores[x], reverse=True)
    return ranked[:top] if top else ranked


# --------------------------------------------------------------------------- the generators


def so_betweenness(mdp: FiniteMDP, settings: SimpleOptionsSettings | None = None) -> tuple[
    np.ndarray, np.ndarray, dict[str, object]
]:
    """simpleoptions' betweenness subgoals (Şimşek & Barto 2008) on ``mdp``.

    Returns:
        ``(scores, subgoals, stats)``: ``(S,)`` the package's centrality (networkx's
        normalisation, endpoints counted; 0 off its graph), the subgoal ids most central first,
        and figures of the run.
    """
    import numpy as np

    from adpart.subgoals.policy import check_mdp

    s = given(SimpleOptionsSettings, settings)
    impl = import_simpleoptions()
    import networkx as nx

    mdp = check_mdp(mdp)
    env = mdp_environment(mdp, s)
    gen = impl.BetweennessOptionGenerator(s.top or mdp.n_states, 1, 1.0, 0.0, 1.0, 0, 1, 0.0)
    stg = env.generate_interaction_graph(directed=s.directed_graph)
    if s.goal_paths:
        goals = [int(g) for g in np.flatnonzero(mdp.terminal) if g in stg]
        if not goals:
            raise TaskError("--goals counts shortest paths to the task's terminal states, and "
                            "this task has none the start states reach; give --goals false")
        central = nx.betweenness_centrality_subset(stg, sources=list(stg), targets=goals)
    else:
        central = nx.betweenness_centrality(stg, normalized=True, endpoints=True)
    maxima = [node for node in stg if gen._is_local_maxima(node, stg, central)]
    subgoals = _ranked(maxima, central, s.top)
    stats = {"graph_states": stg.number_of_nodes(), "graph_edges": stg.number_of_edges(),
             "local_maxima": len(maxima)}
    return _as_vector(central, mdp.n_states), np.asarray(subgoals, dtype=np.int64), stats


@dataclass(frozen=True, eq=False)
class SimpleOptionsEigenoption:
    """One of the package's eigenoptions, reduced.

    Attributes:
        pvf_id: the package's id: ``"j"`` for PVF ``j`` (``j = 1`` the eigenvector of the
            smallest non-zero eigenvalue), ``"-j"`` for its negation.
        pvf: ``(S,)`` the PVF's values (0 off the package's graph).
        sinks: the states where the trained policy terminates (a terminal state excluded).
        subgoals: the states reported for it (the settings' ``sinks`` rule).
    """

    pvf_id: str
    pvf: np.ndarray
    sinks: np.ndarray
    subgoals: np.ndarray

    def to_json(self) -> dict[str, object]:
        return {"pvf": self.pvf_id, "sinks": int(self.sinks.size),
                "subgoals": self.subgoals.tolist()}


def so_eigenoptions(mdp: FiniteMDP, settings: SimpleOptionsSettings | None = None) -> tuple[
    list[SimpleOptionsEigenoption], dict[str, object]
]:
    """simpleoptions' eigenoptions (Machado et al. 2017) on ``mdp``: ``2 k`` options, PVF 0
    dropped, each with its sinks and subgoals (module docstring), and figures of the run."""
    import numpy as np

    from adpart.subgoals.policy import check_mdp

    s = given(SimpleOptionsSettings, settings)
    impl = import_simpleoptions()

    class Generator(impl.EigenoptionGenerator):
        def train_option(self, option: Any) -> None:
            env = option.env
            option.env = _OutcomeStates(env)
            try:
                super().train_option(option)
            finally:
                option.env = env

    mdp = check_mdp(mdp)
    env = mdp_environment(mdp, s)
    n = len(env.get_state_space())
    if s.k + 1 > n:
        raise TaskError(f"--k {s.k} asks for {s.k} non-constant PVFs, but the package's graph "
                        f"has {n} states and so {n - 1}; give --k between 1 and {max(n - 1, 1)}")
    with _quiet():
        options = Generator(s.k + 1, s.discount).generate_options(env)
    S = mdp.n_states
    terminal = mdp.terminal if s.terminals else np.zeros(S, dtype=bool)
    out = []
    for o in options:
        if o.pvf_id in ("0", "-0"):
            continue
        pvf = _as_vector(o.pvf, S)
        stops = [st for st, act in o.primitive_policy.items() if act == _TERMINATE]
        sinks = np.sort(np.asarray(stops, dtype=np.int64))
        sinks = sinks[~terminal[sinks]]
        subgoals = sinks
        if s.sinks == "extreme" and sinks.size:
            states = np.fromiter(o.pvf.keys(), dtype=np.int64)
            span = float(np.ptp(pvf[states]))
            subgoals = sinks[pvf[sinks] >= pvf[sinks].max() - TIE_RTOL * span]
        out.append(SimpleOptionsEigenoption(o.pvf_id, pvf, sinks, subgoals))
    return out, {"graph_states": n, "pvfs_dropped": ["0", "-0"]}


def so_diffusion(mdp: FiniteMDP, settings: SimpleOptionsSettings | None = None) -> tuple[
    np.ndarray, np.ndarray, dict[str, object]
]:
    """simpleoptions' diffusion-option subgoals on ``mdp``: the local maxima of the diffusion
    score at time scale ``t``.

    The subgoal part of ``DiffusionOptionGenerator.generate_options``, with the generator's own
    methods (its graph matrices, eigendecomposition and score), so that the scores are returned
    too. Cost: a dense non-symmetric eigendecomposition and ``n^2`` vector operations in Python
    for a graph of ``n`` states.

    Returns:
        ``(scores, subgoals, stats)``: ``(S,)`` diffusion scores (0 off the package's graph), the
        subgoal ids highest score first, and figures of the run.
    """
    import numpy as np

    from adpart.subgoals.policy import check_mdp

    s = given(SimpleOptionsSettings, settings)
    impl = import_simpleoptions()
    mdp = check_mdp(mdp)
    env = mdp_environment(mdp, s)
    gen = impl.DiffusionOptionGenerator(s.top or mdp.n_states, s.time_scale, 1.0, 0.0, 1.0, 0, 1,
                                        0.0)
    stg, nodes, adj, deg, empty = _diffusion_graph(env)
    if len(nodes) - len(empty) < 2:
        raise TaskError("diffusion options need a state-transition graph of at least 2 states "
                        "with moves; the start states here reach fewer")
    vals, left, right, root = gen._compute_eigendecomp(deg, adj)
    f = gen.compute_f(vals, left, right, root)
    scores: dict[int, float] = {}
    i = 0
    for j, node in enumerate(nodes):
        if j in empty:
            scores[node] = 0.0
        else:
            scores[node] = float(f[i])
            i += 1
    maxima = [node for node in stg if gen._is_local_maxima(node, stg, scores)]
    subgoals = _ranked(maxima, scores, s.top)
    stats = {"graph_states": len(nodes), "local_maxima": len(maxima)}
    return _as_vector(scores, mdp.n_states), np.asarray(subgoals, dtype=np.int64), stats


def _diffusion_graph(env: Any) -> tuple[Any, list[Any], np.ndarray, np.ndarray, np.ndarray]:
    """``DiffusionOptionGenerator._extract_graph_matrices`` with its removal of the states that
    have no out-edge repeated until none is left: ``(undirected graph, node list, adjacency,
    degree matrix, removed node indices)``.

    The package removes such states once; a state whose only out-edges led to removed states
    then has degree 0, and the package's ``D^-1/2`` is infinite (its ``scipy.linalg.polar`` ends
    in ``ValueError: array must not contain infs or NaNs``; met on a counts model of FrozenLake
    8x8, where a state's only observed successors are holes). Where one pass leaves none, the
    result is the package's own; the states removed later get its removed states' score, 0."""
    import networkx as nx
    import numpy as np

    stg = env.generate_interaction_graph()
    undirected = stg.to_undirected()
    nodes = list(undirected.nodes)
    adj = np.asarray(nx.adjacency_matrix(stg, nodelist=nodes).todense())
    keep = np.ones(len(nodes), dtype=bool)
    while True:
        inside = np.flatnonzero(keep)
        dead = inside[adj[np.ix_(inside, inside)].sum(axis=1) == 0]
        if dead.size == 0:
            break
        keep[dead] = False
    inside = np.flatnonzero(keep)
    adj = adj[np.ix_(inside, inside)]
    return undirected, nodes, adj, np.diag(adj.sum(axis=1)), np.flatnonzero(~keep)


# --------------------------------------------------------------------------- the detector


def detect_simpleoptions(mdp: FiniteMDP, settings: SimpleOptionsSettings | None = None, *,
                         name: str = "simpleoptions") -> SubgoalResult:
    """The ``simpleoptions`` detector: the settings' method as a SubgoalResult.

    Scores: betweenness centrality, the number of eigenoptions with the state as a subgoal, or
    the diffusion score. Policy-independent; no threshold.
    """
    import numpy as np

    from adpart.subgoals.result import SubgoalResult

    s = given(SimpleOptionsSettings, settings)
    t0 = time.perf_counter()
    try:
        scores, subgoals, stats = _generated(mdp, s)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as err:  # the package's own
        raise TaskError(f"simpleoptions' {s.generator} generator failed on {mdp.name}: "
                        f"{err}") from err
    stats = {**stats, "time_s": time.perf_counter() - t0, "simpleoptions": _version()}
    return SubgoalResult(subgoals, scores, None, stats, settings_dict(s), name)


def _generated(mdp: FiniteMDP, s: SimpleOptionsSettings) -> tuple[
    np.ndarray, np.ndarray, dict[str, object]
]:
    """``(scores, subgoals, stats)`` of the settings' generator (:func:`detect_simpleoptions`)."""
    import numpy as np

    if s.generator == "eigenoptions":
        options, stats = so_eigenoptions(mdp, s)
        ends = [o.subgoals for o in options]
        flat = np.concatenate(ends) if ends else np.zeros(0, np.int64)
        scores = np.bincount(flat, minlength=mdp.n_states).astype(np.float64)
        subgoals = flat
        stats = {**stats, "eigenoptions": [o.to_json() for o in options]}
    elif s.generator == "diffusion":
        scores, subgoals, stats = so_diffusion(mdp, s)
    else:
        scores, subgoals, stats = so_betweenness(mdp, s)
    return scores, subgoals, stats


def _version() -> str:
    import importlib.metadata

    try:
        return importlib.metadata.version("simpleoptions")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"
