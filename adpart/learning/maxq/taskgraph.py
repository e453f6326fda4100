"""Declarative MAXQ task graphs (Dietterich 2000, sec. 3-5; dissertation sec. 3.4.1 and ch. 6).

A task graph decomposes an MDP into subtasks ``M_0 .. M_n``. Each :class:`Subtask` has

* ``children`` - names of primitive actions (the MDP's ``action_names``) or of other subtasks;
  a parameterised subtask is written by its bare name (one *child slot* per instance) or as one
  instance ``"Navigate(t=2)"``; ``"Go(d={d})"`` is formatted with the parent's static binding.
  ``children`` may also be a callable ``children(**static_binding) -> sequence of references``
  (e.g. "the two directions perpendicular to ``d``");
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
* ``params`` - *static* parameter name -> values; the subtask stands for one instance per
  combination (``Navigate(t)`` for ``t`` in the four landmarks), and every callable receives
  the binding as keyword arguments;
* ``call_params`` - *call-time* parameters, bound from the state in which the subtask is
  called: name -> feature name (or ``callable(features, **static_binding) -> (S,)`` values).
  Chapter 6's ``Go(d, r)`` ("r is bound to the current room") and ``BackOne(d, x, y)`` ("it
  needs the starting x and y position") are of this kind. One instance exists per value the
  feature takes (instances that can never be called are dropped); a parent refers to the
  subtask by its static parameters only, and that **child slot** invokes, in state ``s``, the
  instance whose call-time values equal the feature values at ``s``. The instance's
  ``terminal`` predicate sees the call-time values, so it can end "relative to where it was
  called"; its active set is automatically restricted to the states that bind those values.

:meth:`TaskGraph.compile` turns the description into the arrays the learner runs on
(:class:`CompiledGraph`): predicates become ``(S,)`` masks once, every composite instance keeps
tables only over its own *running* (non-terminal) states, child slots become per-state node-id
maps and abstractions become index maps into small tables. Bad graphs fail early with
:class:`~adpart.errors.TaskError`: a subtask without termination, an unknown child, a cycle, a
predicate of the wrong shape.
"""

from __future__ import annotations

import difflib
import itertools
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP

__all__ = ["CompiledGraph", "Subtask", "TaskGraph", "instance_name"]

Predicate = Callable[..., np.ndarray]
Abstraction = tuple[str, ...] | Mapping[str, tuple[str, ...]] | None
Children = tuple[str, ...] | Callable[..., Sequence[str]]

_INSTANCE = re.compile(r"^\s*([^()\s]+)\s*(?:\((.*)\))?\s*$")


def instance_name(name: str, binding: Mapping[str, object]) -> str:
    """``Navigate(t=2)`` for a binding, the bare name for an unparameterised subtask."""
    if not binding:
        return name
    return f"{name}(" + ",".join(f"{k}={v}" for k, v in binding.items()) + ")"


def _bare(child: str) -> str:
    m = _INSTANCE.match(child)
    return m.group(1) if m else child


