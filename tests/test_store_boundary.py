"""The store boundary: ``KnowledgeBase`` provides everything ``KnowledgeStore`` asks for.

A static structural check by :mod:`inspect`: every method of the Protocol exists on
:class:`adpart.store.KnowledgeBase` with a compatible signature - the same parameters in the same
order and kinds, the same annotations, a default wherever the Protocol has one (the same value),
and any further parameter of ``KnowledgeBase`` optional - and every attribute is set on an open
knowledge base. The workflows call nothing on ``kb`` that the Protocol does not list.
"""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

from adpart.store import KnowledgeBase
from adpart.workflows.store import KnowledgeStore

PACKAGE = Path(__file__).resolve().parents[1] / "adpart"


def _members() -> tuple[list[str], list[str]]:
    """``(methods, attributes)`` the Protocol declares."""
    methods = [n for n, v in vars(KnowledgeStore).items()
               if inspect.isfunction(v) and not n.startswith("_")]
    attributes = [n for n in KnowledgeStore.__annotations__ if not n.startswith("_")]
    return methods, attributes


def incompatibilities(protocol: type, implementation: type, name: str) -> list[str]:
    """Why ``implementation.name`` cannot stand in for ``protocol.name`` (empty: it can)."""
    impl = getattr(implementation, name, None)
    if not callable(impl):
        return [f"{implementation.__name__} has no method {name}"]
    want = list(inspect.signature(getattr(protocol, name)).parameters.values())[1:]
    have = list(inspect.signature(impl).parameters.values())[1:]
    have_by_name = {p.name: p for p in have}
    problems = []
    positional = [p.name for p in want if p.kind is not p.KEYWORD_ONLY]
    if [p.name for p in have if p.kind is not p.KEYWORD_ONLY][:len(positional)] != positional:
        problems.append(f"positional parameters {positional} are not the first of "
                        f"{[p.name for p in have]}")
    for p in want:
        q = have_by_name.get(p.name)
        if q is None:
            problems.append(f"no parameter {p.name!r}")
            continue
        if q.kind is not p.kind:
            problems.append(f"{p.name!r} is {q.kind.description}, not {p.kind.description}")
        if q.annotation != p.annotation:
            problems.append(f"{p.name!r} is annotated {q.annotation!r}, not {p.annotation!r}")
        if p.default is not p.empty and q.default != p.default:
            problems.append(f"{p.name!r} defaults to {q.default!r}, not {p.default!r}")
    wanted = {p.name for p in want}
    for q in have:
        if (q.name not in wanted and q.default is q.empty
                and q.kind not in (q.VAR_POSITIONAL, q.VAR_KEYWORD)):
            problems.append(f"{q.name!r} is required but the protocol does not pass it")
    return [f"{name}: {p}" for p in problems]


@pytest.mark.parametrize("name", _members()[0])
def test_knowledge_base_has_every_method_with_a_compatible_signature(name):
    assert incompatibilities(KnowledgeStore, KnowledgeBase, name) == []


def test_an_open_knowledge_base_is_a_knowledge_store(tmp_path):
    kb = KnowledgeBase.open(tmp_path / "kb")
    try:
        assert isinstance(kb, KnowledgeStore)
        for name in _members()[1]:
            assert isinstance(getattr(kb, name), str), name
    finally:
        kb.close()


def test_the_check_catches_an_incompatible_method():
    class Narrow:
        def get(self, kind: str) -> None: ...

        def records(self, kind: str, *, environment: int = 0, limit: int) -> None: ...

    assert incompatibilities(KnowledgeStore, Narrow, "get") == [
        "get: positional parameters ['kind', 'record_id'] are not the first of ['kind']",
        "get: no parameter 'record_id'",
    ]
    assert incompatibilities(KnowledgeStore, Narrow, "records") == [
        "records: 'environment' is annotated 'int', not 'E.Environment | int | None'",
        "records: 'environment' defaults to 0, not None",
        "records: 'limit' is required but the protocol does not pass it",
    ]
    assert incompatibilities(KnowledgeStore, Narrow, "load") == ["Narrow has no method load"]


def test_the_workflows_call_only_what_the_protocol_lists():
    """Every ``kb.<name>`` in the workflows is a Protocol member, or ``close`` of a knowledge
    base they opened themselves (:func:`adpart.workflows.working_kb.working_kb`)."""
    methods, attributes = _members()
    used: dict[str, str] = {}
    for path in sorted((PACKAGE / "workflows").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id == "kb"):
                used.setdefault(node.attr, f"{path.name}:{node.lineno}")
    extra = {n: where for n, where in used.items() if n not in {*methods, *attributes}}
    assert set(extra) <= {"close"}, extra
    assert extra.get("close", "working_kb.py").startswith("working_kb.py"), extra
