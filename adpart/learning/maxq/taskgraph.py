"""Declarative MAXQ task graphs (Dietterich 2000, sec. 3-5; dissertation sec. 3.4.1 and ch. 6).

A task graph decomposes an MDP into subtasks ``M_0 .. M_n``. Each :class:`Subtask` has

* ``children`` - names of primitive actions (the MDP's ``action_names``) or of other subtasks;
  a parameterised subtask is written by its bare name (all its instances) or as one instance
  ``"Navigate(t=2)"``; ``"Go(d={d})"`` is formatted with the *parent's* binding;
* ``terminal`` - the termination predicate ``T_i``: ``terminal(features, **binding)`` returns an
  ``(S,)`` bool mask over all states at once (vectorised; ``features`` are the MDP's named
  ``(S,)`` arrays plus the graph's derived features). The MDP's own terminal states end every
  subtask, so they are always added;
* ``active`` - optional ``(S,)`` mask of the states where the subtask may be *called* (its
  active set ``S_i`` is ``active & ~terminal``; default every non-terminal state);
* ``pseudo_reward`` - optional ``R~_i``: ``(S,)`` floats read on the states where the subtask
  terminates (only used for learning the subtask's internal policy, Dietterich's ``C~``);
* ``abstraction`` - the state features the completion values ``C(i, s, a)`` depend on (one
  tuple for all children, or a mapping child name -> tuple with ``"*"`` as the default). States
  that agree on them share one table entry ("max node irrelevance" and friends, Dietterich
  sec. 5). ``None`` keeps the full state;
* ``params`` - parameter name -> values; the subtask stands for one instance per combination
  (``Navigate(t)`` for ``t`` in the four landmarks), and every callable receives the binding
  as keyword arguments.

:meth:`TaskGraph.compile` turns the description into the arrays the learner runs on
(:class:`CompiledGraph`): predicates become ``(S,)`` masks once, abstractions become ``(S,)``
index maps into small tables. Bad graphs fail early with :class:`~adpart.errors.TaskError`:
a subtask without termination, an unknown child, a cycle, a predicate of the wrong shape.
"""

from __future__ import annotations

import difflib
import itertools
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP

__all__ = ["CompiledGraph", "Subtask", "TaskGraph", "instance_name"]

Predicate = Callable[..., np.ndarray]
Abstraction = tuple[str, ...] | Mapping[str, tuple[str, ...]] | None

_INSTANCE = re.compile(r"^\s*([^()\s]+)\s*(?:\((.*)\))?\s*$")


def instance_name(name: str, binding: Mapping[str, object]) -> str:
    """``Navigate(t=2)`` for a binding, the bare name for an unparameterised subtask."""
    if not binding:
        return name
    return f"{name}(" + ",".join(f"{k}={v}" for k, v in binding.items()) + ")"


@dataclass(frozen=True)
class Subtask:
    """One node ``M_i`` of a MAXQ task graph (see the module docstring for every field)."""

    name: str
    children: tuple[str, ...]
    terminal: Predicate | None = None
    active: Predicate | None = None
    pseudo_reward: Callable[..., np.ndarray] | None = None
    abstraction: Abstraction = None
    params: Mapping[str, tuple[object, ...]] = field(default_factory=dict)
    description: str = ""

    def bindings(self) -> list[dict[str, object]]:
        """Every parameter binding of this subtask (one empty binding if unparameterised)."""
        keys = list(self.params)
        return [dict(zip(keys, combo, strict=True))
                for combo in itertools.product(*(tuple(self.params[k]) for k in keys))]

    def child_abstraction(self, child: str) -> tuple[str, ...] | None:
        """The features ``C(self, s, child)`` depends on (``None`` = the full state)."""
        if self.abstraction is None or isinstance(self.abstraction, tuple):
            return self.abstraction
        base = _INSTANCE.match(child)
        bare = base.group(1) if base else child
        for key in (child, bare, "*"):
            if key in self.abstraction:
                return tuple(self.abstraction[key])
        return None


