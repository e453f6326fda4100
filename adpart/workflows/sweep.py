"""Sweeps: a grid of learning runs (environments x tasks x learner parameters x seeds).

A sweep is described by a TOML file (docs/scale-out.md)::

    learner = "q-learning"
    runs = 4
    episodes = 100
    seeds = [0, 1]                       # or a count: seeds = 5 means 0..4
    environments = ["two-rooms", { name = "four-rooms", tasks = ["G1", "G2"] }]

    [params]                             # a list is a grid axis, a scalar a fixed value
    alpha = ["0.1", "0.5"]
    epsilon = "0.1"

Every combination is one *cell*: a :class:`~adpart.workflows.LearnRequest` with the task and the
learner parameters resolved (defaults filled in), so the cell is fully explicit. Its **cell key**
is the SHA-256 of the request's canonical JSON; it is stored with the run
(``parameters["sweep_cell"]``) and, since the request itself is stored too
(``parameters["request"]``), can be recomputed from any stored run. A rerun therefore skips every
cell whose key is already in the knowledge base: sweeps are resumable.

The remaining cells run on an executor, one task per cell; each task learns its cell in the
worker with a :class:`~adpart.execution.SerialExecutor` (the cell is the unit of parallelism) and
returns plain data. **The driver alone writes to the knowledge base**, one cell at a time as the
results arrive: workers need no access to the knowledge base, a task that is retried after its
worker died writes nothing, and the driver writes each cell key at most once.
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from adpart.envs.registry import gym_module
from adpart.errors import AdpartError, TaskError, UnknownNameError
from adpart.execution import Executor, SerialExecutor
from adpart.learning.curves import LearningCurve
from adpart.learning.settings import MAX_SEED, Run
from adpart.params import setting_fields
from adpart.plugins import PluginError, get_registry
from adpart.workflows.learning import LearnOutcome, LearnRequest, record_learning, run_learning
from adpart.workflows.resolve import resolve_domain
from adpart.workflows.store import KnowledgeStore

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

#: The key under which a stored run carries its cell key.
CELL_PARAMETER = "sweep_cell"

_INT_KEYS = {"runs": 1, "episodes": 1, "eval_every": 1, "runs_per_batch": 0}
#: the most seeds and cells one sweep may list: each cell is a learning run stored in the
#: knowledge base, and the plan is built in memory before the first runs
MAX_SEEDS = 100_000
MAX_CELLS = 1_000_000
_KEYS = ("name", "learner", *_INT_KEYS, "seeds", "environments", "params", "allow_imports")
_DEFAULTS: dict[str, Any] = {"learner": "q-learning", "runs": 10, "episodes": 300,
                             "eval_every": 10, "runs_per_batch": 0}


class SweepConfigError(AdpartError, ValueError):
    """A sweep configuration is malformed; the message names the key and the fix."""


class SweepError(AdpartError, RuntimeError):
    """A sweep stopped before all its cells were stored."""


# ---------------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class EnvironmentSpec:
    """One environment of the grid and its tasks (None: the environment's default task)."""

    name: str
    tasks: tuple[str, ...] | None = None


#: The run settings' defaults (one declaration: :class:`Run`).
_RUN = Run()
#: the largest value of each integer key: the bound :class:`Run` declares for its field
_INT_MAX = {sf.name: int(sf.bounds.max) for sf in setting_fields(Run)
            if sf.name in ("runs", "episodes", "eval_every")}
_INT_MAX["runs_per_batch"] = _INT_MAX["runs"]


@dataclass(frozen=True)
class SweepConfig:
    """A validated sweep description (see the module docstring for the TOML form).

    Attributes:
        environments: the environments and their tasks, in file order.
        seeds: root seeds, in file order.
        params: learner parameter -> its values (one value: fixed; several: a grid axis).
        learner, runs, episodes, eval_every, runs_per_batch: as in :class:`LearnRequest`.
        name: a label for reports.
        source: where the configuration came from, for error messages.
    """

    environments: tuple[EnvironmentSpec, ...]
    seeds: tuple[int, ...]
    params: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    learner: str = "q-learning"
    runs: int = _RUN.runs
    episodes: int = _RUN.episodes
    eval_every: int = _RUN.eval_every
    runs_per_batch: int = 0
    name: str = "sweep"
    source: str = "<config>"


def load_config(path: str | os.PathLike[str]) -> SweepConfig:
    """Read and validate a sweep TOML file."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SweepConfigError(
            f"cannot read sweep config {path}: {exc.strerror}; check the path"
        ) from None
    except tomllib.TOMLDecodeError as exc:
        raise SweepConfigError(f"sweep config {path} is not valid TOML: {exc}") from None
    return parse_config(data, source=str(path))


def parse_config(data: Mapping[str, Any], *, source: str = "<config>") -> SweepConfig:
    """Validate the parsed TOML ``data``; every error names the offending key."""

    def fail(key: str, problem: str) -> SweepConfigError:
        return SweepConfigError(f"sweep config {source}: `{key}` {problem}")

    raw = {str(k).replace("-", "_"): v for k, v in data.items()}
    for key in raw:
        if key not in _KEYS:
            hint = difflib.get_close_matches(key, _KEYS, n=1)
            raise fail(key, "is not a sweep setting; settings: " + ", ".join(_KEYS)
                       + (f". Did you mean `{hint[0]}`?" if hint else ""))
    for key in ("seeds", "environments"):
        if key not in raw:
            raise fail(key, "is missing; a sweep needs `seeds` (a list or a count) and "
                       "`environments` (a list of names or {name, tasks} tables)")
    values = {**_DEFAULTS, **raw}
    name = values.get("name", Path(source).stem if source != "<config>" else "sweep")
    for key in ("name", "learner"):
        if key in raw and (not isinstance(raw[key], str) or not raw[key]):
            raise fail(key, f"must be a non-empty string, got {raw[key]!r}")
    for key, low in _INT_KEYS.items():
        v = values[key]
        high = _INT_MAX[key]
        if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
            raise fail(key, f"must be an integer in [{low}, {high}], got {v!r}")
    environments = _parse_environments(raw["environments"], fail)
    _check_imports(environments, raw.get("allow_imports", []), fail)
    return SweepConfig(
        environments=environments,
        seeds=_parse_seeds(raw["seeds"], fail),
        params=_parse_params(raw.get("params", {}), fail),
        learner=values["learner"],
        runs=values["runs"],
        episodes=values["episodes"],
        eval_every=values["eval_every"],
        runs_per_batch=values["runs_per_batch"],
        name=name,
        source=source,
    )


def _check_imports(envs: Sequence[EnvironmentSpec], allowed: Any,
                   fail: Callable[[str, str], SweepConfigError]) -> None:
    """A config file imports no Python module it does not list in ``allow_imports``.

    ``gym:MODULE:Id-v0`` runs ``MODULE``'s code; a name on the command line is the user's own,
    but a file may come from elsewhere, so its imports must be named where they can be seen.
    """
    if not isinstance(allowed, list) or not all(isinstance(m, str) and m for m in allowed):
        raise fail("allow_imports", f"must be a list of module names, got {allowed!r}")
    for i, env in enumerate(envs):
        module = gym_module(env.name)
        if module is not None and module not in allowed:
            raise fail(f"environments[{i}]",
                       f"{env.name!r} imports the Python module {module!r}, running its code; "
                       f"a config file imports only the modules it lists: add "
                       f"allow_imports = [\"{module}\"] if you trust it")


def _parse_seeds(seeds: Any, fail: Callable[[str, str], SweepConfigError]) -> tuple[int, ...]:
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        if not 1 <= seeds <= MAX_SEEDS:
            raise fail("seeds", f"as a count must be in [1, {MAX_SEEDS}], got {seeds}")
        return tuple(range(seeds))
    if not isinstance(seeds, list) or not seeds:
        raise fail("seeds", f"must be a non-empty list of integers or a count, got {seeds!r}")
    if len(seeds) > MAX_SEEDS:
        raise fail("seeds", f"lists {len(seeds)} seeds; at most {MAX_SEEDS}")
    for i, s in enumerate(seeds):
        if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s <= MAX_SEED:
            raise fail(f"seeds[{i}]", f"must be an integer in [0, {MAX_SEED}], got {s!r}")
    return tuple(seeds)


def _parse_environments(
    envs: Any, fail: Callable[[str, str], SweepConfigError]
) -> tuple[EnvironmentSpec, ...]:
    if not isinstance(envs, list) or not envs:
        raise fail("environments", "must be a non-empty list of names or {name, tasks} tables, "
                   f"got {envs!r}")
    out = []
    for i, entry in enumerate(envs):
        key = f"environments[{i}]"
        if isinstance(entry, str) and entry:
            out.append(EnvironmentSpec(entry))
            continue
        if not isinstance(entry, dict):
            raise fail(key, f"must be a name or a {{name, tasks}} table, got {entry!r}")
        unknown = sorted(set(entry) - {"name", "tasks"})
        if unknown:
            raise fail(f"{key}.{unknown[0]}", "is not an environment setting; use `name` and "
                       "`tasks`")
        name = entry.get("name")
        if not isinstance(name, str) or not name:
            raise fail(f"{key}.name", f"must be an environment name, got {name!r}")
        tasks = entry.get("tasks")
        if tasks is None:
            out.append(EnvironmentSpec(name))
            continue
        if isinstance(tasks, str):
            tasks = [tasks]
        if not isinstance(tasks, list) or not tasks or not all(
            isinstance(t, str) and t for t in tasks
        ):
            raise fail(f"{key}.tasks", f"must be a non-empty list of task names, got {tasks!r}")
        out.append(EnvironmentSpec(name, tuple(tasks)))
    return tuple(out)


def _parse_params(
    params: Any, fail: Callable[[str, str], SweepConfigError]
) -> dict[str, tuple[Any, ...]]:
    if not isinstance(params, dict):
        raise fail("params", f"must be a table of learner parameters, got {params!r}")
    out: dict[str, tuple[Any, ...]] = {}
    for name, value in params.items():
        values = value if isinstance(value, list) else [value]
        if not values:
            raise fail(f"params.{name}", "is an empty list; give at least one value")
        for v in values:
            if isinstance(v, dict | list):
                raise fail(f"params.{name}", f"values must be strings or numbers, got {v!r}")
        out[str(name)] = tuple(values)
    return out


# ---------------------------------------------------------------------------------- cells
def cell_key(request: LearnRequest | Mapping[str, Any]) -> str:
    """SHA-256 of the request's canonical JSON (sorted keys, no spaces): the cell's identity."""
    data = request.to_dict() if isinstance(request, LearnRequest) else dict(request)
    if "model" in data and data["model"] is None:  # as LearnRequest.to_dict writes it
        del data["model"]
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class Cell:
    """One experiment of the grid: its position, its request and its key."""

    index: int
    request: LearnRequest
    key: str
    varying: tuple[tuple[str, Any], ...] = ()

    @property
    def label(self) -> str:
        """``env/task p=v ... seed=S``, naming only the parameters that vary in the sweep."""
        r = self.request
        extra = "".join(f" {k}={v}" for k, v in self.varying)
        return f"{r.env}/{r.task}{extra} seed={r.seed}"


def plan_cells(config: SweepConfig) -> list[Cell]:
    """Every cell of the grid in a fixed order: environment, task, parameters, seed.

    Validates names against the installed plugins (errors name the config key). The order
    depends on the file only, and identical cells (same key) appear once.
    """
    registry = get_registry()
    src = config.source
    size = len(config.seeds) * sum(len(e.tasks or (None,)) for e in config.environments)
    for values in config.params.values():
        size *= len(values)
    if size > MAX_CELLS:
        raise SweepConfigError(
            f"sweep config {src}: the grid has {size} cells (environments x tasks x params x "
            f"seeds); at most {MAX_CELLS}: split it into several sweeps or shorten `seeds` / "
            "`params`")
    try:
        spec = registry.get("learner", config.learner)
    except UnknownNameError as exc:
        raise SweepConfigError(f"sweep config {src}: `learner`: {exc}") from None
    names = list(config.params)
    combos = []
    for values in itertools.product(*(config.params[n] for n in names)):
        given = dict(zip(names, values, strict=True))
        try:
            combos.append((given, spec.resolve_params(given)))
        except PluginError as exc:
            bad = next((n for n in names if f"--{n.replace('_', '-')}" in str(exc)), None)
            key = f"params.{bad}" if bad else "params"
            raise SweepConfigError(f"sweep config {src}: `{key}`: {exc}") from None
    axes = [n for n in names if len(config.params[n]) > 1]
    cells: list[Cell] = []
    seen: set[str] = set()
    for i, env in enumerate(config.environments):
        tasks = _resolve_tasks(env, f"environments[{i}]", src)
        for task in tasks:
            for given, resolved in combos:
                for seed in config.seeds:
                    request = LearnRequest(
                        env=env.name, task=task, learner=config.learner, params=resolved,
                        runs=config.runs, episodes=config.episodes, seed=seed,
                        eval_every=config.eval_every, runs_per_batch=config.runs_per_batch,
                    )
                    key = cell_key(request)
                    if key in seen:
                        continue
                    seen.add(key)
                    varying = tuple((n, given[n]) for n in axes)
                    cells.append(Cell(len(cells), request, key, varying))
    return cells


def _resolve_tasks(env: EnvironmentSpec, key: str, src: str) -> tuple[str, ...]:
    try:
        domain = resolve_domain(env.name)
    except AdpartError as exc:
        raise SweepConfigError(f"sweep config {src}: `{key}`: {exc}") from None
    if env.tasks is None:
        return (domain.task(None).name,)
    for j, task in enumerate(env.tasks):
        try:
            domain.task(task)
        except (TaskError, UnknownNameError) as exc:
            raise SweepConfigError(f"sweep config {src}: `{key}.tasks[{j}]`: {exc}") from None
    return env.tasks


def done_cells(kb: KnowledgeStore) -> dict[str, int]:
    """Cell key -> run id of every run in ``kb`` whose request is a sweep cell's.

    The key is read from ``parameters["sweep_cell"]``, or recomputed from the stored request.
    """
    done: dict[str, int] = {}
    for run in kb.records("run"):
        params = run.provenance.parameters
        key = params.get(CELL_PARAMETER)
        if key is None and isinstance(params.get("request"), dict):
            key = cell_key(params["request"])
        if key is not None:
            done.setdefault(key, run.id)
    return done


# ---------------------------------------------------------------------------------- worker side
def run_cell(job: Mapping[str, Any]) -> dict[str, Any]:
    """Executor work item: learn one cell in this process; plain data back to the driver.

    ``job`` is ``{"key": cell key, "request": asdict(LearnRequest)}``. An error of the cell is
    returned (``"error"``), not raised, so one bad cell does not stop the others.
    """
    start = time.perf_counter()
    try:
        outcome = run_learning(LearnRequest(**job["request"]), executor=SerialExecutor())
    except Exception as exc:  # noqa: BLE001 (reported per cell; the sweep goes on)
        return {"key": job["key"], "error": f"{type(exc).__name__}: {exc}",
                "seconds": time.perf_counter() - start}
    return {
        "key": job["key"],
        "seconds": time.perf_counter() - start,
        "outcome": {
            "task_name": outcome.task_name,
            "params": outcome.params,
            "learner_package": outcome.learner_package,
            "learner_version": outcome.learner_version,
            "Q": outcome.Q,
            "curve": outcome.curve.to_dict(),
            "metadata": dict(outcome.curve.metadata),
            "batches": [list(b) for b in outcome.batches],
            "v_star_start": outcome.v_star_start,
            "n_states": outcome.n_states,
            "n_actions": outcome.n_actions,
            "model_hash": outcome.model_hash,
            "option_ids": list(outcome.option_ids),
        },
    }


def _outcome(request: LearnRequest, data: Mapping[str, Any]) -> LearnOutcome:
    """Rebuild the :class:`LearnOutcome` a worker returned as plain data."""
    return LearnOutcome(
        request=request,
        task_name=data["task_name"],
        params=dict(data["params"]),
        learner_package=data["learner_package"],
        learner_version=data["learner_version"],
        Q=np.asarray(data["Q"]),
        curve=LearningCurve.from_dict(data["curve"], data["metadata"]),
        batches=[(int(k), int(s)) for k, s in data["batches"]],
        v_star_start=float(data["v_star_start"]),
        n_states=int(data["n_states"]),
        n_actions=int(data["n_actions"]),
        model_hash=data["model_hash"],
        option_ids=tuple(int(i) for i in data.get("option_ids", ())),
    )


# ---------------------------------------------------------------------------------- driver side
@dataclass(frozen=True)
class CellResult:
    """What became of one cell: ``stored`` now, ``skipped`` (already stored), ``failed``, or
    ``pending`` (not reached, or a dry run); ``seconds`` of compute in the worker and
    ``store_seconds`` of knowledge-base writing in the driver."""

    cell: Cell
    status: str
    run: str | None = None
    final_gap: float | None = None
    optimal_runs: int | None = None
    seconds: float | None = None
    error: str | None = None
    store_seconds: float | None = None

    def as_dict(self) -> dict[str, Any]:
        r = self.cell.request
        return {
            "index": self.cell.index, "key": self.cell.key, "env": r.env, "task": r.task,
            "seed": r.seed, "params": dict(self.cell.varying), "status": self.status,
            "run": self.run, "final_value_gap": self.final_gap,
            "optimal_runs": self.optimal_runs, "seconds": self.seconds,
            "store_seconds": self.store_seconds, "error": self.error,
        }


@dataclass(frozen=True)
class SweepReport:
    """All cells of a sweep with their fate, and the driver's wall time."""

    results: list[CellResult]
    seconds: float

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.results)

    @property
    def complete(self) -> bool:
        return all(r.status in {"stored", "skipped"} for r in self.results)

    def as_dict(self) -> dict[str, Any]:
        return {
            "cells": len(self.results),
            **{s: self.count(s) for s in ("stored", "skipped", "failed", "pending")},
            "seconds": self.seconds,
            "results": [r.as_dict() for r in self.results],
        }