@dataclass(frozen=True)
class Subtask:
    """One node ``M_i`` of a MAXQ task graph (see the module docstring for every field)."""

    name: str
    children: Children
    terminal: Predicate | None = None
    active: Predicate | None = None
    pseudo_reward: Callable[..., np.ndarray] | None = None
    abstraction: Abstraction = None
    params: Mapping[str, tuple[object, ...]] = field(default_factory=dict)
    call_params: Mapping[str, str | Callable[..., np.ndarray]] = field(default_factory=dict)
    description: str = ""

    def bindings(self) -> list[dict[str, object]]:
        """Every static parameter binding of this subtask (one empty binding if none)."""
        keys = list(self.params)
        return [dict(zip(keys, combo, strict=True))
                for combo in itertools.product(*(tuple(self.params[k]) for k in keys))]

    def child_refs(self, binding: Mapping[str, object]) -> tuple[str, ...]:
        """The child references of the instance with this static binding."""
        if callable(self.children):
            return tuple(self.children(**binding))
        return tuple(self.children)

    def child_abstraction(self, child: str) -> tuple[str, ...] | None:
        """The features ``C(self, s, child)`` depends on (``None`` = the full state)."""
        if self.abstraction is None or isinstance(self.abstraction, tuple):
            return self.abstraction
        for key in (child, _bare(child), "*"):
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
            predicate or without children, a parameter both static and call-time, or a cycle
            among the subtasks.
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
            both = sorted(set(t.params) & set(t.call_params))
            if both:
                raise TaskError(f"task graph {self.name!r}: subtask {t.name!r} declares {both} "
                                "both in params and in call_params; a parameter is either "
                                "static or bound at call time")
            if not all(t.child_refs(b) for b in t.bindings()):
                raise TaskError(f"task graph {self.name!r}: subtask {t.name!r} has no "
                                "children; list the primitive actions or subtasks it may call")
        self._check_acyclic(by_name)

    def _check_acyclic(self, by_name: Mapping[str, Subtask]) -> None:
        """Depth-first search over the subtask names; a back edge is a cycle."""
        state: dict[str, int] = {}  # 1 = on the stack, 2 = done

        def kids(node: str) -> list[str]:
            sub = by_name[node]
            return list(dict.fromkeys(_bare(c) for b in sub.bindings()
                                      for c in sub.child_refs(b)))

        def visit(node: str, path: list[str]) -> None:
            state[node] = 1
            for c in kids(node):
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
                for child in t.child_refs(binding):
                    self._resolve(child, binding, by_name, tuple(action_names), t.name)

    def _resolve(
        self, child: str, binding: Mapping[str, object], by_name: Mapping[str, Subtask],
        actions: tuple[str, ...], parent: str,
    ) -> list[tuple[str, dict[str, object] | None]]:
        """``[(name, static binding)]`` - the child slots a reference stands for; binding
        ``None`` = primitive."""
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
        called = sorted(set(wanted) & set(sub.call_params))
        if called:
            raise TaskError(f"task graph {self.name!r}: child {text!r} of {parent!r} binds "
                            f"{called}, which {base!r} binds itself from the state at call "
                            "time; refer to it by its static parameters only")
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

    def compile(self, mdp: FiniteMDP, *, abstraction: bool | None = None) -> CompiledGraph:
        """Evaluate predicates and abstractions on ``mdp`` (see :class:`CompiledGraph`).

        Args:
            mdp: the flat model whose states, features and action names the graph refers to.
            abstraction: use the declared state abstractions; ``False`` gives every node a
                table over its full running state set (Dietterich's "MAXQ without
                abstraction"); None: :class:`~adpart.learning.maxq.settings.GraphSettings`'
                default.
        """
        if abstraction is None:
            from adpart.learning.maxq.settings import GraphSettings

            abstraction = GraphSettings().abstraction
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
        slots: list[list[tuple[str, np.ndarray]]] = []
        term_l: list[np.ndarray] = []
        active_l: list[np.ndarray] = []

        def call_values(sub: Subtask, static: Mapping[str, object]) -> dict[str, np.ndarray]:
            out = {}
            for k, src in sub.call_params.items():
                if callable(src):
                    vals = np.asarray(src(features, **static))
                elif src in features:
                    vals = features[src]
                else:
                    raise TaskError(f"call-time parameter {k!r} of {sub.name!r} is bound from "
                                    f"feature {src!r}, which the model lacks; features: "
                                    f"{', '.join(sorted(features))}")
                if vals.shape != (S,):
                    raise TaskError(f"call-time parameter {k!r} of {sub.name!r} must give one "
                                    f"value per state ({S}), got shape {vals.shape}")
                out[k] = vals
            return out

        def number(sub: Subtask, binding: dict[str, object], bind_mask: np.ndarray) -> int:
            """Node id of one instance (full binding); -1 if it can never be called."""
            k = (sub.name, tuple(binding.items()))
            if k in ids:
                return ids[k]
            label = instance_name(sub.name, binding)
            term = _mask(sub.terminal(features, **binding), S, label, "terminal")  # type: ignore[misc]
            term = term | mdp.terminal
            act = np.ones(S, bool) if sub.active is None else _mask(
                sub.active(features, **binding), S, label, "active")
            act = act & bind_mask & ~term
            if sub.call_params and not act.any():
                ids[k] = -1
                return -1
            static = {p: binding[p] for p in sub.params}
            node_slots: list[tuple[str, np.ndarray]] = []
            for ref in sub.child_refs(static):
                for cname, cb in self._resolve(ref, static, by_name, actions, label):
                    node_slots.append(slot(cname, cb))
            ids[k] = A + len(order)
            order.append((sub, binding))
            slots.append(node_slots)
            term_l.append(term)
            active_l.append(act)
            return ids[k]

        def slot(cname: str, cb: dict[str, object] | None) -> tuple[str, np.ndarray]:
            """``(label, (S,) node id invoked in each state, -1 = not callable there)``."""
            if cb is None:
                a = actions.index(cname)
                return cname, np.where(mdp.admissible[:, a], a, -1).astype(np.int64)
            sub = by_name[cname]
            if not sub.call_params:
                node = number(sub, cb, np.ones(S, bool))
                return instance_name(cname, cb), np.where(active_l[node - A], node, -1)
            vals = call_values(sub, cb)
            names_ = list(vals)
            stacked = np.stack([vals[n] for n in names_], axis=1)
            uniq, inverse = np.unique(stacked, axis=0, return_inverse=True)
            inverse = np.asarray(inverse).reshape(-1)
            node_of = np.full(S, -1, dtype=np.int64)
            for u, combo in enumerate(uniq):
                full = {**cb, **{n: _plain(v) for n, v in zip(names_, combo, strict=True)}}
                node = number(sub, full, inverse == u)
                if node >= 0:
                    node_of = np.where(active_l[node - A], node, node_of)
            label = instance_name(cname, {**cb, **{n: "@" for n in names_}})
            return label, node_of

        root = by_name[self.root]
        if root.call_params:
            raise TaskError(f"task graph {self.name!r}: the root {self.root!r} cannot have "
                            "call-time parameters (nothing calls it)")
        root_id = number(root, {}, np.ones(S, bool))
        n_comp = len(order)
        names = [*actions, *(instance_name(t.name, b) for t, b in order)]
        terminal = np.stack(term_l)
        active = np.stack(active_l)
        pseudo = np.zeros((n_comp, S))
        has_pseudo = np.zeros(n_comp, dtype=bool)
        for j, (sub, b) in enumerate(order):
            if sub.pseudo_reward is not None:
                pr = np.asarray(sub.pseudo_reward(features, **b), dtype=np.float64)
                if pr.shape != (S,) or not np.all(np.isfinite(pr)):
                    raise TaskError(f"pseudo_reward of {names[A + j]!r} must return {S} finite "
                                    f"numbers, got shape {pr.shape}")
                pseudo[j] = np.where(terminal[j], pr, 0.0)
                has_pseudo[j] = bool(np.any(pseudo[j] != 0.0))
        rows, slot_node, slot_names, c_index, c_size = [], [], [], [], []
        for j, (sub, _) in enumerate(order):
            r = np.flatnonzero(~terminal[j])
            rows.append(r)
            slot_names.append(tuple(lbl for lbl, _ in slots[j]))
            slot_node.append(np.stack([m[r] for _, m in slots[j]]).reshape(len(slots[j]), r.size))
            idx_j, size_j = [], []
            for lbl, _ in slots[j]:
                feats = sub.child_abstraction(lbl) if abstraction else None
                idx, size = _abstract_index(features, feats, r, names[A + j], lbl)
                idx_j.append(idx)
                size_j.append(size)
            c_index.append(idx_j)
            c_size.append(size_j)
        v_index, v_size = [], []
        for aname in actions:
            feats = self.primitive_abstraction.get(aname) if abstraction else None
            idx, size = _abstract_index(features, feats, np.arange(S), aname, "V")
            v_index.append(idx)
            v_size.append(size)
        return CompiledGraph(
            graph=self.name, names=tuple(names), n_primitives=A, root=root_id,
            terminal=terminal, active=active, pseudo=pseudo, has_pseudo=has_pseudo, rows=rows,
            slot_node=slot_node, slot_names=slot_names, c_index=c_index, c_size=c_size,
            v_index=v_index, v_size=v_size, abstraction=abstraction,
        )