@dataclass(frozen=True)
class TaskGraph:
    """A MAXQ task graph: subtasks, the root, and optional derived features and abstractions.

    Attributes:
        name: the graph's name (``taxi``).
        root: the name of the root subtask (it must terminate exactly where the task ends).
        subtasks: the composite nodes.
        primitive_abstraction: action name -> features the learned one-step reward ``V(a, s)``
            depends on (default: the full state).
        derived: ``mdp -> {name: (S,) array}`` extra features the predicates and abstractions
            may use (e.g. the room of a maze cell); computed once at compile time.
        description: one line for listings.

    Raises:
        TaskError: duplicate subtask names, a missing root, a subtask without termination
            predicate or without children, or a cycle among the subtasks.
    """

    name: str
    root: str
    subtasks: tuple[Subtask, ...]
    primitive_abstraction: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    derived: Callable[[FiniteMDP], Mapping[str, np.ndarray]] | None = None
    description: str = ""

    def __post_init__(self) -> None:
        names = [t.name for t in self.subtasks]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise TaskError(f"task graph {self.name!r}: subtask names {dup} are used twice; "
                            "give every subtask a unique name")
        by_name = {t.name: t for t in self.subtasks}
        if self.root not in by_name:
            raise TaskError(f"task graph {self.name!r}: root {self.root!r} is not one of its "
                            f"subtasks {names}")
        for t in self.subtasks:
            if t.terminal is None:
                raise TaskError(
                    f"task graph {self.name!r}: subtask {t.name!r} has no termination "
                    "predicate; every subtask must end somewhere - give terminal=lambda f: ... "
                    "returning an (S,) bool mask"
                )
            if not t.children:
                raise TaskError(f"task graph {self.name!r}: subtask {t.name!r} has no "
                                "children; list the primitive actions or subtasks it may call")
        self._check_acyclic(by_name)

    def _check_acyclic(self, by_name: Mapping[str, Subtask]) -> None:
        """Depth-first search over the subtask names; a back edge is a cycle."""
        state: dict[str, int] = {}  # 1 = on the stack, 2 = done

        def bare(child: str) -> str:
            m = _INSTANCE.match(child)
            return m.group(1) if m else child

        def visit(node: str, path: list[str]) -> None:
            state[node] = 1
            for child in by_name[node].children:
                c = bare(child)
                if c not in by_name:
                    continue
                if state.get(c) == 1:
                    cycle = " -> ".join([*path[path.index(c):], c])
                    raise TaskError(
                        f"task graph {self.name!r} has a cycle {cycle}; a task graph must be "
                        "acyclic (a subtask may not call itself, directly or through others)"
                    )
                if state.get(c) != 2:
                    visit(c, [*path, c])
            state[node] = 2

        for name in by_name:
            if name not in state:
                visit(name, [name])

    # ---------------------------------------------------------------------------- compile
    def validate(self, action_names: Sequence[str]) -> None:
        """Check every child names a primitive action or a subtask (instance) of the graph."""
        by_name = {t.name: t for t in self.subtasks}
        for t in self.subtasks:
            for binding in t.bindings():
                for child in t.children:
                    self._resolve(child, binding, by_name, tuple(action_names), t.name)

    def _resolve(
        self, child: str, binding: Mapping[str, object], by_name: Mapping[str, Subtask],
        actions: tuple[str, ...], parent: str,
    ) -> list[tuple[str, dict[str, object] | None]]:
        """``[(name, binding)]`` a child reference stands for; binding None = primitive."""
        try:
            text = child.format(**binding)
        except (KeyError, IndexError, ValueError):
            raise TaskError(f"task graph {self.name!r}: child {child!r} of {parent!r} uses a "
                            f"parameter {parent!r} does not have ({list(binding)})") from None
        if text in actions:
            return [(text, None)]
        m = _INSTANCE.match(text)
        base = m.group(1) if m else text
        if base not in by_name:
            known = [*actions, *by_name]
            hint = difflib.get_close_matches(base, known, n=1)
            raise TaskError(
                f"task graph {self.name!r}: subtask {parent!r} has unknown child {text!r}; "
                f"children must be primitive actions ({', '.join(actions)}) or subtasks "
                f"({', '.join(by_name)})" + (f". Did you mean {hint[0]!r}?" if hint else "")
            )
        sub = by_name[base]
        if m is None or m.group(2) is None:
            return [(base, b) for b in sub.bindings()]
        wanted: dict[str, str] = {}
        for item in filter(None, (p.strip() for p in m.group(2).split(","))):
            k, eq, v = item.partition("=")
            if not eq:
                raise TaskError(f"task graph {self.name!r}: child {text!r} of {parent!r}: write "
                                "parameters as name=value, e.g. Navigate(t=2)")
            wanted[k.strip()] = v.strip()
        unknown = sorted(set(wanted) - set(sub.params))
        if unknown:
            raise TaskError(f"task graph {self.name!r}: child {text!r} of {parent!r} binds "
                            f"{unknown}, which {base!r} does not take ({list(sub.params)})")
        out = [(base, b) for b in sub.bindings()
               if all(str(b[k]) == v for k, v in wanted.items())]
        if not out:
            raise TaskError(f"task graph {self.name!r}: child {text!r} of {parent!r} matches "
                            f"no instance of {base!r} (parameter values {dict(sub.params)})")
        return out

    def compile(self, mdp: FiniteMDP, *, abstraction: bool = True) -> CompiledGraph:
        """Evaluate predicates and abstractions on ``mdp`` (see :class:`CompiledGraph`).

        Args:
            mdp: the flat model whose states, features and action names the graph refers to.
            abstraction: use the declared state abstractions; ``False`` gives every node a
                table over the full state (Dietterich's "MAXQ without abstraction").
        """
        actions = tuple(mdp.action_names)
        self.validate(actions)
        by_name = {t.name: t for t in self.subtasks}
        features: dict[str, np.ndarray] = {k: np.asarray(v) for k, v in mdp.features.items()}
        if self.derived is not None:
            features.update({k: np.asarray(v) for k, v in self.derived(mdp).items()})
        S, A = mdp.n_states, mdp.n_actions

        # number the instances reachable from the root, children before parents
        ids: dict[tuple[str, tuple[tuple[str, object], ...]], int] = {}
        order: list[tuple[Subtask, dict[str, object]]] = []
        kids: list[list[tuple[int, str]]] = []

        def key(name: str, b: Mapping[str, object]) -> tuple[str, tuple[tuple[str, object], ...]]:
            return name, tuple(b.items())

        def number(name: str, binding: dict[str, object]) -> int:
            k = key(name, binding)
            if k in ids:
                return ids[k]
            sub = by_name[name]
            children: list[tuple[int, str]] = []
            for child in sub.children:
                for cname, cb in self._resolve(child, binding, by_name, actions, name):
                    if cb is None:
                        children.append((actions.index(cname), cname))
                    else:
                        children.append((number(cname, cb), instance_name(cname, cb)))
            ids[k] = A + len(order)
            order.append((sub, binding))
            kids.append(children)
            return ids[k]

        root_id = number(self.root, {})
        n_comp = len(order)
        names = [*actions, *(instance_name(t.name, b) for t, b in order)]
        terminal = np.zeros((n_comp, S), dtype=bool)
        active = np.zeros((n_comp, S), dtype=bool)
        pseudo = np.zeros((n_comp, S))
        has_pseudo = np.zeros(n_comp, dtype=bool)
        for j, (sub, b) in enumerate(order):
            label = names[A + j]
            term = _mask(sub.terminal(features, **b), S, label, "terminal")  # type: ignore[misc]
            terminal[j] = term | mdp.terminal
            act = np.ones(S, bool) if sub.active is None else _mask(
                sub.active(features, **b), S, label, "active")
            active[j] = act & ~terminal[j]
            if sub.pseudo_reward is not None:
                pr = np.asarray(sub.pseudo_reward(features, **b), dtype=np.float64)
                if pr.shape != (S,) or not np.all(np.isfinite(pr)):
                    raise TaskError(f"pseudo_reward of {label!r} must return {S} finite numbers, "
                                    f"got shape {pr.shape}")
                pseudo[j] = np.where(terminal[j], pr, 0.0)
                has_pseudo[j] = bool(np.any(pseudo[j] != 0.0))
        children = [np.array([c for c, _ in ch], dtype=np.int64) for ch in kids]
        available = []
        c_index: list[list[np.ndarray]] = []
        c_size: list[list[int]] = []
        for j, (sub, _) in enumerate(order):
            av = np.empty((len(children[j]), S), dtype=bool)
            idx_j, size_j = [], []
            for k, (c, cname) in enumerate(kids[j]):
                av[k] = mdp.admissible[:, c] if c < A else active[c - A]
                feats = sub.child_abstraction(cname) if abstraction else None
                idx, size = _abstract_index(features, feats, S, names[A + j], cname)
                idx_j.append(idx)
                size_j.append(size)
            available.append(av)
            c_index.append(idx_j)
            c_size.append(size_j)
        v_index, v_size = [], []
        for aname in actions:
            feats = self.primitive_abstraction.get(aname) if abstraction else None
            idx, size = _abstract_index(features, feats, S, aname, "V")
            v_index.append(idx)
            v_size.append(size)
        return CompiledGraph(
            graph=self.name, names=tuple(names), n_primitives=A, root=root_id,
            children=children, terminal=terminal, active=active, pseudo=pseudo,
            has_pseudo=has_pseudo, available=available, c_index=c_index, c_size=c_size,
            v_index=v_index, v_size=v_size, abstraction=abstraction,
        )