Progress = Callable[[int, int, CellResult], object]


def _parallelism(executor: Executor) -> int:
    if isinstance(executor, SerialExecutor):
        return 1
    for attr in ("parallelism", "workers"):
        value = getattr(executor, attr, None)
        if isinstance(value, int) and value > 0:
            return value
    return os.cpu_count() or 1


def stream(
    executor: Executor, fn: Callable[[Any], Any], items: Sequence[Any], chunk: int | None = None
) -> Iterator[tuple[int, Any]]:
    """``(index, fn(items[index]))`` as results become available.

    Executors with ``imap_unordered`` (Ray) stream task by task; the others are fed chunks of
    ``chunk`` items (default four per worker; one for a serial executor) through the plain
    ``map`` contract, so the driver can store results, and report progress, chunk by chunk.
    """
    imap = getattr(executor, "imap_unordered", None)
    if callable(imap):
        yield from imap(fn, items)
        return
    workers = _parallelism(executor)
    size = chunk or (1 if workers == 1 else 4 * workers)
    for start in range(0, len(items), size):
        for offset, result in enumerate(executor.map(fn, items[start:start + size])):
            yield start + offset, result


def run_sweep(
    cells: Sequence[Cell],
    kb: KnowledgeStore,
    executor: Executor | None = None,
    *,
    progress: Progress | None = None,
    worker: Callable[[Mapping[str, Any]], dict[str, Any]] = run_cell,
    chunk: int | None = None,
) -> SweepReport:
    """Learn every cell not yet in ``kb`` on ``executor``; store each result as it arrives.

    Args:
        cells: from :func:`plan_cells`.
        kb: an open :class:`~adpart.store.KnowledgeBase`; only this process writes to it.
        executor: where cells run (default: serially here); it is used, not closed.
        progress: ``progress(done, total, result)`` after each cell stored or failed; ``total``
            counts the cells to run (skipped ones excluded).
        worker: the work item function (``run_cell`` or a module-level wrapper of it).
        chunk: cells per ``map`` call for executors that cannot stream.

    Returns a :class:`SweepReport`; failed cells are reported, not raised, and are retried by
    the next run. An exception from the executor itself (e.g. a lost worker pool) propagates
    after the cells already received are stored - rerun the sweep to resume.
    """
    start = time.perf_counter()
    done = done_cells(kb)
    results: dict[str, CellResult] = {
        c.key: CellResult(c, "skipped", run=f"run:{done[c.key]}") for c in cells if c.key in done
    }
    todo = [c for c in cells if c.key not in done]
    jobs = [{"key": c.key, "request": asdict(c.request)} for c in todo]
    with_progress = progress or (lambda done, total, result: None)
    received = 0
    try:
        for i, data in stream(executor or SerialExecutor(), worker, jobs, chunk):
            cell = todo[i]
            if data.get("key") != cell.key:
                raise SweepError(f"the executor returned the result of cell {data.get('key')!r} "
                                 f"for cell {cell.key!r}; it broke the in-order contract")
            if cell.key in results:  # a duplicate delivery: the cell is stored already
                continue
            results[cell.key] = result = _store(kb, cell, data)
            received += 1
            with_progress(received, len(todo), result)
    except SweepError:
        raise
    except Exception as exc:
        raise SweepError(
            f"the sweep stopped after storing {received} of {len(todo)} cells "
            f"({type(exc).__name__}: {exc}); rerun it to resume - stored cells are skipped"
        ) from exc
    ordered = [results.get(c.key) or CellResult(c, "pending") for c in cells]
    return SweepReport(ordered, time.perf_counter() - start)


def _store(kb: KnowledgeStore, cell: Cell, data: Mapping[str, Any]) -> CellResult:
    seconds = data.get("seconds")
    if "error" in data:
        return CellResult(cell, "failed", seconds=seconds, error=data["error"])
    start = time.perf_counter()
    outcome = _outcome(cell.request, data["outcome"])
    tagged = replace(outcome, params={**outcome.params, CELL_PARAMETER: cell.key})
    ids = record_learning(kb, tagged)
    summary = outcome.summary()
    return CellResult(
        cell, "stored", run=ids["run"], final_gap=summary["final_value_gap"]["mean"],
        optimal_runs=summary["optimal_runs"], seconds=seconds,
        store_seconds=time.perf_counter() - start,
    )


def preview(cells: Sequence[Cell], kb: KnowledgeStore | None) -> SweepReport:
    """The dry run: which cells are stored already (``skipped``) and which would run.

    ``kb`` None stands for a knowledge base that does not exist yet: every cell would run.
    """
    done = done_cells(kb) if kb is not None else {}
    return SweepReport(
        [CellResult(c, "skipped", run=f"run:{done[c.key]}") if c.key in done
         else CellResult(c, "pending") for c in cells],
        0.0,
    )