def _plain(value: object) -> object:
    """numpy scalar -> Python scalar (so instance names read ``r=3``, not ``np.int64(3)``)."""
    return value.item() if isinstance(value, np.generic) else value


def _mask(value: object, S: int, label: str, what: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.shape != (S,) or arr.dtype != bool:
        raise TaskError(f"the {what} predicate of subtask {label!r} must return an ({S},) bool "
                        f"mask over all states; got shape {arr.shape}, dtype {arr.dtype}")
    return arr


def _abstract_index(
    features: Mapping[str, np.ndarray], feats: tuple[str, ...] | None, rows: np.ndarray,
    node: str, child: str,
) -> tuple[np.ndarray, int]:
    """Table index of every state of ``rows`` under an abstraction, and the table size."""
    n = rows.size
    if feats is None:
        return np.arange(n, dtype=np.int64), n
    if not feats:
        return np.zeros(n, dtype=np.int64), 1
    missing = [f for f in feats if f not in features]
    if missing:
        raise TaskError(f"the abstraction of {node!r} (child {child!r}) names features "
                        f"{missing} the model lacks; features: {', '.join(sorted(features))}")
    if n == 0:
        return np.zeros(0, dtype=np.int64), 0
    stacked = np.stack([np.asarray(features[f])[rows] for f in feats], axis=1)
    _, inverse = np.unique(stacked, axis=0, return_inverse=True)
    inverse = np.asarray(inverse, dtype=np.int64).reshape(-1)
    return inverse, int(inverse.max()) + 1


@dataclass(frozen=True, eq=False)
class CompiledGraph:
    """A task graph evaluated on one MDP: everything as arrays.

    Node ids ``0 .. A-1`` are the primitive actions, ``A ..`` the composite instances (children
    before parents); ``j = id - A`` indexes the per-composite lists below. A composite keeps
    its tables over its **rows** - the states where it is running (not terminated); states it
    can never be in while running need no entry.

    Attributes:
        names: the name of every node id.
        n_primitives: ``A``.
        root: the root's node id.
        terminal: ``(n_composite, S)`` termination masks ``T_i`` (MDP terminals included).
        active: ``(n_composite, S)`` states where the subtask may be called.
        pseudo: ``(n_composite, S)`` pseudo-reward ``R~_i`` on the termination states.
        has_pseudo: ``(n_composite,)`` whether any pseudo-reward is non-zero (else ``C~ = C``).
        rows: per composite, the sorted state ids where it runs (``~terminal[j]``).
        slot_node: per composite, ``(n_slots, n_rows)`` the node id each child slot invokes in
            each row state (``-1``: the slot is not available there).
        slot_names: per composite, the label of each slot (``r=@`` marks a call-time value).
        c_index: per composite, per slot, the ``(n_rows,)`` index into that slot's C table.
        c_size: per composite, per slot, the C table's size.
        v_index: per primitive, the ``(S,)`` index into its one-step reward table.
        v_size: per primitive, that table's size.
        abstraction: whether the declared abstractions were used.
    """

    graph: str
    names: tuple[str, ...]
    n_primitives: int
    root: int
    terminal: np.ndarray
    active: np.ndarray
    pseudo: np.ndarray
    has_pseudo: np.ndarray
    rows: list[np.ndarray]
    slot_node: list[np.ndarray]
    slot_names: list[tuple[str, ...]]
    c_index: list[list[np.ndarray]]
    c_size: list[list[int]]
    v_index: list[np.ndarray]
    v_size: list[int]
    abstraction: bool

    @property
    def n_composite(self) -> int:
        return len(self.rows)

    @property
    def n_states(self) -> int:
        return self.terminal.shape[1]

    def slot_nodes(self, j: int) -> np.ndarray:
        """``(n_slots, S)`` node id per slot and state of composite ``j`` (-1 outside its rows
        and where the slot is unavailable)."""
        out = np.full((self.slot_node[j].shape[0], self.n_states), -1, dtype=np.int64)
        out[:, self.rows[j]] = self.slot_node[j]
        return out

    @cached_property
    def children(self) -> list[np.ndarray]:
        """Per composite, the ``(n_slots,)`` node id of each slot where the slot always invokes
        the same node (static children); ``-1`` for a call-time slot."""
        out = []
        for j, sn in enumerate(self.slot_node):
            ids = np.full(sn.shape[0], -1, dtype=np.int64)
            for k, row in enumerate(sn):
                used = np.unique(row[row >= 0])
                if used.size == 1 and not self.slot_names[j][k].count("=@"):
                    ids[k] = used[0]
                elif used.size == 0 and "=@" not in self.slot_names[j][k]:
                    ids[k] = self.names.index(self.slot_names[j][k])
            out.append(ids)
        return out

    @cached_property
    def available(self) -> list[np.ndarray]:
        """Per composite, ``(n_slots, S)`` whether each slot may be chosen in ``s``."""
        return [self.slot_nodes(j) >= 0 for j in range(self.n_composite)]

    def table_size(self) -> int:
        """Number of stored values: all C entries (twice where ``C~`` is kept) plus all V(a)."""
        c = sum(sum(s) * (2 if self.has_pseudo[j] else 1) for j, s in enumerate(self.c_size))
        return int(c + sum(self.v_size))

    def postorder(self) -> list[int]:
        """Composite node ids, children before parents (the order they were numbered in)."""
        return list(range(self.n_primitives, self.n_primitives + self.n_composite))