def _mask(value: object, S: int, label: str, what: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.shape != (S,) or arr.dtype != bool:
        raise TaskError(f"the {what} predicate of subtask {label!r} must return an ({S},) bool "
                        f"mask over all states; got shape {arr.shape}, dtype {arr.dtype}")
    return arr


def _abstract_index(
    features: Mapping[str, np.ndarray], feats: tuple[str, ...] | None, S: int, node: str,
    child: str,
) -> tuple[np.ndarray, int]:
    """``(S,)`` table index of every state under an abstraction, and the table size."""
    if feats is None:
        return np.arange(S, dtype=np.int64), S
    if not feats:
        return np.zeros(S, dtype=np.int64), 1
    missing = [f for f in feats if f not in features]
    if missing:
        raise TaskError(f"the abstraction of {node!r} (child {child!r}) names features "
                        f"{missing} the model lacks; features: {', '.join(sorted(features))}")
    stacked = np.stack([np.asarray(features[f]) for f in feats], axis=1)
    _, inverse = np.unique(stacked, axis=0, return_inverse=True)
    inverse = np.asarray(inverse, dtype=np.int64).reshape(-1)
    return inverse, int(inverse.max()) + 1


@dataclass(frozen=True, eq=False)
class CompiledGraph:
    """A task graph evaluated on one MDP: everything as arrays.

    Node ids ``0 .. A-1`` are the primitive actions, ``A ..`` the composite instances (children
    before parents); ``j = id - A`` indexes the per-composite lists below.

    Attributes:
        names: the name of every node id.
        n_primitives: ``A``.
        root: the root's node id.
        children: per composite, the ``(n_children,)`` child node ids.
        terminal: ``(n_composite, S)`` termination masks ``T_i`` (MDP terminals included).
        active: ``(n_composite, S)`` states where the subtask may run (``active & ~T_i``).
        pseudo: ``(n_composite, S)`` pseudo-reward ``R~_i`` on the termination states.
        has_pseudo: ``(n_composite,)`` whether any pseudo-reward is non-zero (else ``C~ = C``).
        available: per composite, ``(n_children, S)`` whether each child may be chosen in ``s``.
        c_index: per composite, per child, the ``(S,)`` index into that child's C table.
        c_size: per composite, per child, the C table's size.
        v_index: per primitive, the ``(S,)`` index into its one-step reward table.
        v_size: per primitive, that table's size.
        abstraction: whether the declared abstractions were used.
    """

    graph: str
    names: tuple[str, ...]
    n_primitives: int
    root: int
    children: list[np.ndarray]
    terminal: np.ndarray
    active: np.ndarray
    pseudo: np.ndarray
    has_pseudo: np.ndarray
    available: list[np.ndarray]
    c_index: list[list[np.ndarray]]
    c_size: list[list[int]]
    v_index: list[np.ndarray]
    v_size: list[int]
    abstraction: bool

    @property
    def n_composite(self) -> int:
        return len(self.children)

    @property
    def n_states(self) -> int:
        return self.terminal.shape[1]

    def table_size(self) -> int:
        """Number of stored values: all C entries (twice where ``C~`` is kept) plus all V(a)."""
        c = sum(sum(s) * (2 if self.has_pseudo[j] else 1) for j, s in enumerate(self.c_size))
        return int(c + sum(self.v_size))

    def postorder(self) -> list[int]:
        """Composite node ids, children before parents (the order they were numbered in)."""
        return list(range(self.n_primitives, self.n_primitives + self.n_composite))
